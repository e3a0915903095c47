"""``roadpreview replay``: run a recording through the pipeline and write the outputs."""

from __future__ import annotations

import argparse
import threading
from pathlib import Path
from typing import Any

from roadpreview.cli._input_args import add_input_arguments, inputs_from_args
from roadpreview.cli._pipeline_args import add_pipeline_arguments, pipeline_config


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "replay",
        help="replay a recording (video + CAN logs, or a simulator folder) through the pipeline",
        description=(
            "Replay a recording through the pipeline. Give a simulator recording folder, or a "
            "video with --camera and CAN logs / an IMU CSV. Outputs: alerts.blf, alerts.jsonl, "
            "frames.csv, plots.png, summary.json (and annotated.mp4 with --annotate)."
        ),
    )
    add_input_arguments(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")
    add_pipeline_arguments(p)
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
        help="simulator folder: match the alerts to the true events and print them",
    )
    p.add_argument("--annotate", action="store_true", help="also write annotated.mp4")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roadpreview.apps.replay import (
        format_modes,
        print_progress,
        replay,
    )
    from roadpreview.loop import Pace, install_signal_handlers

    inputs = inputs_from_args(args, truth=args.truth)
    config = pipeline_config(args)
    stop = threading.Event()
    handlers = install_signal_handlers(stop)  # Ctrl-C / SIGTERM: stop, flush, close outputs
    try:
        result = replay(
            inputs,
            config,
            args.out,
            annotated_video=args.annotate,
            progress=print_progress,
            stop=stop,
            pace=Pace(args.pace) if args.pace else None,
        )
    finally:
        handlers.restore()
    print(
        f"\n{result.frames} frames in {result.seconds:.1f} s ({result.fps:.1f} fps), "
        f"{len(result.alerts)} alert(s), {result.decode_failures} undecodable frame(s), "
        f"{result.input_errors} CAN input frame(s) skipped"
    )
    print("fusion modes:")
    print(format_modes(result.mode_changes, result.video_start_s))
    if result.match is not None:
        print(result.match.table())
    print(f"outputs in {args.out}: alerts.blf, alerts.jsonl, frames.csv, plots.png, summary.json")
    if result.interrupted:
        print("interrupted: the outputs hold everything up to the last frame processed")
        return 130
    return 0
