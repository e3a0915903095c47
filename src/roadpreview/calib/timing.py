"""Offline camera-IMU time offset over a whole drive, whatever the IMU's orientation.

The offset τ is the IMU stamp minus the camera time of the same instant (positive: the
IMU's stamps lag; the convention of ``roadpreview.fusion.timesync``). Visual rotations
between frames ``ta -> tb`` (rotation vectors in camera axes) are compared with the gyro's
mean rate over ``[ta + τ, tb + τ]``, read from the gyro's running integral (exact whatever
the two sampling rates). Because the IMU's axes are not known yet, the score at a lag is
the fraction of the visual rates' variance explained by an affine map of the three gyro
axes (a 3x3 matrix and an offset, i.e. any rotation, scale and bias): a multivariate R².
It is evaluated on a coarse grid over a wide range, then on a fine grid around the coarse
peak, and the peak is refined by a parabola. Its uncertainty is the delete-one-block
jackknife over contiguous blocks of the drive (the per-block sums are kept per lag, so each
jackknife replicate costs a 4x4 solve per lag).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

_MAD_TO_STD = 1.4826


@dataclass(frozen=True)
class TimeOffsetResult:
    """The offset (s), its jackknife standard error, the peak R², what it used."""

    offset_s: float
    std_s: float
    r2: float  #: fraction of the visual rates' variance the gyro explains at the peak
    n_increments: int  #: visual frame-to-frame rotations used
    seconds: float  #: camera time they cover
    lags_s: F64  #: the fine lag grid
    scores: F64  #: R² on the fine grid
    reason: str = ""  #: why there is no estimate ('' when there is)

    def __bool__(self) -> bool:
        return not self.reason


def gyro_integral(t_gyro: ArrayLike, gyro: ArrayLike) -> tuple[F64, F64]:
    """(stamps, running integral (m, 3)) of a gyro whose sample k is the mean rate over
    ``(t[k-1], t[k]]`` (a MEMS output data rate); linear interpolation of the integral
    between stamps is then exact."""
    t = np.asarray(t_gyro, dtype=np.float64).reshape(-1)
    w = np.asarray(gyro, dtype=np.float64).reshape(t.size, -1)
    G = np.zeros_like(w)
    G[1:] = np.cumsum(w[1:] * np.diff(t)[:, None], axis=0)
    return t, G


def mean_rates(t: F64, G: F64, ta: F64, tb: F64) -> F64:
    """Mean gyro rate (n, 3) over each interval ``[ta, tb]`` from the integral ``G``."""
    ends = np.column_stack([np.interp(tb, t, G[:, i]) for i in range(G.shape[1])])
    starts = np.column_stack([np.interp(ta, t, G[:, i]) for i in range(G.shape[1])])
    out: F64 = (ends - starts) / (tb - ta)[:, None]
    return out


def robust_rows(v: F64, sigma: float = 6.0) -> NDArray[np.bool_]:
    """Rows of ``v`` within ``sigma`` robust standard deviations (MAD) of the median in
    every column (gross visual errors are dropped: least squares is not robust)."""
    med = np.median(v, axis=0)
    mad = _MAD_TO_STD * np.median(np.abs(v - med), axis=0) + 1e-12
    keep: NDArray[np.bool_] = np.all(np.abs(v - med) <= sigma * mad, axis=1)
    return keep


def _block_sums(g: F64, v: F64, blocks: NDArray[np.intp], n_blocks: int) -> tuple[F64, F64, F64]:
    """Per lag and block: XᵀX (L, B, 4, 4), Xᵀv (L, B, 4, 3) with X = [g, 1]; vᵀv per
    column (B, 3) and the counts go with ``v``'s block sums in `_r2`."""
    L, n, _ = g.shape
    X = np.concatenate([g, np.ones((L, n, 1))], axis=2)
    onehot = np.zeros((n, n_blocks))
    onehot[np.arange(n), blocks] = 1.0
    XtX = np.einsum("lni,lnj,nb->lbij", X, X, onehot, optimize=True)
    Xtv = np.einsum("lni,nj,nb->lbij", X, v, onehot, optimize=True)
    vv = np.stack([onehot.T @ v, onehot.T @ (v * v)], axis=1)  # (B, 2, 3): sum, sum sq
    return XtX, Xtv, vv


def _r2(XtX: F64, Xtv: F64, vv: F64, count: float) -> F64:
    """Multivariate R² per lag from summed normal equations (L, 4, 4), (L, 4, 3)."""
    beta = np.linalg.solve(XtX + 1e-12 * np.eye(4), Xtv)  # (L, 4, 3)
    explained = np.einsum("lij,lij->l", beta, Xtv)  # Σ fitted·v over the columns
    sst = float(np.sum(vv[1] - vv[0] ** 2 / count))
    ssr = float(np.sum(vv[1])) - explained  # Σ v² - Σ fitted·v
    out: F64 = 1.0 - ssr / max(sst, 1e-300)
    return out


