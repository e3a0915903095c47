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
`mode_reason` says why a frame is in its mode, in words that fit that mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from roadpreview.fusion.config import GyroConfig, ModeConfig
from roadpreview.types import FusionMode


class VisionTrust(Enum):
    STARTING = "starting"
    TRUSTED = "trusted"
    LOST = "lost"
    VALIDATING = "validating"


# the members as module constants for the per-frame methods: an enum member read through its
# class is an unspecialised attribute lookup in CPython 3.11 (about 0.1 µs each)
_STARTING, _TRUSTED = VisionTrust.STARTING, VisionTrust.TRUSTED
_LOST, _VALIDATING = VisionTrust.LOST, VisionTrust.VALIDATING
_FUSED, _VISUAL_ONLY = FusionMode.FUSED, FusionMode.VISUAL_ONLY
_IMU_ONLY, _DEGRADED = FusionMode.IMU_ONLY, FusionMode.DEGRADED


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
    #: when the back end last accepted a visual measurement
    last_accepted_t: float = -math.inf
    mode: FusionMode = FusionMode.DEGRADED

    def trusted(self) -> bool:
        return self.trust is _TRUSTED

    def good_frame(self, t: float, consistent: bool) -> bool:
        """A frame with a good-quality measurement; True when it may be fused.

        ``consistent`` says whether it agrees with the gyro (True when that
        cannot be checked).
        """
        self.bad_frames = 0
        if self.trust is _STARTING:
            self.trust = _TRUSTED
        if self.trust is _TRUSTED:
            self.last_good_t = t
            return True
        if not consistent:
            self.trust = _LOST
            return False
        previous, self.last_good_t = self.last_good_t, t
        if self.trust is _LOST or t - previous > self.cfg.loss_time_s:
            self.trust = _VALIDATING
            self.validating_since = t
        if t - self.validating_since >= self.cfg.revalidation_s - 1e-9:
            self.trust = _TRUSTED
            self.rejected = 0
            self.reacquired_t = t
            self.last_accepted_t = t
            return True
        return False

    def bad_frame(self, t: float) -> None:
        """A frame where vision failed (no texture, poor fit) or gave nonsense.

        Trusted vision is lost after ``loss_frames`` failed frames in a row that also span
        ``loss_time_s`` since the last good one: on a rough road a fit that fails every
        other frame still gives the filter a measurement every few frames, and the gyro
        bridges the rest. A validating vision keeps validating through such gaps; only a
        longer one (or a frame that disagrees with the gyro) sends it back to LOST.
        """
        self.bad_frames += 1
        gap = t - self.last_good_t
        if self.trust is _VALIDATING:
            if gap > self.cfg.loss_time_s:
                self.trust = _LOST
        elif (
            self.trust is _TRUSTED
            and self.bad_frames >= self.cfg.loss_frames
            and gap >= self.cfg.loss_time_s - 1e-9
        ):
            self.trust = _LOST

    def no_news(self, t: float) -> None:
        """A frame without any visual result: lost after ``vision_timeout_s``."""
        if self.trust is _TRUSTED and t - self.last_good_t > self.cfg.vision_timeout_s:
            self.trust = _LOST

    def gated(self, rejected: bool, max_rejections: int, t: float = math.inf) -> None:
        """Outcome of the back end's outlier gate for a fused measurement at frame ``t``.

        Trusted vision is lost after ``max_rejections`` rejections in a row that also span
        ``loss_time_s`` since the last accepted measurement: while the ego crosses a bump
        the increments disagree with the gyro for a few frames (a few ms of time offset at
        10 deg/s), and leaving FUSED for each burst made the mode flap."""
        if not rejected:
            self.rejected = 0
            self.last_accepted_t = t
            return
        self.rejected += 1
        if (
            self.rejected >= max_rejections
            and self.trust is _TRUSTED
            and t - self.last_accepted_t >= self.cfg.loss_time_s - 1e-9
        ):
            self.trust = _LOST
            self.rejected = 0

    def update_mode(self, imu_ok: bool) -> FusionMode:
        vision = self.trust is _TRUSTED
        if vision and imu_ok:
            self.mode = _FUSED
        elif vision:
            self.mode = _VISUAL_ONLY
        elif imu_ok:
            self.mode = _IMU_ONLY
        else:
            self.mode = _DEGRADED
        return self.mode


def gyro_state(gyro_age_s: float, timeout_s: float = GyroConfig().timeout_s) -> str:
    """The gyro as the mode reasons see it: ``"none"`` (no sample yet), ``"timed out"``
    (newest sample older than ``timeout_s``) or ``"recent"``."""
    if math.isinf(gyro_age_s):
        return "none"
    return "timed out" if gyro_age_s > timeout_s else "recent"


def mode_reason(
    mode: FusionMode,
    *,
    vision_failure: str = "",
    gyro_age_s: float = math.inf,
    gyro_timeout_s: float = GyroConfig().timeout_s,
) -> str:
    """Why a frame is in ``mode``, from what the frame shows: ``vision_failure``, why the
    frame's pitch vision failed ('' when it worked); ``gyro_age_s``, the frame time minus
    the newest gyro sample's (inf: none yet). The reason always describes ``mode`` (the
    frame's lead may be lost in any mode: that is not why the mode is what it is)."""
    gyro = gyro_state(gyro_age_s, gyro_timeout_s)
    if gyro == "none":
        imu = "no IMU input (no gyro sample so far)"
    elif gyro == "timed out":
        imu = f"gyro timed out (newest sample {gyro_age_s:.2f} s old)"
    else:
        imu = "gyro not fused (its time offset is still being estimated, or the back end has none)"
    if vision_failure:
        vision = f"vision failed: {vision_failure}"
    else:
        vision = "vision not trusted (it disagreed with the gyro, or is re-validating)"
    if mode is _FUSED:
        if gyro == "none":
            return "vision trusted; no gyro sample yet (start-up grace)"
        return "gyro and vision agree"
    if mode is _VISUAL_ONLY:
        return f"vision only: {imu}"
    if mode is _IMU_ONLY:
        return f"gyro only: {vision}"
    return f"no pitch source: {imu}; {vision}"
