"""The experiments: the paper's Fig. 4-7 and Table I, then ours (texture loss, range, lead
time). Each takes the processed data (`EvalData`) and returns a frozen dataclass of
numbers (its ``as_dict()`` is the JSON of ``results.json``); `roadpreview.eval.suite`
runs them and draws their figures (`roadpreview.eval.figures`), and
`roadpreview.eval.report` writes the report from the JSON.

* `signal_distance` (E1, Fig. 4): s at the bump crossings of the ``controlled`` drives vs
  the lead distance, the fit s(d) = α f δ / d + β, the separation distance.
* `ego_bump` (E2, Fig. 5): pitch of each method vs the truth and y_c while the ego crosses
  a bump.
* `fpr_rotation` (E3, Fig. 6): false-positive rate of background windows vs the ego's
  rotation intensity.
* `table1` (E4, Table I, Fig. 7): cross-validated balanced accuracy and F-score, AUC,
  entire / hard / easy, ROC curves; `ceiling`: the detector on the true trajectory.
* `texture_loss`, `detection_range`, `lead_time` (E5): texture loss, detection range per
  resolution, alert lead time.
* `data`: `EvalData`, the recordings loaded once; `base`: shared helpers.
"""

from roadpreview.eval.experiments.ceiling import (
    ceiling_s,
    ceiling_scores,
    true_compensated_y,
    true_trajectory,
    windowed_std,
)
from roadpreview.eval.experiments.data import EvalData
from roadpreview.eval.experiments.detection_range import DetectionRange, detection_range
from roadpreview.eval.experiments.ego_bump import EgoBump, ego_bump
from roadpreview.eval.experiments.fpr_rotation import FprVsRotation, fpr_vs_rotation
from roadpreview.eval.experiments.lead_time import LeadTime, lead_time
from roadpreview.eval.experiments.signal_distance import SignalVsDistance, signal_vs_distance
from roadpreview.eval.experiments.table1 import Table1, table1, thresholds_of
from roadpreview.eval.experiments.texture_loss import TextureLoss, texture_loss

__all__ = [
    "DetectionRange",
    "EgoBump",
    "EvalData",
    "FprVsRotation",
    "LeadTime",
    "SignalVsDistance",
    "Table1",
    "TextureLoss",
    "ceiling_s",
    "ceiling_scores",
    "detection_range",
    "ego_bump",
    "fpr_vs_rotation",
    "lead_time",
    "signal_vs_distance",
    "table1",
    "texture_loss",
    "thresholds_of",
    "true_compensated_y",
    "true_trajectory",
    "windowed_std",
]
