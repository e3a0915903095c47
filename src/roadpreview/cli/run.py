"""``roadpreview run``: the in-vehicle daemon (live camera + CAN bus in, alerts and status out)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import Any

from roadpreview.cli._pipeline_args import add_pipeline_arguments, pipeline_config


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "run",
        help="run the in-vehicle daemon: live camera and CAN bus in, alerts and status out",
        description=(
            "Run the pipeline live until SIGINT/SIGTERM: frames from a camera (device index, "
            "video file played at its recorded pace, or stream URL), IMU and speed from a CAN "
            "bus; RP_ALERT and the periodic RP_STATUS go out on the same or another bus. "
            "Frame and CAN time stamps share the Unix clock (time.time())."
        ),
    )
    add_pipeline_arguments(p)
    p.add_argument("--camera", type=Path, required=True, help="camera calibration (TOML)")
    p.add_argument(
        "--source",
        help="camera: device index, video file or stream URL (default: [daemon] camera_source)",
    )
    p.add_argument(
        "--source-start",
        type=float,
        default=None,
        help="a video file as camera: Unix time of frame 0 (default: when it is opened)",
    )
    p.add_argument(
        "--keep-running",
        action="store_true",
        help="a video file as camera: keep running after it ends (the camera watchdog fires)",
    )
    p.add_argument("--can-interface", help="input bus interface (overrides [can])")
    p.add_argument("--can-channel", help="input bus channel (overrides [can])")
    p.add_argument("--out-interface", help="output bus interface (default: the input bus)")
    p.add_argument("--out-channel", help="output bus channel (default: the input bus)")
    p.add_argument(
        "--alerts-log",
        type=Path,
        help="write the RP_ALERT frames sent to this CAN log (.blf, .asc, .log, ...)",
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roadpreview.apps.daemon import (
        Daemon,
        DaemonOptions,
        install_signal_handlers,
        iter_summary_lines,
    )
    from roadpreview.camera import CameraModel

    config = pipeline_config(args)
    overrides = {
        "input_interface": args.can_interface,
        "input_channel": args.can_channel,
        "output_interface": args.out_interface,
        "output_channel": args.out_channel,
    }
    can_cfg = replace(config.can, **{k: v for k, v in overrides.items() if v is not None})
    config = replace(config, can=can_cfg)
    options = DaemonOptions(
        camera_source=args.source,
        camera_start_s=args.source_start,
        alerts_log=args.alerts_log,
        stop_at_end=not args.keep_running,
    )
    daemon = Daemon(CameraModel.load(args.camera), config, options)
    handlers = install_signal_handlers(daemon.stop_event)
    try:
        summary = daemon.run()
    finally:
        handlers.restore()
    for line in iter_summary_lines(summary):
        print(line)
    return 0
