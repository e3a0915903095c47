"""``roadpreview demo``: the main job end to end on the built-in default.

Generates the simulator's ``demo`` drive (or reuses it when present and
identical), replays it through the default pipeline (motion lead finder,
robust pitch, Kalman fusion, heave compensation), and prints the anomalies detected against the
truth, the fusion mode changes (the fog stretch shows IMU_ONLY and the
recovery), where the outputs were written, and the speed.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "demo", help="simulate the demo drive and replay it through the default pipeline"
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("runs/demo"),
        metavar="DIR",
        help="working folder: the drive in DIR/recording (reused when it is the same drive),"
        " the replay's outputs in DIR/replay (replaced at each run)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the demo drive")
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="shorten the drive to S seconds; default: the preset's 60 s",
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roadpreview.apps.progress import Progress
    from roadpreview.apps.replay import (
        OUTPUT_FILES,
        ReplayInputs,
        format_alerts,
        format_modes,
        replay,
    )
    from roadpreview.cli._output import prepare_output_folder
    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import write_recording
    from roadpreview.sim.scenario import ScenarioConfig

    t0 = time.perf_counter()
    rec_dir = args.out / "recording"
    cfg = drive_config("demo", args.seed, duration_s=args.duration)
    reuse = False
    if (rec_dir / "truth.json").is_file():
        try:
            reuse = ScenarioConfig.load(rec_dir / "scenario.toml") == cfg
        except Exception:  # a half-written folder is regenerated
            reuse = False
    if reuse:
        print(f"reusing the demo drive in {rec_dir}")
    else:
        print(
            f"simulating the demo drive ({cfg.motion.duration_s:.0f} s, "
            f"{cfg.camera.width}x{cfg.camera.height}) into {rec_dir} ..."
        )
        info = write_recording(cfg, rec_dir)
        print(f"  {info.n_frames} frames, {info.n_can_frames} CAN frames in {info.seconds:.1f} s")
    inputs = ReplayInputs.from_recording(rec_dir)
    out = args.out / "replay"
    prepare_output_folder(out, force=True, ours=OUTPUT_FILES, say=None)  # the last replay
    print(
        "replaying it through the default pipeline (motion finder, robust pitch, kalman, heave) ..."
    )
    progress = Progress("replay", enabled=getattr(args, "verbosity", 0) >= 0)
    result = replay(inputs, None, out, progress=progress, keep_results=True)
    print(
        f"\ntimes below: seconds from the video's frame 0 (Unix time {result.video_start_s:.3f} s)"
    )
    print("\nanomalies the lead crossed, against the truth:")
    assert result.match is not None
    print(result.match.table())
    print("\nalerts (what RP_ALERT carried, and what the ego felt when it got there):")
    print(
        format_alerts(
            result.alerts, result.confirmations, result.video_start_s, result.run.cancelled
        )
    )
    print(
        "\nthe anomalies in the road preview (RP_PREVIEW) 1 s after the lead crossed them: the"
        " largest height over each, as sent (the confirmed alerts' bins carry their height)"
        " and from the lead's response alone:"
    )
    print(_preview_table(result, cfg, rec_dir))
    road = result.road
    print(
        f"\nroad class (ISO 8608): {road.iso_class or 'unknown'} (ego's IMU "
        f"{road.ego_class or '-'}, lead {road.lead_class or '-'}); the drive's road is class "
        f"{cfg.motion.road.iso_class}"
    )
    print("\nfusion modes:")
    print(format_modes(result.mode_changes, result.video_start_s))
    print(
        f"\noutputs: {out / 'alerts.blf'} (RP_ALERT, RP_ALERT_DETAIL, RP_ALERT_END, RP_CONFIRM,"
        f" RP_STATUS, RP_ROAD_STATUS, RP_INPUT_STATUS), {out / 'alerts.jsonl'},"
    )
    print(f"         {out / 'frames.csv'}, {out / 'plots.png'}, {out / 'summary.json'}")
    print(
        f"speed: {result.frames} frames in {result.seconds:.1f} s = {result.fps:.1f} fps "
        f"(pipeline only); whole demo {time.perf_counter() - t0:.0f} s"
    )
    return 0


def _preview_table(result: Any, cfg: Any, rec_dir: Path) -> str:
    """The demo's anomalies as the preview showed them (`roadpreview.preview.at_anomalies`)."""
    import json
    import math

    from roadpreview.eval.road_truth import at_anomalies, drive_for_scenario
    from roadpreview.pipeline.config import PipelineConfig
    from roadpreview.preview import ProfileEstimator

    frames = result.results or []
    sent = [r.preview for r in frames if r.preview is not None]
    pc = PipelineConfig()
    alone = ProfileEstimator(
        pc.preview, pc.anomaly.two_axle.vehicle, principal_row_px=cfg.camera_model().cy
    )
    profile = []
    for r in frames:
        if r.target_changed:
            alone.restart()
        if r.sample is not None and (p := alone.push(r.sample)) is not None:
            profile.append(p)
    drive = drive_for_scenario(cfg)
    events = json.loads((rec_dir / "truth.json").read_text())["events"]
    t0 = result.video_start_s
    rows = at_anomalies(sent, drive, events, t0=t0)
    bare = {a.index: a for a in at_anomalies(profile, drive, events, t0=t0)}

    def mm(x: float) -> str:
        return f"{x:+5.0f} mm" if math.isfinite(x) else "    -   "

    lines = ["  event  kind      true      length  ahead of the ego  previewed  profile alone"]
    for a in rows:
        ahead = f"{a.ahead_m:5.1f} m" if math.isfinite(a.ahead_m) else "   -   "
        lines.append(
            f"  {a.index:5d}  {a.kind:8s} {mm(a.height_mm)}  {a.length_m:4.1f} m   {ahead:>12s}"
            f"     {mm(a.previewed_mm)}  {mm(bare[a.index].previewed_mm)}"
        )
    return "\n".join(lines)
