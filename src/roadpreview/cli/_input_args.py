"""Command-line options that say what a drive is (replay, calibrate, batch): a recording
folder, a video with its calibration, or a ROS bag; with CAN logs and/or an IMU CSV, and
the offsets that put their clocks on one (``docs/inputs.md``).

`add_input_arguments` declares them; `inputs_from_args` turns them into `ReplayInputs`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from roadpreview.apps.replay import ReplayInputs


def add_input_arguments(p: argparse.ArgumentParser, *, camera_required: bool = False) -> None:
    """The input positional and its companions: ``--camera``, ``--can``, ``--imu-csv``,
    ``--frames-csv``, the clock options and the bag's topics."""
    p.add_argument(
        "input",
        type=Path,
        help="a recording folder, a video file, or a ROS bag (rosbag2 folder, .mcap, .db3,"
        " ROS 1 .bag)",
    )
    p.add_argument(
        "--camera",
        type=Path,
        required=camera_required,
        help="camera calibration (TOML), for a video or bag input",
    )
    p.add_argument(
        "--can",
        type=Path,
        action="append",
        default=[],
        help="a CAN log (repeatable): .blf .asc .log .trc .csv .mf4 .db (text ones also .gz)",
    )
    p.add_argument("--imu-csv", type=Path, help="an IMU CSV (smartphone style)")
    p.add_argument("--frames-csv", type=Path, help="frame time stamps (frame,t_s)")
    clocks = p.add_argument_group(
        "clocks",
        "By default frame 0 is at the first sample of a log on Unix time, else at the"
        " video's creation time (or file time minus duration); a log whose clock starts"
        " near 0 starts with the video. Mixed clocks are refused unless an offset is given.",
    )
    clocks.add_argument(
        "--video-start",
        type=float,
        default=None,
        metavar="SECONDS",
        help="time of the video's frame 0 on the drive's clock (Unix time, s)",
    )
    clocks.add_argument(
        "--can-offset",
        type=float,
        default=None,
        metavar="SECONDS",
        help="added to every CAN log's time stamps",
    )
    clocks.add_argument(
        "--imu-offset",
        type=float,
        default=None,
        metavar="SECONDS",
        help="added to the IMU CSV's time stamps (the camera-IMU estimator still refines it)",
    )
    bag = p.add_argument_group("ROS bag topics", "default: the only topic of each type")
    bag.add_argument("--image-topic", help="sensor_msgs/Image or CompressedImage topic")
    bag.add_argument("--imu-topic", help="sensor_msgs/Imu topic")
    bag.add_argument("--speed-topic", help="TwistStamped, TwistWithCovarianceStamped or Odometry")


def inputs_from_args(args: argparse.Namespace, *, truth: bool = False) -> ReplayInputs:
    """The drive the arguments describe (truth events kept only with ``truth``): the same
    `DriveSpec` a batch manifest row gives."""
    from roadpreview.batch.manifest import DriveSpec

    spec = DriveSpec(
        drive="",
        input=args.input,
        camera=args.camera,
        can=tuple(args.can),
        imu_csv=args.imu_csv,
        frames_csv=args.frames_csv,
        video_start_s=args.video_start,
        can_offset_s=args.can_offset,
        imu_offset_s=args.imu_offset,
        image_topic=args.image_topic,
        imu_topic=args.imu_topic,
        speed_topic=args.speed_topic,
    )
    return spec.replay_inputs(truth=truth)
