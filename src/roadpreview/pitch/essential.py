"""The paper's baseline: pitch from the essential matrix (5-point RANSAC or USAC).

``cv2.findEssentialMat`` + ``cv2.recoverPose`` give R with ``X_cur = R X_ref + t``;
the pitch is read off R in the convention of ``docs/method.md``
(``R(φ) @ (0, 0, 1) = (0, sin φ, cos φ)``), i.e. ``φ = atan2(R[1, 2], R[2, 2])``
for the rotation about the camera x axis.

OpenCV gives no uncertainty, and the fusion needs one to weigh and gate the
measurement. The reported std is the Gauss-Newton one of the pitch in the full
five-parameter model on the RANSAC inliers: ``E(ε, τ) = [t + τ1 u1 + τ2 u2]x
R_x(ε1) R_y(ε2) R_z(ε3) R`` around the solution (``u1, u2`` orthogonal to
``t``), ``J`` the numerical Jacobian of the signed Sampson distances,
``Cov = σ² (JᵀJ)⁻¹`` and the pitch variance its (ε1, ε1) entry, with ``σ`` the
robust (MAD) scale of the inliers' Sampson distances, floored at a tenth of
the RANSAC threshold. That is the std of an optimal fit to all inliers;
OpenCV's RANSAC returns the best minimal-sample hypothesis without refining it
on the consensus set, and its error does not shrink with the number of points
(on synthetic scenes with 1 px noise it is 6-15 times that bound for 200-2000
points). So the bound is scaled by ``sqrt(n_inliers / effective_points)``: the
answer is treated as a fit to ``effective_points`` correspondences (default 10,
which puts the normalised errors of the synthetic scenes near 1; a test checks
it from 200 to 2000 points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike

from roadpreview.camera import CameraModel
from roadpreview.configtools import check_ranges, param
from roadpreview.pitch.base import (
    PitchEstimate,
    poor_fit_reason,
    too_few,
    validate_correspondences,
)
from roadpreview.pitch.geometry import normalise, rot_pitch, rot_roll, rot_yaw, sampson_terms, skew

_METHODS = {
    "ransac": cv2.RANSAC,
    "usac": getattr(cv2, "USAC_DEFAULT", cv2.RANSAC),
    "usac_magsac": getattr(cv2, "USAC_MAGSAC", cv2.RANSAC),
    "lmeds": cv2.LMEDS,
}


@dataclass(frozen=True)
class EssentialPitchConfig:
    """Settings of `EssentialMatrixPitchEstimator`."""

    method: str = param(
        "ransac",
        choices=tuple(_METHODS),
        help="the paper's baseline is 5-point RANSAC; USAC is OpenCV's faster modern variant",
    )
    threshold_px: float = param(1.0, unit="px", gt=0.0, help="RANSAC inlier threshold")
    confidence: float = param(0.999, gt=0.0, lt=1.0, help="RANSAC success probability")
    max_iters: int = param(1000, ge=1, help="RANSAC iteration cap")
    min_correspondences: int = param(8, ge=5, help="5 for the solver, a few more for RANSAC")
    min_inlier_ratio: float = param(0.25, ge=0.0, le=1.0, help="below: falsy 'poor fit'")
    effective_points: float = param(
        10.0,
        ge=5.0,
        help="the unrefined RANSAC answer is as good as a fit to this many points: scales"
        " the reported std (module docstring)",
    )

    def validate(self, where: str = "") -> None:
        pass


def pitch_from_rotation(R: np.ndarray) -> float:
    """The pitch angle (nose up positive) of a rotation matrix in our convention."""
    return math.atan2(float(R[1, 2]), float(R[2, 2]))


class EssentialMatrixPitchEstimator:
    """Pitch from a full 5-point essential-matrix fit (baseline of the paper)."""

    name = "essential"

    def __init__(self, camera: CameraModel, config: EssentialPitchConfig | None = None) -> None:
        self.camera = camera
        self.config = config or EssentialPitchConfig()
        check_ranges(self.config, "pitch")

    def reset(self) -> None:
        """Stateless: nothing to forget."""

    def estimate(self, x_ref: ArrayLike, x_cur: ArrayLike) -> PitchEstimate:
        cfg = self.config
        a, b, n_invalid = validate_correspondences(x_ref, x_cur)
        n = a.shape[0]
        if (failed := too_few(n, cfg.min_correspondences, n_invalid)) is not None:
            return failed
        K = self.camera.K
        E, mask = cv2.findEssentialMat(
            a,
            b,
            K,
            method=_METHODS[cfg.method],
            prob=cfg.confidence,
            threshold=cfg.threshold_px,
            maxIters=cfg.max_iters,
        )
        if E is None or E.shape[0] < 3 or mask is None:
            return PitchEstimate.failed(
                "essential matrix: no solution", n_points=n, n_invalid=n_invalid
            )
        # several solutions may come stacked (3k x 3): keep the one that puts the most
        # RANSAC inliers in front of both cameras (recoverPose's cheirality test)
        best: tuple[int, np.ndarray, np.ndarray] | None = None
        for k in range(E.shape[0] // 3):  # at most 10 candidate solutions, not points
            n_good, R, t, _ = cv2.recoverPose(E[3 * k : 3 * k + 3], a, b, K, mask=mask.copy())
            if best is None or n_good > best[0]:
                best = (int(n_good), R, t)
        assert best is not None
        n_good, R, t_vec = best
        inlier_ratio = float(np.count_nonzero(mask)) / n
        if n_good < 5:
            # near-zero translation: recoverPose puts every point at infinity and its
            # cheirality vote is empty. The two rotations of E differ by a half turn
            # about the baseline; a car's is the one near the identity.
            R1, R2, _ = cv2.decomposeEssentialMat(E[:3])
            R = min(
                (R1, R2), key=lambda Rk: float(np.arccos(np.clip((np.trace(Rk) - 1) / 2, -1, 1)))
            )
        yaw = math.atan2(float(R[0, 2]), float(R[2, 2]))
        roll = math.atan2(float(R[0, 1]), float(R[1, 1]))
        phi = pitch_from_rotation(R)
        inliers = mask.ravel().astype(bool)
        return PitchEstimate(
            phi=phi,
            std=self._std(R, t_vec.ravel(), a[inliers], b[inliers]),
            inlier_ratio=inlier_ratio,
            iterations=0,
            converged=True,
            n_points=n,
            reason=poor_fit_reason(inlier_ratio, cfg.min_inlier_ratio),
            yaw=yaw,
            roll=roll,
            n_invalid=n_invalid,
        )

    def _std(self, R: np.ndarray, t: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        """Gauss-Newton std of the pitch in the five-parameter model (module docstring)."""
        if a.shape[0] < 6 or not np.all(np.isfinite(t)) or np.linalg.norm(t) == 0:
            return math.nan
        cam = self.camera
        n_ref, n_cur = normalise(a, cam.K), normalise(b, cam.K)
        t = t / np.linalg.norm(t)
        u1 = np.cross(t, (1.0, 0.0, 0.0) if abs(t[0]) < 0.9 else (0.0, 1.0, 0.0))
        u1 /= np.linalg.norm(u1)
        u2 = np.cross(t, u1)

        def distances(p: np.ndarray) -> np.ndarray:
            Rp = rot_pitch(p[0]) @ rot_yaw(p[1]) @ rot_roll(p[2]) @ R
            E = skew(t + p[3] * u1 + p[4] * u2) @ Rp
            r, _, _, D = sampson_terms(E, n_ref, n_cur, cam.fx, cam.fy)
            return r / np.sqrt(D)

        h = 1e-6
        steps = np.eye(5) * h
        # 5 parameters: a loop of 10 vectorised evaluations, not a loop over points
        J = np.column_stack([(distances(e) - distances(-e)) / (2 * h) for e in steps])
        dist = distances(np.zeros(5))
        scale = 1.4826 * float(np.median(np.abs(dist - np.median(dist))))
        sigma = max(scale, 0.1 * self.config.threshold_px)
        try:
            cov = np.linalg.inv(J.T @ J)
        except np.linalg.LinAlgError:
            return math.nan
        var = float(cov[0, 0])
        if not (var > 0 and math.isfinite(var)):
            return math.nan
        inflation = math.sqrt(max(a.shape[0] / self.config.effective_points, 1.0))
        return sigma * math.sqrt(var) * inflation
