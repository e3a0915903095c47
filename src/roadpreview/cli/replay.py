"""``roadpreview replay``: run a recording through the pipeline and write the outputs."""

from __future__ import annotations

import argparse
import sys
import threading
from pathlib import Path
from typing import Any

from roadpreview.cli._input_args import add_input_arguments, inputs_from_args
from roadpreview.cli._output import add_output_arguments, prepare_output_folder
from roadpreview.cli._pipeline_args import add_pipeline_arguments, pipeline_config

OUTPUTS = "alerts.blf, alerts.jsonl, frames.csv, plots.png, summary.json"


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected seconds, e.g. 12.5") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be >= 0 s")
    return value


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "replay",
        help="replay a recording (video + CAN logs, or a simulator folder) through the pipeline",
        description=(
            "Replay a recording through the pipeline. Give a simulator recording folder, or a "
            "video with --camera and CAN logs / an IMU CSV.\n\n"
            f"Outputs in --out: {OUTPUTS} (and annotated.mp4 with --annotate). They are written "
            "as the replay goes; after SIGINT/SIGTERM they hold every frame processed and "
            'summary.json says "interrupted": true.\n\n'
            "Times: frames.csv has t_unix_s (the log clock) and t_rel_s; the console and the "
            "*_rel_s fields of summary.json count seconds from the video's frame 0, whose Unix "
            "time is printed once."
        ),
    )
    add_input_arguments(p)
    add_output_arguments(p, what=f"{OUTPUTS}")
    add_pipeline_arguments(p)
    p.add_argument(
        "--start",
        type=_seconds,
        default=None,
        metavar="S",
        help="begin at S seconds after the video's frame 0 (earlier frames are decoded and"
        " skipped); default: the beginning",
    )
    p.add_argument(
        "--end",
        type=_seconds,
        default=None,
        metavar="S",
        help="stop after S seconds from the video's frame 0; default: the end",
    )
    p.add_argument(
        "--pace",
        type=float,
        default=None,
        metavar="RATE",
        help="play at RATE times the recorded speed (1: real time); default: as fast as possible",
    )
    p.add_argument(
        "--truth",
        action="store_true",
        help="simulator folder: match the alerts to the true events, print them and add one"
        " row per event to summary.json",
    )
    p.add_argument("--annotate", action="store_true", help="also write annotated.mp4")
    p.add_argument(
        "--allow-missing",
        action="store_true",
        help="exit 0 even when an input gave nothing (a CAN log without a frame or without"
        " a frame the DBC/mapping maps, an IMU CSV without a valid row); the drive is"
        " replayed without it either way and summary.json lists it under unusable_inputs",
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roadpreview.apps.progress import Progress
    from roadpreview.apps.replay import OUTPUT_FILES, format_modes, replay
    from roadpreview.errors import ConfigError
    from roadpreview.loop import Pace, install_signal_handlers

    if args.start is not None and args.end is not None and not args.start < args.end:
        raise ConfigError(f"--start {args.start} s must be before --end {args.end} s")
    inputs = inputs_from_args(args, truth=args.truth)
    config = pipeline_config(args)
    out: Path = args.out
    prepare_output_folder(out, force=args.force, ours=OUTPUT_FILES)
    quiet = getattr(args, "verbosity", 0) < 0
    progress = Progress("replay", enabled=not quiet)
    stop = threading.Event()
    handlers = install_signal_handlers(stop)  # Ctrl-C / SIGTERM: stop, flush, close outputs
    try:
        result = replay(
            inputs,
            config,
            out,
            annotated_video=args.annotate,
            progress=progress,
            stop=stop,
            pace=Pace(args.pace) if args.pace else None,
            start_s=args.start,
            end_s=args.end,
            more_inputs=[p for p in (args.camera, args.config) if p is not None],
        )
    finally:
        handlers.restore()
    t0 = result.video_start_s
    print(
        f"{result.frames} frames in {result.seconds:.1f} s ({result.fps:.1f} fps), "
        f"{len(result.alerts)} alert(s), {result.decode_failures} undecodable frame(s), "
        f"{result.input_errors} CAN input frame(s) skipped"
    )
    print(f"times below: seconds from the video's frame 0 (Unix time {t0:.3f} s)")
    print("fusion modes:")
    print(format_modes(result.mode_changes, t0))
    if result.match is not None:
        print(result.match.table())
    annotated = ", annotated.mp4" if args.annotate else ""
    print(f"outputs in {out}: {OUTPUTS}{annotated}")
    if result.interrupted:
        print("interrupted: the outputs hold everything up to the last frame processed")
        return 130
    for bad in result.unusable_inputs:
        allowed = (
            "allowed by --allow-missing" if args.allow_missing else "--allow-missing to accept"
        )
        print(
            f"roadpreview replay: {'warning' if args.allow_missing else 'error'}: unusable input "
            f"{bad['reason']} (the drive ran without it; {allowed})",
            file=sys.stderr,
        )
    if result.unusable_inputs and not args.allow_missing:
        return 1
    return 0
