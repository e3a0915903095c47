"""Compensation: the lead's row less the ego camera's own motion, y_c = y - f tan φ -
f Δz / d (paper eq. 4 and our heave term; ``docs/method.md``).

* `compensation`, `compensate`, `heave_term_px`: the model over numpy arrays;
* `Compensator`: the pipeline's stage per frame (the heave observer and the held heave
  term), returning `Compensated` (y_c and each term subtracted).
"""

from __future__ import annotations

from roadpreview.compensation.model import compensate, compensation, heave_term_px
from roadpreview.compensation.stage import Compensated, Compensator, HeaveTerm

__all__ = ["Compensated", "Compensator", "HeaveTerm", "compensate", "compensation", "heave_term_px"]
