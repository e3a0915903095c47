"""Relative camera motion between two frames from background correspondences (OpenCV's
five-point essential matrix with RANSAC, then ``recoverPose``), in the project's frames.

Camera coordinates are OpenCV's (x right, y down, z optical axis, ``docs/method.md``).
`relative_motion` returns the rotation of camera b relative to camera a as a rotation
vector in a's axes (right-handed: +x is nose up, +y is turning right, +z rolls clockwise
as seen from behind) and the direction of b's optical centre seen from a (the direction of
travel). A pair that cannot tell is a falsy result with the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class RelativeMotion:
    """Camera b relative to camera a (module docstring)."""

    rotvec: F64 = field(default_factory=lambda: np.full(3, np.nan))  #: rad, in a's axes
    direction: F64 = field(default_factory=lambda: np.full(3, np.nan))  #: unit, a's axes
    inliers: int = 0  #: RANSAC inliers that passed the cheirality check
    parallax_px: float = math.nan  #: median displacement left once the rotation is removed
    reason: str = ""  #: why the pair gave nothing ('' when it did)

    def __bool__(self) -> bool:
        return not self.reason


def relative_motion(
    x_a: ArrayLike,
    x_b: ArrayLike,
    K: ArrayLike,
    *,
    threshold_px: float = 1.0,
    min_inliers: int = 20,
    seed: int = 0,
) -> RelativeMotion:
    """The rotation and the translation direction between two views of a static scene.

    ``x_a``, ``x_b``: (n, 2) matching pixels; ``K`` the intrinsics. RANSAC with a
    ``threshold_px`` Sampson distance; fewer than ``min_inliers`` pairs after the
    cheirality check is a failure. The direction is b's optical centre in a's frame,
    ``-Rᵀ t`` for OpenCV's ``x_b = R x_a + t``, signed so that it points ahead (z > 0).
    """
    a = np.ascontiguousarray(np.asarray(x_a, dtype=np.float64).reshape(-1, 2))
    b = np.ascontiguousarray(np.asarray(x_b, dtype=np.float64).reshape(-1, 2))
    k = np.asarray(K, dtype=np.float64)
    if a.shape[0] < max(min_inliers, 5) or a.shape != b.shape:
        return RelativeMotion(reason=f"{a.shape[0]} point pairs (need {max(min_inliers, 5)})")
    cv2.setRNGSeed(seed)
    E, mask = cv2.findEssentialMat(a, b, k, method=cv2.RANSAC, prob=0.999, threshold=threshold_px)
    if E is None or E.shape != (3, 3):
        return RelativeMotion(reason="no essential matrix (degenerate motion)")
    n_in, R, t, mask2 = cv2.recoverPose(E, a, b, k, mask=mask)
    if n_in < min_inliers:
        return RelativeMotion(inliers=int(n_in), reason=f"{n_in} inliers (need {min_inliers})")
    R = np.asarray(R, dtype=np.float64)
    direction = -R.T @ np.asarray(t, dtype=np.float64).reshape(3)
    direction /= np.linalg.norm(direction)
    if direction[2] < 0.0:
        direction = -direction
    # parallax: where the inliers of a land in b under the rotation alone
    sel = np.asarray(mask2).ravel() > 0
    rays = np.column_stack([a[sel], np.ones(int(sel.sum()))]) @ np.linalg.inv(k).T
    p = rays @ (k @ R).T
    moved = np.linalg.norm(p[:, :2] / p[:, 2:3] - b[sel], axis=1)
    return RelativeMotion(
        rotvec=Rotation.from_matrix(R.T).as_rotvec(),
        direction=direction,
        inliers=int(n_in),
        parallax_px=float(np.median(moved)),
    )


def rotation_given_direction(
    x_a: ArrayLike,
    x_b: ArrayLike,
    K: ArrayLike,
    direction: ArrayLike,
    *,
    scale_px: float = 0.5,
    min_points: int = 20,
) -> RelativeMotion:
    """The rotation between two views when the direction of travel is known (3 unknowns
    instead of the essential matrix's 5, so yaw is not traded against sideways motion).

    ``direction`` is the direction of travel in a's axes (the forward direction t).
    With the camera's rotation Q (b's axes in a's frame, rotation vector ω) the essential
    matrix is ``E ∝ Qᵀ [t]x``; ω minimises the Cauchy-robust Sampson distances (pixels,
    ``scale_px``) from zero. The result's direction is the given one.
    """
    a = np.asarray(x_a, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(x_b, dtype=np.float64).reshape(-1, 2)
    if a.shape[0] < min_points or a.shape != b.shape:
        return RelativeMotion(reason=f"{a.shape[0]} point pairs (need {min_points})")
    k = np.asarray(K, dtype=np.float64)
    k_inv = np.linalg.inv(k)
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    d = d / np.linalg.norm(d)
    tx = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
    ha = np.column_stack([a, np.ones(a.shape[0])])
    hb = np.column_stack([b, np.ones(b.shape[0])])

    def sampson(w: F64) -> F64:
        F = k_inv.T @ Rotation.from_rotvec(w).as_matrix().T @ tx @ k_inv
        Fa = ha @ F.T
        Fb = hb @ F
        num = np.einsum("ij,ij->i", hb, Fa)
        den = np.sqrt(Fa[:, 0] ** 2 + Fa[:, 1] ** 2 + Fb[:, 0] ** 2 + Fb[:, 1] ** 2) + 1e-300
        out: F64 = num / den
        return out

    fit = least_squares(sampson, np.zeros(3), loss="cauchy", f_scale=scale_px, x_scale=1e-3)
    res = np.abs(sampson(fit.x))
    inliers = int(np.count_nonzero(res < 3.0 * scale_px))
    if not fit.success or inliers < min_points:
        return RelativeMotion(inliers=inliers, reason=f"{inliers} inliers (need {min_points})")
    return RelativeMotion(rotvec=fit.x, direction=d, inliers=inliers)
