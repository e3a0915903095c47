"""The built-in lead finder without a model (the module is `finder`; split follows)."""

from __future__ import annotations

from roadpreview.vision.motion.finder import (
    MotionDiagnostics,
    MotionFinderConfig,
    MotionLeadFinder,
    RearFit,
    RearSearch,
    _masked_median,
    fit_rear,
    run_steps,
)

__all__ = [
    "MotionDiagnostics",
    "MotionFinderConfig",
    "MotionLeadFinder",
    "RearFit",
    "RearSearch",
    "_masked_median",
    "fit_rear",
    "run_steps",
]
