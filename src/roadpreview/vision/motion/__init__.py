"""The built-in lead finder without a model: vehicles are what the static-scene flow
cannot explain.

* `finder`: `MotionLeadFinder`, the finder the front end runs (history, corners and
  their flow, the run in three slices) and its diagnostics;
* `config`: `MotionFinderConfig`, its settings;
* `egomotion`: the static scene's motion: rotation removed, expansion from the FOE,
  the road's expansion k fitted;
* `clusters`: vehicles as clusters of points that move unlike the road;
* `window`: the lead as a rigid window standing on the road;
* `rear`: a vehicle's rear fitted to the image (`fit_rear`, `RearSearch`).
"""

from __future__ import annotations

from roadpreview.vision.motion.config import MotionFinderConfig
from roadpreview.vision.motion.finder import MotionDiagnostics, MotionLeadFinder, run_steps
from roadpreview.vision.motion.rear import RearFit, RearFitConfig, RearSearch, fit_rear

__all__ = [
    "MotionDiagnostics",
    "MotionFinderConfig",
    "MotionLeadFinder",
    "RearFit",
    "RearFitConfig",
    "RearSearch",
    "fit_rear",
    "run_steps",
]
