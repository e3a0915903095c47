"""Command-line options that say what a drive is (replay, calibrate, batch): a recording
folder, or a video with its calibration, CAN logs and/or an IMU CSV.

`add_input_arguments` declares them; `inputs_from_args` turns them into `ReplayInputs`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from roadpreview.apps.replay import ReplayInputs


def add_input_arguments(p: argparse.ArgumentParser, *, camera_required: bool = False) -> None:
    """The input positional and its companions (``--camera``, ``--can``, ``--imu-csv``,
    ``--frames-csv``, ``--video-start``)."""
    p.add_argument("input", type=Path, help="a recording folder, or a video file")
    p.add_argument(
        "--camera",
        type=Path,
        required=camera_required,
        help="camera calibration (TOML), for a video input",
    )
    p.add_argument("--can", type=Path, action="append", default=[], help="a CAN log (repeatable)")
    p.add_argument("--imu-csv", type=Path, help="an IMU CSV (smartphone style)")
    p.add_argument("--frames-csv", type=Path, help="frame time stamps (frame,t_s)")
    p.add_argument(
        "--video-start",
        type=float,
        default=None,
        help="time of the first frame on the log clock (s); default: first CAN frame",
    )


def inputs_from_args(args: argparse.Namespace, *, truth: bool = False) -> ReplayInputs:
    """The drive the arguments describe (truth events kept only with ``truth``)."""
    from roadpreview.apps.replay import ReplayInputs
    from roadpreview.camera import CameraModel
    from roadpreview.errors import ConfigError

    if args.input.is_dir():
        inputs = ReplayInputs.from_recording(args.input)
        if not truth:
            inputs.truth_events = None
        return inputs
    if args.camera is None:
        raise ConfigError("--camera: a camera calibration is needed for a video input")
    if truth:
        raise ConfigError("--truth needs a simulator recording folder")
    return ReplayInputs(
        video=args.input,
        camera=CameraModel.load(args.camera),
        can_logs=list(args.can),
        imu_csv=args.imu_csv,
        frames_csv=args.frames_csv,
        video_start_s=args.video_start,
    )
