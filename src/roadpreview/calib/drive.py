"""Read a drive for calibration: the camera's frame-to-frame rotations and directions of
travel (vision front end -> `motion.relative_motion`), and the IMU's samples in the chip's
own axes. This is the I/O side; the estimates are made by the pure modules.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.canbus.samples import RATE_SIGNS
from roadpreview.types import CameraFrame, ImuSample
from roadpreview.vision.frontend import VisionConfig, VisionFrontEnd

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class FramePair:
    """Background correspondences between two frames (full-resolution pixels)."""

    ta: float  #: camera time of the earlier frame
    tb: float  #: camera time of the later frame
    x_a: F64  #: (n, 2)
    x_b: F64  #: (n, 2)


@dataclass(frozen=True)
class DriveTracks:
    """What the camera saw: pairs of consecutive frames, and per key frame its longest pair."""

    consecutive: list[FramePair]
    key_pairs: list[FramePair]  #: one per key frame: the key and its last tracked frame
    frames: int  #: frames read
    seconds: float  #: camera time from the first to the last frame


@dataclass(frozen=True)
class ImuData:
    """The IMU as it delivered its samples: stamps and the chip's own axes (ISO 8855 order,
    before any mount rotation)."""

    t: F64  #: (m,) stamps, IMU clock
    gyro: F64  #: (m, 3) right-handed rates about the chip's x, y, z, rad/s
    accel: F64  #: (m, 3) specific force along the chip's axes, m/s² (NaN if absent)

    def __len__(self) -> int:
        return int(self.t.size)


def read_tracks(
    frames: Iterable[CameraFrame],
    camera: CameraModel,
    config: VisionConfig | None = None,
    *,
    max_seconds: float | None = None,
    progress: Callable[[int], None] | None = None,
) -> DriveTracks:
    """Background tracks over a drive from the pipeline's vision front end (vehicles
    masked): the pairs of consecutive frames, and for each key frame the pair from it to
    the last frame its tracks reached (the longest baseline)."""
    fe = VisionFrontEnd(camera, config)
    consecutive: list[FramePair] = []
    keys: dict[int, FramePair] = {}
    n = 0
    t_first = t_last = math.nan
    prev_t = math.nan
    for frame in frames:
        t = frame.t_s
        if max_seconds is not None and n and t - t_first > max_seconds:
            break
        if n == 0:
            t_first = t
        n += 1
        t_last = t
        bg = fe.process(t, frame.image).background
        if progress is not None:
            progress(n)
        if bg and bg.x_prev.shape[0] and math.isfinite(prev_t):
            consecutive.append(FramePair(prev_t, t, bg.x_prev, bg.x_cur_ff))
            keys[bg.key_index] = FramePair(bg.key_t, t, bg.x_key, bg.x_cur)
        prev_t = t if frame.image is not None else math.nan
    return DriveTracks(
        consecutive=consecutive,
        key_pairs=list(keys.values()),
        frames=n,
        seconds=(t_last - t_first) if n else 0.0,
    )


def imu_data(samples: Iterable[ImuSample]) -> ImuData:
    """The gyro and accelerometer samples (those with all three rates) in the chip's axes:
    roadpreview's rates back to right-handed rates about x, y, z (`RATE_SIGNS`)."""
    rows = [
        (s.t_s, *s.rates_rad_s, *s.accel_m_s2)
        for s in samples
        if not any(math.isnan(r) for r in s.rates_rad_s)
    ]
    a = np.asarray(rows, dtype=np.float64).reshape(-1, 7)
    order = np.argsort(a[:, 0], kind="stable")
    a = a[order]
    return ImuData(t=a[:, 0].copy(), gyro=a[:, 1:4] * RATE_SIGNS, accel=a[:, 4:7].copy())
