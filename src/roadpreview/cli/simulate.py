"""``roadpreview simulate``: write simulated recordings (one drive, or a labelled data set)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from roadpreview.cli._output import add_output_arguments, prepare_output_folder


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
    add_output_arguments(
        p,
        what="a recording folder; with --dataset one folder per drive and dataset.json,"
        " and a data set folder is resumed (complete drives reused)",
    )
    p.add_argument("--seed", type=int, default=None, help="seed; default: the preset's, 0")
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="override the drive's duration, seconds (the road is lengthened to fit it;"
        " random anomalies spread over it, a preset's placed ones stay); default: the"
        " preset's",
    )
    p.add_argument(
        "--resolution",
        type=_resolution,
        default=None,
        metavar="WxH",
        help="override the image size in pixels, e.g. 640x360; default: the preset's",
    )
    p.add_argument(
        "--fps",
        type=float,
        default=None,
        metavar="HZ",
        help="override the frame rate, frames per second; default: the preset's",
    )
    p.add_argument(
        "--can",
        default=None,
        metavar="FORMATS",
        help="CAN log formats, comma-separated: blf,asc,log; default: the preset's (blf)",
    )
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


#: what a recording folder holds (`roadpreview.sim.recording`): replaced with --force
RECORDING_FILES = (
    "video.mp4",
    "frames.csv",
    "can.blf",
    "can.asc",
    "can.log",
    "imu.csv",
    "camera.toml",
    "scenario.toml",
    "truth.npz",
    "truth.json",
)


def _is_dataset(folder: Path) -> bool:
    """A folder an earlier ``--dataset`` run wrote (it is resumed, not refused)."""
    return (folder / "dataset.json").is_file() or any(folder.glob("drive_[0-9]*"))


class _Counter:
    """``done/total`` progress of drives or frames, through `Progress` (bar or log lines)."""

    def __init__(self, label: str, enabled: bool) -> None:
        from roadpreview.apps.progress import Progress

        self.progress = Progress(label, enabled=enabled)
        self.t0 = time.perf_counter()
        self.started = False

    def __call__(self, done: int, total: int) -> None:
        if not self.started:
            self.progress.start(total)
            self.started = True
        self.progress(done, time.perf_counter() - self.t0)
        if done >= total:
            self.progress.close(done)


def _run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from roadpreview.sim.dataset import build_dataset, drive_config
    from roadpreview.sim.recording import write_recording
    from roadpreview.sim.scenario import ScenarioConfig

    width, height = args.resolution if args.resolution else (None, None)
    enabled = getattr(args, "verbosity", 0) >= 0
    out: Path = args.out
    if args.dataset is not None and out.is_dir() and _is_dataset(out):
        print(f"resuming the data set in {out}: complete drives are reused")
    else:
        prepare_output_folder(out, force=args.force, ours=RECORDING_FILES)
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
            progress=_Counter("drives", enabled),
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
        cfg = drive_config(args.preset, args.seed or 0, width=width, height=height, fps=args.fps)
    if args.duration is not None:
        cfg = cfg.with_duration(args.duration)  # the road sized for it
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
    info = write_recording(cfg, args.out, progress=_Counter("frames", enabled))
    print(
        f"{cfg.name} (seed {cfg.seed}): {info.n_frames} frames, {info.n_imu_samples} IMU samples, "
        f"{info.n_can_frames} CAN frames in {info.seconds:.1f} s -> {info.folder}"
    )
    return 0
