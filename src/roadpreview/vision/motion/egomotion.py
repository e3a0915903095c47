"""The static scene's motion between two frames: rotation removed, expansion from the FOE.

With the camera's rotation taken out (`derotate`), a static point moves along its ray
from the focus of expansion (FOE), ``x' - foe = (1 + e) (x - foe)`` (`point_motion`
measures e and the motion across the ray). The flat road at y px below the horizon
expands by ``e_g(y) = k y / (f - k y)`` with ``k = Δ / h`` (`road_expansion`), and k is
fitted robustly to the points that move (`fit_road`). Small-image pixels throughout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.pitch.geometry import rotation
from roadpreview.vision.base import F64
from roadpreview.vision.motion.config import MotionFinderConfig


@dataclass(frozen=True)
class ViewGeometry:
    """The reduced image's view of the road on this frame."""

    #: focal length (px)
    f: float
    #: focus of expansion (u, v) (px)
    foe: F64
    #: row of the horizon at this frame's pitch (px)
    v_horizon: float
    #: camera height above the road (m)
    height_m: float


@dataclass(frozen=True)
class PointMotion:
    """Corners tracked between the reference frame and this one, rotation removed.

    Per point (N,): ``a`` its position in the reference frame (N, 2), ``e`` its
    expansion from the FOE, ``rn`` its distance from the FOE (px), ``y`` its row below
    the horizon (px), ``flow_px`` the length of its derotated motion; ``usable``: far
    enough from the FOE for e to mean something, ``radial``: it moves along its ray.
    """

    a: F64
    e: F64
    rn: F64
    y: F64
    flow_px: F64
    usable: NDArray[np.bool_]
    radial: NDArray[np.bool_]


@dataclass(frozen=True)
class RoadFit:
    """The road's expansion per unit height below the horizon, ``k = Δ / h``.

    Falsy with ``reason`` when the ego hardly moves or the road's motion is not
    found; ``road_points`` counts the points that move as road (0 when not fitted).
    """

    k: float = float("nan")
    road_points: int = 0
    reason: str = ""

    def __bool__(self) -> bool:
        return not self.reason


def road_expansion(k: float | F64, y: F64, f: float) -> F64:
    """Expansion e of the flat road at y px below the horizon for k = Δ / h (inf if passed)."""
    den = f - k * y
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(den > 0.0, k * y / den, np.inf)
    return np.asarray(out, np.float64)


def derotate(b: F64, cam: CameraModel, phi: float, yaw: float) -> F64:
    """Current-frame pixels rotated back into the reference frame's orientation."""
    R = rotation([phi, yaw])
    H = cam.K @ R.T @ cam.K_inv
    hb = np.c_[b, np.ones(b.shape[0])] @ H.T
    return np.asarray(hb[:, :2] / hb[:, 2:3], np.float64)


def point_motion(
    a: F64,
    b: F64,
    cam: CameraModel,
    phi: float,
    yaw: float,
    geom: ViewGeometry,
    max_perp_px: float,
) -> PointMotion:
    """Points ``a`` (reference frame) seen at ``b`` (this frame) after a rotation of
    ``phi`` (pitch) and ``yaw``: their expansion from the FOE and whether they move
    along their ray (less than ``max_perp_px`` plus 20 % of the motion across it)."""
    foe = geom.foe
    b_d = derotate(b, cam, phi, yaw)
    r = a - foe
    rn = np.linalg.norm(r, axis=1)
    d = b_d - foe
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.einsum("ij,ij->i", d, r) / (rn * rn) - 1.0
        perp = (r[:, 0] * d[:, 1] - r[:, 1] * d[:, 0]) / rn
    flow_px = np.linalg.norm(b_d - a, axis=1)
    y = a[:, 1] - geom.v_horizon
    usable = (rn > 4.0) & np.isfinite(e)
    radial = usable & (np.abs(perp) <= max_perp_px + 0.2 * flow_px)
    return PointMotion(a=a, e=e, rn=rn, y=y, flow_px=flow_px, usable=usable, radial=radial)


def fit_road(points: PointMotion, geom: ViewGeometry, cfg: MotionFinderConfig) -> RoadFit:
    """Robust 1-D fit of k on the points that move (a grid of k, Cauchy cost)."""
    e, rn, y, f = points.e, points.rn, points.y, geom.f
    sel = points.radial & (y > 2.0) & (points.flow_px > cfg.min_flow_px) & (e > 0.0)
    n = int(np.count_nonzero(sel))
    # the road at 10 m must move by min_parallax_px for the ego to count as moving
    y10 = f * geom.height_m / 10.0
    r10 = max(float(np.median(rn[y > 2.0])) if np.any(y > 2.0) else y10, y10)
    if n < cfg.min_road_points:
        return RoadFit(reason=f"no motion parallax (ego not moving? {n} moving points)")
    es, rs, ys = e[sel], rn[sel], y[sel]
    k_grid = np.geomspace(1e-3, 3.0, 96)
    sig = cfg.noise_px
    eg = road_expansion(k_grid[:, None], ys[None, :], f)
    cost = np.log1p(((rs[None, :] * (es[None, :] - eg)) / sig) ** 2).sum(axis=1)
    j = int(np.argmin(cost))
    # refine on a finer grid between the neighbours
    lo, hi = k_grid[max(j - 1, 0)], k_grid[min(j + 1, k_grid.size - 1)]
    fine = np.linspace(lo, hi, 33)
    eg = road_expansion(fine[:, None], ys[None, :], f)
    res = rs[None, :] * (es[None, :] - eg)
    cost = np.log1p((res / sig) ** 2).sum(axis=1)
    jf = int(np.argmin(cost))
    k = float(fine[jf])
    n_road = int(np.count_nonzero(np.abs(res[jf]) < 2.0 * sig + 0.1 * rs * eg[jf]))
    if n_road < cfg.min_road_points:
        return RoadFit(
            road_points=n_road, reason=f"the road's motion is not found ({n_road} road points)"
        )
    parallax = r10 * float(road_expansion(k, np.array([y10]), f)[0])
    if parallax < cfg.min_parallax_px:
        return RoadFit(
            road_points=n_road,
            reason=f"no motion parallax (road at 10 m moves {parallax:.2f} px)",
        )
    return RoadFit(k=k, road_points=n_road)
