"""``roadpreview calibrate``: the camera's forward direction and horizon, the IMU's axes and
mount rotation and the camera-IMU time offset, from a drive (``docs/calibration.md``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from roadpreview.cli._input_args import add_input_arguments, inputs_from_args


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "calibrate",
        help="estimate the forward direction, horizon, IMU axes and time offset from a drive",
        description=(
            "Self-calibration from a drive (a recording folder, or a video with --camera and "
            "CAN logs / an IMU CSV). Writes camera.toml (the forward direction t), "
            "mapping.toml (the CAN mapping with the IMU's [mount]: rotation into the car's "
            "axes and time offset; name it in the pipeline configuration's [can] mapping) "
            "and calibration.json, and prints each estimate with its uncertainty."
        ),
    )
    add_input_arguments(p)
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--config", type=Path, help="pipeline configuration (vision, CAN mapping)")
    p.add_argument(
        "--max-seconds", type=float, default=None, help="use at most this much of the drive"
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roadpreview.calib.drive import imu_data, read_tracks
    from roadpreview.calib.estimate import calibrate
    from roadpreview.calib.result import table, write_outputs
    from roadpreview.pipeline.config import PipelineConfig
    from roadpreview.types import CameraFrame, ImuSample

    inputs = inputs_from_args(args)
    config = PipelineConfig.load(args.config) if args.config else PipelineConfig()
    video, sources = inputs.sources(config)
    try:
        frames = (s for s in video if isinstance(s, CameraFrame))
        tracks = read_tracks(frames, inputs.camera, config.vision, max_seconds=args.max_seconds)
        imu_samples = [
            s for src in sources if src is not video for s in src if isinstance(s, ImuSample)
        ]
    finally:
        for src in sources:
            src.close()
    imu = imu_data(imu_samples) if imu_samples else None
    cal = calibrate(tracks, imu, inputs.camera)
    written = write_outputs(cal, args.out, mapping=config.can.mapping)
    print(f"{tracks.frames} frames ({tracks.seconds:.1f} s), {len(imu) if imu else 0} IMU samples")
    print(table(cal))
    print("written: " + ", ".join(str(p) for p in written))
    return 0
