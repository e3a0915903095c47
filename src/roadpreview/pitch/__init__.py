"""Camera pitch from background correspondences: the paper's robust LM and its baselines.

Estimators are chosen by name from `ESTIMATORS` (imported lazily)::

    est = make_estimator("robust", camera)
    result = est.estimate(x_ref, x_cur)
    if result:
        phi = result.phi
"""

from __future__ import annotations

from roadpreview.camera import CameraModel
from roadpreview.pitch.base import PitchEstimate, PitchEstimator
from roadpreview.registry import build

#: config name -> (module, class, config class)
ESTIMATORS: dict[str, tuple[str, str, str | None]] = {
    "robust": ("roadpreview.pitch.robust_lm", "RobustPitchEstimator", "RobustPitchConfig"),
    "essential": (
        "roadpreview.pitch.essential",
        "EssentialMatrixPitchEstimator",
        "EssentialPitchConfig",
    ),
    "none": ("roadpreview.pitch.zero", "ZeroPitchEstimator", None),
}


def make_estimator(name: str, camera: CameraModel, **options: object) -> PitchEstimator:
    """Build the estimator registered as ``name``; ``options`` fill its config dataclass."""
    estimator: PitchEstimator = build(
        ESTIMATORS, name, camera, key="pitch.estimator", where="pitch", options=options
    )
    return estimator


__all__ = ["ESTIMATORS", "PitchEstimate", "PitchEstimator", "make_estimator"]
