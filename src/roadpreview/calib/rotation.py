"""The IMU's axes from paired angular rates: which gyro axis (and sign) is a reference's
pitch rate, and the full rotation between the two frames when the motion allows it.

The reference is a rate vector in its own frame (the camera's visual rotation rates, or
an INS's body rates); the gyro's samples are in the chip's axes, already aligned in time.
The model is ``v = R g + c``: a rotation R (IMU -> reference), the gyro bias folded into c.
Both series are centred (which removes c), and R is Wahba's problem solved by SVD (Kabsch)
on the paired vectors. Only axes the motion excites constrain R: with the rate covariance's
principal standard deviations s1 >= s2 >= s3, R is determined when two axes are excited
(s2 well above the noise); the third follows from the other two. A car pitches on bumps and
yaws in turns, rolls little; on a straight road it pitches and rolls only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class AxisResult:
    """Which gyro axis, with which sign, is the reference's rate about one axis."""

    axis: int  #: 0, 1, 2 for the chip's x, y, z
    sign: int  #: +1 or -1: reference rate = sign * gyro[axis] (+ bias)
    correlation: float  #: Pearson correlation of the chosen axis (with its sign), 0..1
    correlations: F64  #: (3,) signed correlation of each gyro axis with the reference
    slopes: F64  #: (3,) each axis regressed on the reference (its cosine to the axis)
    n_samples: int
    reason: str = ""  #: why the axis is not clear ('' when it is)

    def __bool__(self) -> bool:
        return not self.reason


@dataclass(frozen=True)
class RotationResult:
    """The rotation taking gyro (chip) vectors to the reference frame, and how well known."""

    R: F64  #: (3, 3); NaN when not determined
    std_deg: float  #: jackknife standard error of the rotation angle, deg
    excitation_rad_s: F64  #: (3,) principal std of the reference rates, largest first
    residual_rad_s: float  #: rms of v - R g after centring, per axis
    n_samples: int
    reason: str = ""  #: why the rotation is not determined ('' when it is)

    def __bool__(self) -> bool:
        return not self.reason


def rate_axis(reference: ArrayLike, gyro: ArrayLike, *, min_correlation: float = 0.5) -> AxisResult:
    """The gyro axis and sign that carry ``reference`` (n,), from (n, 3) ``gyro``.

    Each axis is regressed on the reference (bias-free): its slope is the cosine between
    that axis and the reference's axis (scaled alike for all three by the reference's
    noise), so the largest slope in magnitude wins. Correlation alone cannot choose: an
    axis tilted 5 deg towards the pitch axis sees 9 % of the pitch rate and nothing else
    on a straight road, and correlates almost as well. Not clear when the winner's
    correlation is below ``min_correlation``, or when a second axis has more than half its
    slope (the chip sits between two axes: only the full rotation says how).
    """
    ref = np.asarray(reference, dtype=np.float64).reshape(-1)
    g = np.asarray(gyro, dtype=np.float64).reshape(ref.size, 3)
    ok = np.isfinite(ref) & np.all(np.isfinite(g), axis=1)
    rc = ref[ok] - ref[ok].mean()
    gc = g[ok] - g[ok].mean(axis=0)
    rr = float(rc @ rc) + 1e-300
    slope = (gc.T @ rc) / rr
    corr = (gc.T @ rc) / (np.sqrt(np.sum(gc * gc, axis=0) * rr) + 1e-300)
    order = np.argsort(-np.abs(slope))
    axis = int(order[0])
    best = float(abs(corr[axis]))
    ratio = float(abs(slope[order[1]]) / (abs(slope[axis]) + 1e-300))
    reason = ""
    if best < min_correlation:
        reason = f"best correlation {best:.2f} is below {min_correlation:.2f}"
    elif ratio > 0.5:
        reason = (
            f"two gyro axes carry it alike (slopes {slope[axis]:+.2f} and"
            f" {slope[order[1]]:+.2f}): the chip sits between them"
        )
    return AxisResult(
        axis=axis,
        sign=1 if slope[axis] >= 0 else -1,
        correlation=best,
        correlations=corr,
        slopes=slope,
        n_samples=int(ok.sum()),
        reason=reason,
    )


def _kabsch(v: F64, g: F64) -> F64:
    """The rotation R minimising Σ |v - R g|² (rows are paired vectors, already centred)."""
    U, _, Wt = np.linalg.svd(v.T @ g)
    d = np.sign(np.linalg.det(U @ Wt))
    R: F64 = U @ np.diag([1.0, 1.0, d]) @ Wt
    return R


def rotation_from_rates(
    reference: ArrayLike,
    gyro: ArrayLike,
    *,
    min_excitation_rad_s: float = math.radians(0.3),
    max_std_deg: float = 3.0,
    n_blocks: int = 10,
) -> RotationResult:
    """The rotation gyro (chip) -> reference frame from (n, 3) paired, time-aligned rates.

    Determined when the second principal std of the reference rates reaches
    ``min_excitation_rad_s`` and the delete-one-block jackknife (contiguous blocks)
    puts the rotation's standard error below ``max_std_deg``; otherwise the result is
    falsy and says which axes the drive did not excite.
    """
    v = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    g = np.asarray(gyro, dtype=np.float64).reshape(v.shape[0], 3)
    ok = np.all(np.isfinite(v), axis=1) & np.all(np.isfinite(g), axis=1)
    v, g = v[ok], g[ok]
    n = int(v.shape[0])
    nan3 = np.full((3, 3), np.nan)
    if n < 3 * n_blocks:
        return RotationResult(
            nan3, math.nan, np.full(3, np.nan), math.nan, n,
            reason=f"{n} paired rates (need {3 * n_blocks})",
        )  # fmt: skip
    vc, gc = v - v.mean(axis=0), g - g.mean(axis=0)
    excitation = np.sqrt(np.clip(np.linalg.eigvalsh(vc.T @ vc / n)[::-1], 0.0, None))
    R = _kabsch(vc, gc)
    residual = float(np.sqrt(np.mean((vc - gc @ R.T) ** 2)))
    blocks = np.minimum((np.arange(n) * n_blocks) // n, n_blocks - 1)
    angles = np.array(
        [
            Rotation.from_matrix(_kabsch(vc[blocks != k], gc[blocks != k]) @ R.T).magnitude()
            for k in range(n_blocks)  # ten replicates
        ]
    )
    std = math.degrees(math.sqrt((n_blocks - 1) / n_blocks * float(np.sum(angles**2))))
    reason = ""
    if excitation[1] < min_excitation_rad_s:
        reason = (
            f"only one axis is excited (principal rate std {math.degrees(excitation[0]):.2f},"
            f" {math.degrees(excitation[1]):.2f}, {math.degrees(excitation[2]):.2f} deg/s;"
            f" need {math.degrees(min_excitation_rad_s):.2f} on two: turns and bumps)"
        )
    elif std > max_std_deg:
        reason = f"the rotation is uncertain by {std:.1f} deg (> {max_std_deg:.1f})"
    return RotationResult(
        R=nan3 if reason else R,
        std_deg=std,
        excitation_rad_s=excitation,
        residual_rad_s=residual,
        n_samples=n,
        reason=reason,
    )
