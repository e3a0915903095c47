"""The forward direction t (focus of expansion) from directions of travel over straight
driving, the horizon row and the camera's mounting pitch it implies, and the vehicle's
body axes in camera coordinates.

Each direction is a unit vector in camera coordinates (x right, y down, z ahead); over a
drive the body pitches and rolls about its rest attitude, so the robust centre of many
directions is the direction of travel at rest, ``CameraModel.forward``. Sign conventions
are those of ``docs/method.md``: a camera looking up by φ sees the direction of travel
below its optical axis, ``t = (0, sin φ, cos φ)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

#: a direction further than this many robust standard deviations from the median is dropped
_OUTLIER_SIGMA = 3.0
_MAD_TO_STD = 1.4826


@dataclass(frozen=True)
class ForwardEstimate:
    """The direction of travel at rest in camera coordinates, with its uncertainty."""

    t: F64  #: unit 3-vector (z > 0); NaN when nothing could be estimated
    yaw_rad: float  #: atan(t_x / t_z): the direction of travel right of the optical axis
    pitch_rad: float  #: atan(t_y / t_z): the camera's mounting pitch, nose up positive
    yaw_std_rad: float  #: standard error of ``yaw_rad``
    pitch_std_rad: float  #: standard error of ``pitch_rad``
    n_used: int  #: directions kept (independent pairs)
    n_rejected: int  #: directions dropped as outliers
    reason: str = ""  #: why there is no estimate ('' when there is)

    def __bool__(self) -> bool:
        return not self.reason


def forward_direction(directions: ArrayLike, *, min_directions: int = 5) -> ForwardEstimate:
    """Robust centre of (n, 3) directions of travel, and its standard error.

    The directions become two angles (yaw = atan(x/z), pitch = atan(y/z)); those further
    than 3 robust sigmas (1.4826 MAD) from the median in either angle are dropped; the
    estimate is the mean of the rest and its standard error the sample std over sqrt(n).
    The directions must be independent (one per key frame), or the error is optimistic.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d[np.all(np.isfinite(d), axis=1) & (d[:, 2] > 0.0)]
    nan = math.nan
    if d.shape[0] < min_directions:
        return ForwardEstimate(
            np.full(3, nan), nan, nan, nan, nan, int(d.shape[0]), 0,
            reason=f"{d.shape[0]} usable directions of travel (need {min_directions})",
        )  # fmt: skip
    ang = np.column_stack([np.arctan2(d[:, 0], d[:, 2]), np.arctan2(d[:, 1], d[:, 2])])
    med = np.median(ang, axis=0)
    spread = _MAD_TO_STD * np.median(np.abs(ang - med), axis=0) + 1e-9
    keep = np.all(np.abs(ang - med) <= _OUTLIER_SIGMA * spread, axis=1)
    kept = ang[keep]
    n = int(kept.shape[0])
    mean = kept.mean(axis=0)
    std = kept.std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.full(2, math.inf)
    t = np.array([math.tan(mean[0]), math.tan(mean[1]), 1.0])
    t /= np.linalg.norm(t)
    return ForwardEstimate(
        t=t,
        yaw_rad=float(mean[0]),
        pitch_rad=float(mean[1]),
        yaw_std_rad=float(std[0]),
        pitch_std_rad=float(std[1]),
        n_used=n,
        n_rejected=int(d.shape[0] - n),
    )


def focus_of_expansion(t: ArrayLike, K: ArrayLike) -> tuple[float, float]:
    """The pixel (u, v) where the direction ``t`` images: ``K t`` (the focus of expansion;
    its row is the horizon of a level road)."""
    p = np.asarray(K, dtype=np.float64) @ np.asarray(t, dtype=np.float64).reshape(3)
    return float(p[0] / p[2]), float(p[1] / p[2])


def body_axes_in_camera(t: ArrayLike) -> F64:
    """(3, 3) rotation taking body vectors (ISO 8855: x forward, y left, z up) to camera
    coordinates: x_body = t; y_body = the camera's -x made orthogonal to t (the camera is
    taken not to be rolled on the car); z_body = x_body × y_body."""
    x = np.asarray(t, dtype=np.float64).reshape(3)
    x = x / np.linalg.norm(x)
    left = np.array([-1.0, 0.0, 0.0])
    y = left - (left @ x) * x
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    out: F64 = np.column_stack([x, y, z])
    return out
