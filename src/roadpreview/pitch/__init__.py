"""Camera pitch from background correspondences: the paper's robust LM and its baselines.

Estimators are chosen by name from `ESTIMATORS` (imported lazily)::

    est = make_estimator("robust", camera)
    result = est.estimate(x_ref, x_cur)
    if result:
        phi = result.phi
"""

from __future__ import annotations

import importlib
from typing import Any

from roadpreview.camera import CameraModel
from roadpreview.errors import ConfigError
from roadpreview.pitch.base import PitchEstimate, PitchEstimator

#: config name -> (module, class, config class)
ESTIMATORS: dict[str, tuple[str, str, str | None]] = {
    "robust": ("roadpreview.pitch.robust_lm", "RobustPitchEstimator", "RobustPitchConfig"),
    "essential": (
        "roadpreview.pitch.essential",
        "EssentialMatrixPitchEstimator",
        "EssentialPitchConfig",
    ),
    "none": ("roadpreview.pitch.none", "NoCompensation", None),
}


def make_estimator(name: str, camera: CameraModel, **options: Any) -> PitchEstimator:
    """Build the estimator registered as ``name``; ``options`` fill its config dataclass."""
    try:
        module_name, cls_name, cfg_name = ESTIMATORS[name]
    except KeyError:
        raise ConfigError(
            f"pitch.estimator = {name!r}: unknown; choose one of {sorted(ESTIMATORS)}"
        ) from None
    module = importlib.import_module(module_name)
    cls = getattr(module, cls_name)
    if cfg_name is None:
        if options:
            raise ConfigError(f"pitch estimator {name!r} takes no options, got {sorted(options)}")
        return cls(camera)
    from roadpreview.configtools import from_mapping

    config = from_mapping(getattr(module, cfg_name), options, where="pitch")
    return cls(camera, config)


__all__ = ["ESTIMATORS", "PitchEstimate", "PitchEstimator", "make_estimator"]
