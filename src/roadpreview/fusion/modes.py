"""Which sources are trusted at a frame: vision trust with hysteresis, IMU liveness, the mode.

Vision is a small state machine, fed once per frame:

* TRUSTED: measurements are fused. ``loss_frames`` failed frames in a row, no
  visual news for ``vision_timeout_s``, or too many gated measurements in a
  row make it LOST (a single bad frame is bridged by the gyro).
* LOST: nothing visual is fused. The first good frame that agrees with the
  gyro starts VALIDATING.
* VALIDATING: good frames keep being checked against the gyro but are not
  fused; after ``revalidation_s`` of agreement vision is TRUSTED again. A bad
  or disagreeing frame sends it back to LOST.

At the start vision is trusted on its first good frame (there is nothing to
re-validate against). The mode follows from vision trust and IMU liveness:
FUSED, VISUAL_ONLY (IMU lost), IMU_ONLY (vision not trusted), DEGRADED.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from roadpreview.fusion.config import ModeConfig
from roadpreview.fusion.mode import FusionMode


class VisionTrust(Enum):
    STARTING = "starting"
    TRUSTED = "trusted"
    LOST = "lost"
    VALIDATING = "validating"


@dataclass
class ModeSupervisor:
    """Per-frame vision trust and mode; a plain dataclass so that it can be copied."""

    cfg: ModeConfig
    trust: VisionTrust = VisionTrust.STARTING
    bad_frames: int = 0
    rejected: int = 0
    last_good_t: float = -math.inf
    validating_since: float = math.nan
    #: when vision was last re-acquired (trusted again after a loss)
    reacquired_t: float = -math.inf
    mode: FusionMode = FusionMode.DEGRADED

    def trusted(self) -> bool:
        return self.trust is VisionTrust.TRUSTED

    def good_frame(self, t: float, consistent: bool) -> bool:
        """A frame with a good-quality measurement; True when it may be fused.

        ``consistent`` says whether it agrees with the gyro (True when that
        cannot be checked).
        """
        self.bad_frames = 0
        if self.trust is VisionTrust.STARTING:
            self.trust = VisionTrust.TRUSTED
        if self.trust is VisionTrust.TRUSTED:
            self.last_good_t = t
            return True
        if not consistent:
            self.trust = VisionTrust.LOST
            return False
        self.last_good_t = t
        if self.trust is VisionTrust.LOST:
            self.trust = VisionTrust.VALIDATING
            self.validating_since = t
        if t - self.validating_since >= self.cfg.revalidation_s - 1e-9:
            self.trust = VisionTrust.TRUSTED
            self.rejected = 0
            self.reacquired_t = t
            return True
        return False

    def bad_frame(self, t: float) -> None:
        """A frame where vision failed (no texture, poor fit) or gave nonsense."""
        self.bad_frames += 1
        validating = self.trust is VisionTrust.VALIDATING
        if validating or (
            self.trust is VisionTrust.TRUSTED and self.bad_frames >= self.cfg.loss_frames
        ):
            self.trust = VisionTrust.LOST

    def no_news(self, t: float) -> None:
        """A frame without any visual result: lost after ``vision_timeout_s``."""
        if self.trust is VisionTrust.TRUSTED and t - self.last_good_t > self.cfg.vision_timeout_s:
            self.trust = VisionTrust.LOST

    def gated(self, rejected: bool, max_rejections: int) -> None:
        """Outcome of the back end's outlier gate for a fused measurement."""
        self.rejected = self.rejected + 1 if rejected else 0
        if self.rejected >= max_rejections and self.trust is VisionTrust.TRUSTED:
            self.trust = VisionTrust.LOST
            self.rejected = 0

    def update_mode(self, imu_ok: bool) -> FusionMode:
        vision = self.trust is VisionTrust.TRUSTED
        if vision and imu_ok:
            self.mode = FusionMode.FUSED
        elif vision:
            self.mode = FusionMode.VISUAL_ONLY
        elif imu_ok:
            self.mode = FusionMode.IMU_ONLY
        else:
            self.mode = FusionMode.DEGRADED
        return self.mode
