"""``roadpreview run``: the in-vehicle daemon (live camera + CAN bus in, alerts and status out)."""

from __future__ import annotations

import argparse
import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

from roadpreview.cli._pipeline_args import add_pipeline_arguments, pipeline_config

log = logging.getLogger(__name__)


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "run",
        help="run the in-vehicle daemon: live camera and CAN bus in, alerts and status out",
        description=(
            "Run the pipeline live until SIGINT/SIGTERM: frames from a camera (device index, "
            "video file played at its recorded pace, or stream URL), IMU and speed from a CAN "
            "bus; RP_ALERT and the periodic RP_STATUS go out on the same or another bus. "
            "Frame and CAN time stamps share the Unix clock (time.time()). Without hardware: "
            "a video file as --source and --can-log FILE played onto a virtual bus. Under "
            "systemd (Type=notify): READY, WATCHDOG and STATUS notifications; see "
            "docs/daemon.md."
        ),
    )
    add_pipeline_arguments(p)
    p.add_argument("--camera", type=Path, required=True, help="camera calibration (TOML)")
    p.add_argument(
        "--source",
        help="camera: device index or /dev/videoN (V4L2), video file, stream URL, or a "
        "GStreamer pipeline ('gst:...' or holding ' ! '; only with an OpenCV built with "
        "GStreamer) (default: [daemon] camera_source)",
    )
    p.add_argument(
        "--camera-width", type=int, help="frame width to request (px; overrides [daemon])"
    )
    p.add_argument(
        "--camera-height", type=int, help="frame height to request (px; overrides [daemon])"
    )
    p.add_argument(
        "--camera-fps", type=float, help="frame rate to request (1/s; overrides [daemon])"
    )
    p.add_argument(
        "--source-start",
        type=float,
        default=None,
        help="a video file as camera: Unix time of frame 0 (default: when it is opened)",
    )
    p.add_argument(
        "--can-log",
        type=Path,
        help="play this CAN log (.blf, .asc, .log, .trc, .csv) onto the input bus at its "
        "recorded pace, re-stamped onto the daemon's clock (the input bus is python-can's "
        "'virtual' unless --can-interface is given)",
    )
    p.add_argument(
        "--can-log-loop", action="store_true", help="start the CAN log over when it ends"
    )
    p.add_argument(
        "--video-start",
        type=float,
        default=None,
        help="with --can-log and a video file: the log's time stamp of frame 0 (s); "
        "default: the log's first frame",
    )
    p.add_argument(
        "--rate",
        type=float,
        default=1.0,
        help="a video file (and its --can-log): play at this multiple of the recorded "
        "speed; other than 1 only on the virtual interface (default: 1)",
    )
    p.add_argument(
        "--frames-csv",
        type=Path,
        help="a video file as camera: its frame time stamps (frame,t_s); default: index / fps",
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
    p.add_argument(
        "--frame-table",
        type=Path,
        help="write the per-frame table (CSV) as replay writes its frames.csv",
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
    from roadpreview.configtools import check_ranges
    from roadpreview.errors import ConfigError

    config = pipeline_config(args)
    interface = args.can_interface
    if args.can_log is not None:
        if interface is None:
            interface = "virtual"  # never a car's bus unless asked for
        elif interface != "virtual":
            log.warning(
                "event=can_log_on_real_bus interface=%s channel=%s: the recorded frames are "
                "sent onto this bus",
                interface,
                args.can_channel or config.can.input_channel,
            )
    elif args.video_start is not None or args.can_log_loop:
        raise ConfigError("--video-start and --can-log-loop need --can-log")
    camera_overrides = {
        "camera_width": args.camera_width,
        "camera_height": args.camera_height,
        "camera_fps": args.camera_fps,
    }
    daemon_cfg = replace(
        config.daemon, **{k: v for k, v in camera_overrides.items() if v is not None}
    )
    overrides = {
        "input_interface": interface,
        "input_channel": args.can_channel,
        "output_interface": args.out_interface,
        "output_channel": args.out_channel,
    }
    can_cfg = replace(config.can, **{k: v for k, v in overrides.items() if v is not None})
    config = replace(config, can=can_cfg, daemon=daemon_cfg)
    check_ranges(config.daemon, "daemon")
    options = DaemonOptions(
        camera_source=args.source,
        camera_start_s=args.source_start,
        alerts_log=args.alerts_log,
        frame_table=args.frame_table,
        frames_csv=args.frames_csv,
        stop_at_end=not args.keep_running,
        can_log=args.can_log,
        can_log_loop=args.can_log_loop,
        video_start_s=args.video_start,
        rate=args.rate,
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
