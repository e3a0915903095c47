"""Configuration of the anomaly detector and of the alerts (``docs/detector.md``).

Every default carries its unit and the reason for its value. The threshold
derivation from the noise level is `noise_threshold_px`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from scipy.stats import chi2

from roadpreview.configtools import param
from roadpreview.errors import ConfigError

#: assumed noise of the compensated trajectory y_c, px (docs/detector.md, "Threshold")
NOISE_STD_PX = 0.4
#: per-frame false-positive rate the default threshold is derived for (~0.1 per hour at 30 fps)
FALSE_POSITIVE_RATE = 1e-6


def noise_threshold_px(
    noise_std_px: float,
    window_samples: int,
    false_positive_rate: float,
    *,
    detrended: bool = False,
) -> float:
    """Threshold on s that white Gaussian noise of ``noise_std_px`` exceeds with the given rate.

    s is the population standard deviation (ddof = 0) of N = ``window_samples``
    samples; for white noise N s²/σ² follows χ² with N - 1 degrees of freedom
    (N - 2 when s is taken around the window's least-squares line, ``detrended``),
    so ``P(s > thr) = false_positive_rate`` at ``thr = σ sqrt(χ²_dof(1 - p) / N)``.
    The rate is per frame (neighbouring frames share samples, so exceedances
    come in clusters).
    """
    dof = window_samples - (2 if detrended else 1)
    if noise_std_px <= 0 or dof < 1 or not 0 < false_positive_rate < 1:
        raise ConfigError(
            f"noise_threshold_px({noise_std_px}, {window_samples}, {false_positive_rate}):"
            " need noise > 0 px, more samples than fitted parameters and 0 < rate < 1"
        )
    q = float(chi2.isf(false_positive_rate, dof))
    return noise_std_px * math.sqrt(q / window_samples)


@dataclass(frozen=True)
class SignalModel:
    """Paper Fig. 4: a lead lifted by δ at distance d gives s(d) = α f δ / d + β."""

    focal_px: float | None = param(
        None,
        unit="px",
        gt=0,
        help="camera focal length; set from the CameraModel. None: no height estimates and"
        " no distance-aware threshold",
    )
    alpha: float = param(
        1.0,
        unit="",
        gt=0,
        le=10,
        help="paper's α, calibrated from drives over known bumps. 1 until calibrated: then the"
        " height estimate is the displacement whose size equals s (an ideal step gives"
        " s = displacement / 2, i.e. α = 0.5)",
    )
    beta_px: float = param(
        0.0,
        unit="px",
        ge=0,
        le=10,
        help="paper's β, the noise floor of s; 0 until calibrated",
    )

    def height_m(self, s_px: float, distance_m: float) -> float | None:
        """δ = (s - β) d / (α f), the anomaly height s stands for; None when unknown."""
        if self.focal_px is None or not math.isfinite(distance_m) or distance_m <= 0:
            return None
        return max(0.0, s_px - self.beta_px) * distance_m / (self.alpha * self.focal_px)

    def s_px(self, height_m: float, distance_m: float) -> float:
        """Expected s for an anomaly of ``height_m`` at ``distance_m`` (needs ``focal_px``)."""
        if self.focal_px is None:
            raise ConfigError("signal model: focal_px is not set")
        return self.alpha * self.focal_px * height_m / distance_m + self.beta_px


@dataclass(frozen=True)
class DetectorConfig:
    """The windowed-std detector (paper eq. 1) with NMS, sides and suppression."""

    window_s: float = param(
        1.0,
        unit="s",
        gt=0,
        le=10,
        help="paper's T = 30 frames at 30 fps. The window holds the samples of the last"
        " window_s seconds, so any frame rate and dropped frames work",
    )
    threshold_px: float = param(
        1.0,
        unit="px",
        gt=0,
        le=100,
        help="noise floor 0.4 px gives 0.65 px at 1e-6 false positives per frame"
        " (noise_threshold_px), plus a margin for slow trends; see docs/detector.md",
    )
    detrend: bool = param(
        True,
        help="s is the std of y_c around its least-squares line over the window instead of"
        " around its mean: slow ramps (a gap that closes, long road waves, a drifting pitch)"
        " do not count, a bump's up-and-down does (it is nearly orthogonal to a line through"
        " the window's centre). false: the paper's eq. 1. A step's s drops from A/2 to A/4",
    )
    threshold_mode: str = param(
        "pixel",
        choices=("pixel", "distance"),
        help="pixel: the paper's fixed pixel threshold. distance: flag anomalies of at least"
        " min_height_m at any distance (threshold α f h / d + β, never below threshold_px)",
    )
    min_height_m: float = param(
        0.03,
        unit="m",
        gt=0,
        le=1,
        help="distance mode: smallest anomaly worth an alert (3 cm: a pronounced expansion joint)",
    )
    nms_window_s: float = param(
        1.0,
        unit="s",
        gt=0,
        le=30,
        help="a peak must be the largest s within ± this; >= window_s, because one bump keeps"
        " s raised for one window",
    )
    emit: str = param(
        "onset",
        choices=("peak", "onset"),
        help="peak: the paper's NMS, an event at the largest s within ± nms_window_s, known"
        " nms_window_s after it. onset: an event when s first exceeds the threshold, about"
        " 1-1.5 s earlier (the alert's lead time), described at that moment. Default onset: on"
        " the demo drive the lead time went from -0.2..0.8 s (peak) to 1.4..2.3 s",
    )
    both_sides_ratio: float = param(
        0.6,
        unit="",
        gt=0,
        lt=1,
        help="side BOTH when min(s_left, s_right) >= ratio * max(...). A rigid rear over a"
        " one-wheel pothole moves its halves 3:1 (ratio 0.33); a full-width bump 1:1",
    )
    lead_accel_limit_mps2: float = param(
        2.0,
        unit="m/s^2",
        gt=0,
        le=20,
        help="suppress above this lead acceleration: its body pitch (~1 deg per g) moves the"
        " rear ~7 mm at 2 m/s^2, the threshold's size at short gaps",
    )
    compensation_error_fraction: float = param(
        0.1,
        unit="",
        ge=0,
        le=1,
        help="the ego-motion compensation is good to about this fraction of its own windowed"
        " spread: the threshold becomes sqrt(threshold² + (fraction * s_comp)²), s_comp the"
        " std of the compensation over the window. A few ms of IMU-camera misalignment at"
        " the 1-2 Hz of the ego crossing a bump is 5-10 % (2π f δt); 0 disables",
    )
    imu_only_settle_s: float = param(
        10.0,
        unit="s",
        ge=0,
        le=600,
        help="IMU_ONLY frames are suppressed (SETTLING) until the fusion has been FUSED this"
        " long in total: the gyro bias is learnt only while vision and gyro are fused, and an"
        " unsettled bias of a phone gyro (0.1-0.3 deg/s) drifts 1-4 px per second",
    )
    suppress_hold_s: float = param(
        0.5,
        unit="s",
        ge=0,
        le=10,
        help="suppression lasts window_s + this after the cause ends: half a period of the"
        " ~1 Hz body pitch mode to settle",
    )
    min_samples: int = param(
        8,
        unit="frames",
        ge=2,
        le=10000,
        help="fewer valid samples give no s (the relative error of a std over n samples is"
        " ~1/sqrt(2(n-1)), 27 % at 8)",
    )
    min_valid_fraction: float = param(
        0.5,
        unit="",
        gt=0,
        le=1,
        help="share of the window's frames that must be valid",
    )
    min_span_fraction: float = param(
        0.5,
        unit="",
        gt=0,
        le=1,
        help="the window's frames must span this share of window_s (start-up, after gaps)",
    )
    recompute_every: int = param(
        1000,
        unit="frames",
        ge=1,
        le=10_000_000,
        help="exact recomputation of the running moments from the window, against drift",
    )
    signal: SignalModel = field(default_factory=SignalModel)

    def validate(self, where: str = "DetectorConfig") -> None:
        """Cross-field checks (called by configtools after loading)."""
        if self.threshold_mode == "distance" and self.signal.focal_px is None:
            raise ConfigError(f"{where}.threshold_mode = 'distance' needs signal.focal_px")
        if self.nms_window_s < self.window_s:
            raise ConfigError(
                f"{where}.nms_window_s = {self.nms_window_s} s: must be >= window_s ="
                f" {self.window_s} s, or one bump gives several events"
            )


@dataclass(frozen=True)
class AlertConfig:
    """How events become alerts (``AlertBuilder``)."""

    min_speed_mps: float = param(
        0.5,
        unit="m/s",
        ge=0,
        le=100,
        help="below this ego speed there is no time to arrival (standstill)",
    )
    mode_confidence: tuple[float, float, float, float] = param(
        (1.0, 0.8, 0.6, 0.0),
        unit="",
        help="confidence factor per FusionMode (FUSED, VISUAL_ONLY, IMU_ONLY, DEGRADED):"
        " the pitch compensation is best when fused",
    )

    def validate(self, where: str = "AlertConfig") -> None:
        """The per-mode factors lie in [0, 1]."""
        if any(not 0.0 <= c <= 1.0 for c in self.mode_confidence):
            raise ConfigError(f"{where}.mode_confidence = {self.mode_confidence}: each in [0, 1]")


@dataclass(frozen=True)
class AnomalyConfig:
    """The ``[anomaly]`` table: detector, alerts and the shared signal model."""

    detector: DetectorConfig = field(default_factory=DetectorConfig)
    alert: AlertConfig = field(default_factory=AlertConfig)
