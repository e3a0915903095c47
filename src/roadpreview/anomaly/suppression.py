"""Why alerts are held back at a frame: hard lead manoeuvres, a DEGRADED fusion, an
IMU_ONLY fusion whose gyro bias has not settled (``docs/detector.md``, "Suppression").

`SuppressionTracker` is shared by the detectors: each cause taints the frames
whose detector window still holds its samples, plus a settling time
(``span_s``, the detector's window plus a hold).
"""

from __future__ import annotations

import math

from roadpreview.anomaly.base import TrajectorySample
from roadpreview.types import FusionMode, SuppressionReason


class SuppressionTracker:
    """The `SuppressionReason` of each pushed frame (times increasing)."""

    def __init__(self, *, lead_accel_limit_mps2: float, settle_s: float, span_s: float) -> None:
        self.lead_accel_limit_mps2 = lead_accel_limit_mps2
        self.settle_s = settle_s
        self.span_s = span_s
        self._last_cause_t = {
            SuppressionReason.LEAD_ACCEL: -math.inf,
            SuppressionReason.DEGRADED: -math.inf,
            SuppressionReason.SETTLING: -math.inf,
        }
        self.fused_s = 0.0  #: time the fusion has been FUSED so far (kept over restarts)
        self._fused_t = math.nan  # time of the last FUSED sample
        #: the longest interval that counts towards `fused_s` (a gap counts this much)
        self.max_step_s = span_s

    def push(self, sample: TrajectorySample) -> SuppressionReason:
        """The reasons in force at ``sample``'s frame."""
        t = sample.t
        accel = sample.lead_accel_mps2
        if accel is not None and math.isfinite(accel) and abs(accel) > self.lead_accel_limit_mps2:
            self._last_cause_t[SuppressionReason.LEAD_ACCEL] = t
        if sample.mode == FusionMode.DEGRADED:
            self._last_cause_t[SuppressionReason.DEGRADED] = t
        if sample.mode == FusionMode.FUSED:
            if math.isfinite(self._fused_t):
                # a frame interval, or at most one window across a gap
                self.fused_s += min(t - self._fused_t, self.max_step_s)
            self._fused_t = t
        else:
            self._fused_t = math.nan
            if sample.mode == FusionMode.IMU_ONLY and self.fused_s < self.settle_s:
                self._last_cause_t[SuppressionReason.SETTLING] = t
        reason = SuppressionReason.NONE
        for cause, t_cause in self._last_cause_t.items():
            if t - t_cause < self.span_s:
                reason |= cause
        return reason
