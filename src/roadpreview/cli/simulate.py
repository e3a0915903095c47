"""``roadpreview simulate``: write simulated recordings (one drive, or a labelled data set)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"resolution {text!r}: expected WIDTHxHEIGHT, e.g. 1280x720"
        ) from None
    return w, h


def add_subparser(sub: Any) -> None:
    from roadpreview.sim.presets import PRESETS

    p: argparse.ArgumentParser = sub.add_parser(
        "simulate",
        help="write a simulated drive (video, CAN, IMU, truth) or a labelled data set",
        description=(
            "Simulate a drive with ground truth and write it as a recording folder: video.mp4, "
            "can.blf, imu.csv, camera.toml, scenario.toml, truth.npz/json."
        ),
    )
    src = p.add_mutually_exclusive_group()
    src.add_argument("--preset", choices=sorted(PRESETS), default="demo", help="named scenario")
    src.add_argument("--scenario", type=Path, help="a scenario.toml to run instead of a preset")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=int, default=None, help="seed (default: the preset's 0)")
    p.add_argument("--duration", type=float, default=None, help="override the duration, s")
    p.add_argument("--resolution", type=_resolution, default=None, help="override, e.g. 640x360")
    p.add_argument("--fps", type=float, default=None, help="override the frame rate")
    p.add_argument("--can", default=None, help="CAN log formats, comma-separated: blf,asc,log")
    p.add_argument("--masks", action="store_true", help="also write per-frame vehicle masks")
    p.add_argument(
        "--write-scenario",
        action="store_true",
        help="only write scenario.toml (to edit and run with --scenario)",
    )
    p.add_argument(
        "--dataset",
        type=int,
        metavar="N",
        default=None,
        help="build a labelled data set of N drives (seeds seed..seed+N-1)",
    )
    p.add_argument("--jobs", type=int, default=2, help="parallel processes for --dataset")
    p.set_defaults(func=_run)


def _progress(done: int, total: int) -> None:
    if sys.stderr.isatty():
        print(f"\r  {done}/{total}", end="" if done < total else "\n", file=sys.stderr)


def _run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from roadpreview.sim.dataset import build_dataset, drive_config
    from roadpreview.sim.recording import write_recording
    from roadpreview.sim.scenario import ScenarioConfig

    width, height = args.resolution if args.resolution else (None, None)
    if args.dataset is not None:
        clips = build_dataset(
            args.out,
            preset_name=args.preset,
            n_drives=args.dataset,
            seed=args.seed or 0,
            jobs=args.jobs,
            duration_s=args.duration,
            width=width,
            height=height,
            progress=_progress,
        )
        n_pos = sum(c.label for c in clips)
        n_hard = sum(1 for c in clips if c.label and c.hard)
        print(
            f"data set in {args.out}: {n_pos} anomaly clips ({n_hard} hard), "
            f"{len(clips) - n_pos} background clips -> {args.out / 'dataset.json'}"
        )
        return 0
    if args.scenario is not None:
        cfg = ScenarioConfig.load(args.scenario)
        if args.seed is not None:
            cfg = replace(cfg, seed=args.seed)
    else:
        cfg = drive_config(
            args.preset,
            args.seed or 0,
            duration_s=args.duration,
            width=width,
            height=height,
            fps=args.fps,
        )
    if args.can:
        cfg = replace(cfg, output=replace(cfg.output, can_formats=args.can.split(",")))
    if args.masks:
        cfg = replace(cfg, output=replace(cfg.output, masks=True))
    cfg.validate()
    if args.write_scenario:
        args.out.mkdir(parents=True, exist_ok=True)
        cfg.save(args.out / "scenario.toml")
        print(f"wrote {args.out / 'scenario.toml'}")
        return 0
    info = write_recording(cfg, args.out, progress=_progress)
    print(
        f"{cfg.name} (seed {cfg.seed}): {info.n_frames} frames, {info.n_imu_samples} IMU samples, "
        f"{info.n_can_frames} CAN frames in {info.seconds:.1f} s -> {info.folder}"
    )
    return 0
