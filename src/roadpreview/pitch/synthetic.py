"""Synthetic two-view scenes with known pitch, for tests and benchmarks.

Static points 5-80 m ahead in a street-like corridor; the camera moves forward
by ``forward_m`` along its calibrated direction t and rotates by the known
``(φ, yaw, roll)``, exactly the model of ``docs/method.md``
(``X_cur = R X_ref - b t``). Outliers are of two kinds: gross mismatches, and a
rigid "vehicle" cluster that moves with the ego car (no parallax), which is what
a lead car looks like to the pitch estimator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.pitch.geometry import rotation

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TwoViewScene:
    """Correspondences ``x_ref -> x_cur`` (pixels) with their truth."""

    x_ref: Array
    x_cur: Array
    #: True for a static background point (the estimator's inliers)
    is_inlier: NDArray[np.bool_]
    phi: float
    yaw: float
    roll: float
    forward_m: float


def _sample_static_points(n: int, rng: np.random.Generator) -> Array:
    z = rng.uniform(5.0, 80.0, n)
    x = rng.uniform(-1.0, 1.0, n) * (2.0 + 0.35 * z)  # corridor widening with depth
    y = rng.uniform(-6.0, 1.4, n)  # from above the camera down to the road (y down)
    return np.stack([x, y, z], axis=1)


def make_two_view_scene(
    camera: CameraModel,
    n: int,
    rng: np.random.Generator,
    *,
    phi: float = 0.0,
    yaw: float = 0.0,
    roll: float = 0.0,
    forward_m: float = 0.6,
    noise_px: float = 1.0,
    outlier_ratio: float = 0.3,
    vehicle_share: float = 0.5,
) -> TwoViewScene:
    """``n`` correspondences visible in both frames.

    ``outlier_ratio`` of them are outliers; ``vehicle_share`` of those belong to
    a rigid vehicle cluster moving with the ego car, the rest are gross
    mismatches. Gaussian noise of ``noise_px`` (per coordinate) is added to both
    images.
    """
    R = rotation([phi, yaw, roll])
    t = camera.t
    n_out = round(outlier_ratio * n)
    n_in = n - n_out
    n_veh = round(vehicle_share * n_out)
    n_gross = n_out - n_veh

    # static inliers: oversample, keep those visible in both frames
    pts_ref: list[Array] = []
    pts_cur: list[Array] = []
    have = 0
    w, h = camera.width, camera.height
    while have < n_in:
        X = _sample_static_points(max(2 * (n_in - have), 64), rng)
        Xc = X @ R.T - forward_m * t
        p1 = camera.project(X)
        p2 = camera.project(Xc)
        ok = (
            np.isfinite(p1).all(1)
            & np.isfinite(p2).all(1)
            & (p1[:, 0] >= 0)
            & (p1[:, 0] < w)
            & (p1[:, 1] >= 0)
            & (p1[:, 1] < h)
            & (p2[:, 0] >= 0)
            & (p2[:, 0] < w)
            & (p2[:, 1] >= 0)
            & (p2[:, 1] < h)
        )
        pts_ref.append(p1[ok])
        pts_cur.append(p2[ok])
        have += int(ok.sum())
    x_ref = np.concatenate(pts_ref)[:n_in]
    x_cur = np.concatenate(pts_cur)[:n_in]

    # a vehicle ahead moving with the ego: only the rotation and a small relative motion
    if n_veh:
        centre = np.array([rng.uniform(-1.0, 1.0), rng.uniform(0.0, 0.6), rng.uniform(8.0, 25.0)])
        Xv = centre + rng.uniform(-1.0, 1.0, (n_veh, 3)) * (0.9, 0.6, 0.05)
        # moving with the ego along the road: up to +-0.1 m per frame longitudinally
        # (3 m/s relative at 30 fps; invisible to the epipolar constraint), plus a
        # lateral drift (sd 5 mm/frame = 0.15 m/s) and a vertical bounce (sd 3 mm/frame
        # = 0.09 m/s), which do bias a fit that does not reject them
        rel = np.array([rng.normal(0.0, 0.005), rng.normal(0.0, 0.003), rng.uniform(-0.1, 0.1)])
        Xv2 = Xv @ R.T + rel
        x_ref = np.concatenate([x_ref, camera.project(Xv)])
        x_cur = np.concatenate([x_cur, camera.project(Xv2)])
    if n_gross:
        g1 = np.column_stack([rng.uniform(0, w, n_gross), rng.uniform(0, h, n_gross)])
        g2 = g1 + rng.normal(0.0, 15.0, (n_gross, 2))
        x_ref = np.concatenate([x_ref, g1])
        x_cur = np.concatenate([x_cur, g2])
    x_ref = x_ref + rng.normal(0.0, noise_px, x_ref.shape)
    x_cur = x_cur + rng.normal(0.0, noise_px, x_cur.shape)
    is_inlier = np.zeros(n, dtype=bool)
    is_inlier[:n_in] = True
    order = rng.permutation(n)
    return TwoViewScene(
        x_ref=x_ref[order],
        x_cur=x_cur[order],
        is_inlier=is_inlier[order],
        phi=phi,
        yaw=yaw,
        roll=roll,
        forward_m=forward_m,
    )
