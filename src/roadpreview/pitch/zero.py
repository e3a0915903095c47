"""The paper's other baseline: no compensation (the pitch is taken as zero)."""

from __future__ import annotations

from numpy.typing import ArrayLike

from roadpreview.camera import CameraModel
from roadpreview.pitch.base import PitchEstimate, validate_correspondences


class ZeroPitchEstimator:
    """Always reports zero pitch, so ``y_c = y``: the uncompensated baseline."""

    name = "none"

    def __init__(self, camera: CameraModel | None = None, config: object | None = None) -> None:
        self.camera = camera

    def reset(self) -> None:
        """Stateless."""

    def estimate(self, x_ref: ArrayLike, x_cur: ArrayLike) -> PitchEstimate:
        a, _, n_invalid = validate_correspondences(x_ref, x_cur)
        return PitchEstimate(
            phi=0.0,
            std=0.0,
            inlier_ratio=1.0,
            iterations=0,
            converged=True,
            n_points=a.shape[0],
            n_invalid=n_invalid,
        )
