"""The recording folder format: what the simulator writes and replay reads.

One folder per drive::

    video.mp4          the camera
    frames.csv         frame index -> time stamp (s, the recording clock: 0 = its start)
    can.blf / .asc / .log   IMU, vehicle speed and wheel speeds as CAN frames
    imu.csv            the same IMU, smartphone style
    camera.toml        K, forward direction t, mounting height
    scenario.toml      how the drive was made (the simulator's scenario, a plain mapping here)
    truth.npz          per-frame and per-IMU-sample ground truth
    truth.json         events, clocks (``can_t0_unix_s``: the Unix time of t = 0), summary
    masks/NNNNNN.png   optional per-frame vehicle-id masks (16-bit PNG)

This module sits below both the simulator and the pipeline: it knows the files,
not how they were made.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview._tomlio import load_toml
from roadpreview.camera import CameraModel
from roadpreview.errors import InputDataError

#: the files a folder must hold to be a recording
REQUIRED = ("scenario.toml", "camera.toml", "truth.npz", "truth.json")
_R = TypeVar("_R", bound="RecordingFolder")

#: CAN log names, in the order they are looked for
CAN_LOGS = ("can.blf", "can.asc", "can.log")


@dataclass(frozen=True)
class RecordingFolder:
    """A recording folder opened for reading (module docstring)."""

    folder: Path
    scenario: dict[str, Any]  #: scenario.toml as a mapping
    camera: CameraModel
    truth: dict[str, NDArray[Any]]
    info: dict[str, Any]  #: truth.json

    @classmethod
    def open(cls: type[_R], folder: str | Path) -> _R:
        folder = Path(folder)
        for name in REQUIRED:
            if not (folder / name).is_file():
                raise InputDataError(f"{folder}: not a roadpreview recording ({name} is missing)")
        try:
            with np.load(folder / "truth.npz") as npz:
                truth = {k: npz[k] for k in npz.files}
        except (OSError, ValueError) as exc:
            raise InputDataError(f"{folder / 'truth.npz'}: not readable ({exc})") from None
        try:
            info = json.loads((folder / "truth.json").read_text())
        except json.JSONDecodeError as exc:
            raise InputDataError(f"{folder / 'truth.json'}: not valid JSON: {exc}") from None
        return cls(
            folder=folder,
            scenario=load_toml(folder / "scenario.toml"),
            camera=CameraModel.load(folder / "camera.toml"),
            truth=truth,
            info=info,
        )

    @property
    def video(self) -> Path:
        return self.folder / "video.mp4"

    @property
    def frames_csv(self) -> Path:
        return self.folder / "frames.csv"

    @property
    def imu_csv(self) -> Path:
        return self.folder / "imu.csv"

    @property
    def t0_unix_s(self) -> float:
        """The Unix time of the recording's t = 0 (the CAN log's clock)."""
        return float(self.info["can_t0_unix_s"])

    @property
    def duration_s(self) -> float:
        return float(self.info["duration_s"])

    @property
    def events(self) -> list[dict[str, Any]]:
        """The true road events (truth.json)."""
        return list(self.info["events"])

    def can_log(self) -> Path:
        """The first CAN log present (blf, asc, then candump)."""
        for name in CAN_LOGS:
            p = self.folder / name
            if p.is_file():
                return p
        raise InputDataError(f"{self.folder}: no CAN log ({', '.join(CAN_LOGS)})")

    def mask(self, frame: int) -> NDArray[np.int16]:
        """The vehicle-id mask of a frame (needs ``output.masks`` at recording time)."""
        path = self.folder / "masks" / f"{frame:06d}.png"
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise InputDataError(f"{path}: no mask (record with output.masks = true)")
        return img.astype(np.int16)


__all__ = ["CAN_LOGS", "REQUIRED", "RecordingFolder"]