def _peak(lags: F64, r: F64) -> float:
    """Parabolic refinement of the maximum of ``r`` on the even grid ``lags`` (NaN at an
    edge)."""
    j = int(np.argmax(r))
    if j == 0 or j == r.size - 1:
        return math.nan
    rm, r0, rp = float(r[j - 1]), float(r[j]), float(r[j + 1])
    curv = rm - 2.0 * r0 + rp
    delta = 0.5 * (rm - rp) / curv if curv < 0 else 0.0
    return float(lags[j] + min(max(delta, -0.5), 0.5) * (lags[1] - lags[0]))


def estimate_time_offset(
    ta: ArrayLike,
    tb: ArrayLike,
    rotvec: ArrayLike,
    t_gyro: ArrayLike,
    gyro: ArrayLike,
    *,
    min_offset_s: float = -0.3,
    max_offset_s: float = 0.3,
    coarse_step_s: float = 0.01,
    fine_step_s: float = 0.001,
    n_blocks: int = 10,
    min_increments: int = 60,
) -> TimeOffsetResult:
    """The camera-IMU offset from visual rotations and a gyro in unknown axes (module doc).

    ``ta``, ``tb`` (n,): camera times of each visual rotation ``rotvec`` (n, 3, rad);
    ``t_gyro`` (m,), ``gyro`` (m, 3): stamps (IMU clock) and rates (rad/s) in the chip's
    axes. Increments whose shifted interval the gyro does not cover at every lag are left
    out. A falsy result says why there is no estimate (too few increments, no rotation,
    peak on the edge of the range).
    """
    a = np.asarray(ta, dtype=np.float64).reshape(-1)
    b = np.asarray(tb, dtype=np.float64).reshape(-1)
    rv = np.asarray(rotvec, dtype=np.float64).reshape(-1, 3)
    tg, G = gyro_integral(t_gyro, gyro)
    ok = (
        np.all(np.isfinite(rv), axis=1)
        & (b > a)
        & (a + min_offset_s >= tg[0])
        & (b + max_offset_s <= tg[-1])
    )
    a, b, rv = a[ok], b[ok], rv[ok]
    v = rv / (b - a)[:, None]
    if v.shape[0] >= min_increments:
        keep = robust_rows(v)
        a, b, v = a[keep], b[keep], v[keep]
    n = int(v.shape[0])
    empty = np.empty(0)
    if n < min_increments:
        return TimeOffsetResult(
            math.nan, math.nan, math.nan, n, 0.0, empty, empty,
            reason=f"{n} visual rotations within the gyro's span (need {min_increments})",
        )  # fmt: skip
    seconds = float(np.sum(b - a))
    blocks = np.minimum((np.arange(n) * n_blocks) // n, n_blocks - 1)

    def scores(lags: F64) -> tuple[F64, F64, F64, F64]:
        g = np.stack([mean_rates(tg, G, a + lag, b + lag) for lag in lags])  # (L, n, 3)
        XtX, Xtv, vv = _block_sums(g, v, blocks, n_blocks)
        r = _r2(XtX.sum(axis=1), Xtv.sum(axis=1), vv.sum(axis=0), n)
        return r, XtX, Xtv, vv

    n_coarse = round((max_offset_s - min_offset_s) / coarse_step_s)
    coarse = min_offset_s + coarse_step_s * np.arange(n_coarse + 1.0)
    rc = scores(coarse)[0]
    jc = int(np.argmax(rc))
    if jc == 0 or jc == coarse.size - 1:
        return TimeOffsetResult(
            math.nan, math.nan, float(rc[jc]), n, seconds, coarse, rc,
            reason=f"the correlation peaks at the edge of the search range ({coarse[jc]:+.3f} s)",
        )  # fmt: skip
    half = round(2 * coarse_step_s / fine_step_s)
    fine = coarse[jc] + fine_step_s * np.arange(-half, half + 1.0)
    r, XtX, Xtv, vv = scores(fine)
    offset = _peak(fine, r)
    if not math.isfinite(offset):
        return TimeOffsetResult(
            math.nan, math.nan, float(r.max()), n, seconds, fine, r,
            reason="the fine correlation peaks at the edge of its grid (no clear peak)",
        )  # fmt: skip
    # delete-one-block jackknife
    counts = np.bincount(blocks, minlength=n_blocks).astype(np.float64)
    XtX_all, Xtv_all, vv_all = XtX.sum(axis=1), Xtv.sum(axis=1), vv.sum(axis=0)
    reps = np.array(
        [
            _peak(
                fine,
                _r2(XtX_all - XtX[:, k], Xtv_all - Xtv[:, k], vv_all - vv[k], n - counts[k]),
            )
            for k in range(n_blocks)  # ten replicates, not points
        ]
    )
    reps = reps[np.isfinite(reps)]
    m = reps.size
    std = math.sqrt((m - 1) / m * float(np.sum((reps - reps.mean()) ** 2))) if m > 1 else math.inf
    return TimeOffsetResult(
        offset_s=offset,
        std_s=max(std, fine_step_s / math.sqrt(12.0)),
        r2=float(r.max()),
        n_increments=n,
        seconds=seconds,
        lags_s=fine,
        scores=r,
    )
