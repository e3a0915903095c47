"""Configuration of the anomaly detector and of the alerts (``docs/detector.md``).

Every default carries its unit and the reason for its value. The threshold
derivation from the noise level is `noise_threshold_px`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from scipy.stats import chi2

from roadpreview.anomaly.confirm import ConfirmConfig
from roadpreview.anomaly.response import NominalVehicle
from roadpreview.anomaly.roughness import RoughnessConfig
from roadpreview.configtools import param
from roadpreview.errors import ConfigError

#: detector name -> (module, class, the `AnomalyConfig` field holding its table); the
#: registry of `roadpreview.anomaly.make_detector`
DETECTORS: dict[str, tuple[str, str, str]] = {
    "two-axle": ("roadpreview.anomaly.two_axle", "TwoAxleDetector", "two_axle"),
    "std": ("roadpreview.anomaly.windowed_std", "WindowedStdDetector", "std"),
}

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
class TwoAxleConfig:
    """The two-axle CFAR detector (`roadpreview.anomaly.two_axle`, ``docs/detector.md``).

    Thresholds are physical: a margin over the road's own background (a ratio) and a
    floor in millimetres of road input, so one configuration serves every camera.
    """

    vehicle: NominalVehicle = field(default_factory=NominalVehicle)
    durations_s: tuple[float, ...] = param(
        (0.03, 0.07, 0.14, 0.25, 0.45, 0.8),
        unit="s",
        help="bank of anomaly durations under a wheel (length / speed): a 0.3 m pothole at"
        " 36 km/h is 0.03 s, a 3 m cushion at 20 km/h 0.55 s",
    )
    pre_s: float = param(
        0.4, unit="s", gt=0, le=3, help="fit window before the front axle meets the anomaly"
    )
    post_s: float = param(
        0.3,
        unit="s",
        ge=0.1,
        le=3,
        help="fit window after the rear axle leaves it: a 1.3 Hz body peaks ~0.2 s after its"
        " input; longer only delays the alert",
    )
    threshold_z: float = param(
        6.0,
        unit="background std",
        gt=0,
        le=100,
        help="CFAR margin: the fitted road input must exceed this many background stds of"
        " the current road. The lowest of the evaluation's grid that keeps the wild set"
        " (its 22 drives: the training data) at <= 0.5 false alarms per minute: 0.36"
        " (docs/evaluation.md, E6); the generalization suite is held out",
    )
    min_height_mm: float = param(
        20.0,
        unit="mm",
        ge=0,
        le=500,
        help="floor: smaller road inputs give no alert whatever the background (a 2 cm"
        " joint is what a comfort-tuned damper does not need to know about)",
    )
    tracking_noise_px: float = param(
        0.15,
        unit="px",
        gt=0,
        le=10,
        help="std of the lead's image row from tracking alone (LK grid on a car's rear):"
        " carried to the road through each fit at the current distance, the background's"
        " floor (a glass-smooth road must not turn tracking noise into alerts)",
    )
    background_s: float = param(
        30.0,
        unit="s",
        gt=1,
        le=600,
        help="the background follows the road over this much driving (tens of seconds: a"
        " road's class changes over hundreds of metres)",
    )
    background_short_s: float = param(
        5.0,
        unit="s",
        gt=0.5,
        le=600,
        help="the background is at least the median over this much: it rises within seconds"
        " when the road or the tracking gets worse (a texture loss, a rough stretch)",
    )
    background_min_s: float = param(
        5.0,
        unit="s",
        ge=0,
        le=600,
        help="the road is being learnt until this much of its background has been seen (the"
        " start of a drive): the score relies on the whitening model alone, with a wider"
        " margin (learning_threshold_factor)",
    )
    learning_threshold_factor: float = param(
        1.25,
        unit="",
        ge=1,
        le=10,
        help="while the road is being learnt (the first background_min_s), the whitening"
        " model stands for the background (on the wild drives it overstates the background:"
        " the measured level is 0.4-1.0 of it) and the threshold is this many times higher",
    )
    background_refresh_frames: int = param(
        30,
        ge=1,
        le=1000,
        help="the background median is recomputed every this many frames (once a second at"
        " 30 fps: it describes tens of seconds of road)",
    )
    guard_s: float = param(
        3.0,
        unit="s",
        ge=0,
        le=30,
        help="frames this close after an eligible one are not background (neither its level"
        " nor its whitening filter): an anomaly's response, two axles and the body's"
        " ringing, lasts 2-3 s and must not raise its own background or bend the filter",
    )
    compensation_error_fraction: float = param(
        0.1,
        unit="",
        ge=0,
        le=1,
        help="the ego-motion compensation is good to about this fraction of itself; its"
        " fit on the same template widens the heave channel's background (as for the"
        " windowed std)",
    )
    glitch_sigma: float = param(
        8.0,
        unit="background std",
        gt=1,
        le=1000,
        help="a frame-to-frame change of the lead's row beyond this many robust stds of the"
        " background's changes ...",
    )
    glitch_ratio: float = param(
        4.0,
        unit="",
        gt=1,
        le=1000,
        help="... and this many times the largest change of the two frames either side is a"
        " jump of the tracker (a re-seeded grid, a box that snaps), not the lead's body (it"
        " moves smoothly): it is taken out of the later samples. On the 60 fps"
        " generalization drive such jumps were three false alarms a minute",
    )
    jolt_ratio: float = param(
        4.0,
        unit="",
        gt=1,
        le=100,
        help="the ego is jolted (its own anomaly) when its band-passed vertical acceleration"
        " peaks at this many times its background (`roadpreview.ego`) ...",
    )
    jolt_min_mps2: float = param(1.5, unit="m/s^2", ge=0, le=50, help="... and at least this much")
    jolt_mask_s: tuple[float, float] = param(
        (0.1, 0.25),
        unit="s",
        help="the lead's channels are interpolated over this long before / after each frame"
        " where the ego itself was jolted: the compensation misses part of a jolt's sharp"
        " motion (a few ms of IMU-camera timing, the heave's high-pass) and does not"
        " compensate the ego's roll (demo drive: a 1 px notch in y_c where the ego crossed"
        " the pothole the lead had crossed)",
    )
    roll_leak_fraction: float = param(
        0.3,
        unit="",
        ge=0,
        le=1,
        help="the halves of a lead bouncing on both wheels never move quite alike (their"
        " points, outliers and box edges differ): on the demo drive's cushion the roll"
        " channel moved a quarter of the heave. This share of the heave amplitude widens"
        " the roll channel's background",
    )
    one_sided_ratio: float = param(
        1.0,
        unit="",
        gt=0,
        le=10,
        help="side LEFT / RIGHT when the roll channel's amplitude exceeds this times the"
        " heave channel's: one side of height h gives h and h / 2, both sides h and 0",
    )
    refine_search_s: float = param(
        0.45,
        unit="s",
        ge=0,
        le=2,
        help="a confirmed event's crossing is searched this far around its peak's, with every"
        " duration, on one common window: the matched filter's side lobes (half a body"
        " period, 0.38 s, off and of the opposite sign) are not taken for the anomaly",
    )
    refine_prior_s: float = param(
        0.19,
        unit="s",
        gt=0,
        le=2,
        help="std of the prior on the refined crossing around the detection's: a shift by"
        " a side lobe's offset (half a body period, 0.38 s) costs (0.38 / 0.19)^2 = 4 in the"
        " fit's chi-square units, so a side lobe of the opposite sign takes the crossing and"
        " the height's sign only when it fits decisively better (a quarter body period: not"
        " tuned on any drive)",
    )
    close_fit_fraction: float = param(
        0.8,
        unit="",
        gt=0,
        le=1,
        help="durations whose score is within this fraction of the best spread the height's std",
    )
    confidence_logit: tuple[float, float] = param(
        (-0.75, 6.84),
        help="(a, b): an event's probability of being real is 1 / (1 + exp(-(a + b ln(z /"
        " threshold_z)))), z its score. Logistic fit to the alerts of the 22 wild drives"
        " (35 alerts, 27 real; docs/evaluation.md, E6 'Confidence': its cross-fitted and"
        " held-out reliability)",
    )
    refractory_s: tuple[float, float] = param(
        (0.5, 2.0),
        unit="s",
        help="hypotheses whose crossing lies this much before / after a reported anomaly's"
        " are its ringing (the body's oscillation after the rear axle), not a new anomaly",
    )
    peak_window_s: float = param(
        0.45,
        unit="s",
        gt=0,
        le=5,
        help="an event is sent this long after its first frame above the threshold,"
        " described by its best frame in between (a fixed latency); its crossing is then"
        " searched ± refine_search_s on the frames seen since",
    )
    min_lead_speed_mps: float = param(
        2.0,
        unit="m/s",
        gt=0,
        le=50,
        help="a lead slower than this crosses nothing worth a two-axle fit (standstill,"
        " creeping): no score",
    )
    range_rate_s: float = param(
        1.0, unit="s", gt=0, le=10, help="the range rate is the distance's slope over this time"
    )
    max_range_rate_mps: float = param(
        15.0, unit="m/s", gt=0, le=100, help="range rates beyond this are distance glitches"
    )
    min_distance_m: float = param(
        5.0,
        unit="m",
        gt=0,
        le=100,
        help="no fit while the lead's distance is below this: at the simulated wild drives'"
        " gaps (5-35 m) a lead this near is the tracker holding the road or a box that grew",
    )
    max_distance_ratio: float = param(
        1.5,
        unit="",
        gt=1,
        le=100,
        help="no fit over a window whose lead distance varies more than this factor: the"
        " tracker switched or lost its target (a real gap changes a few per cent a second)",
    )
    max_gap_s: float = param(
        0.15,
        unit="s",
        gt=0,
        le=2,
        help="dropped frames and invalid stretches up to this long are interpolated within a"
        " fit window (a few frames: the body moves at 1-2 Hz); a longer gap: no fit there",
    )
    min_frames: int = param(8, ge=3, le=10_000, help="fewer valid frames in a window: no fit")
    min_valid_fraction: float = param(
        0.5, unit="", gt=0, le=1, help="share of a window's frames that must be valid"
    )
    min_span_fraction: float = param(
        0.8, unit="", gt=0, le=1, help="the frames must span this share of the window"
    )
    buffer_frames: int = param(
        512, ge=32, le=100_000, help="frames kept: the longest window at the highest frame rate"
    )
    lead_accel_limit_mps2: float = param(
        2.0, unit="m/s^2", gt=0, le=20, help="suppression: as the windowed-std detector's"
    )
    imu_only_settle_s: float = param(
        10.0, unit="s", ge=0, le=600, help="suppression: as the windowed-std detector's"
    )
    suppress_hold_s: float = param(
        0.5, unit="s", ge=0, le=10, help="suppression: as the windowed-std detector's"
    )

    provisional: bool = param(
        True,
        help="send a PROVISIONAL alert as soon as the lead's front axle has met the anomaly"
        " (the early fit below), CONFIRMED by the two-axle fit under the same id or"
        " CANCELLED (NOT_CONFIRMED) when the rear axle does not match (docs/detector.md,"
        " 'Provisional alerts')",
    )
    provisional_lag_s: float = param(
        0.2,
        unit="s",
        gt=0.03,
        le=1.0,
        help="the early fit's window ends this long after the front axle met the anomaly's"
        " middle: the provisional alert's latency (plus a frame). The two-axle template is"
        " cut there: the front axle's response (-rho q, a third of the body's) and, above"
        " 50 km/h, the start of the rear axle's",
    )
    provisional_threshold_z: float = param(
        5.5,
        unit="background std",
        gt=0,
        le=100,
        help="CFAR margin of the early fit (its own running background, as threshold_z's):"
        " the lowest of the evaluation's grid that keeps the wild set (the training data)"
        " at <= 1 provisional false alarm per minute: 0.86 (docs/evaluation.md, E6 'Alert"
        " timing'); the generalization suite is held out",
    )
    provisional_confidence_logit: tuple[float, float] = param(
        (0.47, 1.23),
        help="(a, b): a provisional event's probability of being real, 1 / (1 + exp(-(a + b"
        " ln(z / provisional_threshold_z)))), z its early score. Logistic fit to the"
        " provisional alerts of the 22 wild drives at the shipped threshold (56 alerts, 37"
        " real; docs/evaluation.md, E6 'Alert timing'): 0.61 at the threshold",
    )
    provisional_match_s: float = param(
        0.9,
        unit="s",
        gt=0,
        le=3,
        help="a two-axle event confirms the provisional one whose crossing is within this"
        " of its own: the early fit fires when its evidence suffices, often on the rear"
        " axle's start, and its crossing is late by up to a body half-period (0.4 s) plus"
        " the rear axle's lag",
    )
    provisional_check_s: float = param(
        0.1,
        unit="s",
        ge=0,
        le=3,
        help="a provisional event is CANCELLED when the two-axle fit has had this long after"
        " its hypothesis for that crossing (rear axle + post_s) and no excursion of it is"
        " open: the rear axle did not match. One still open is waited for until its"
        " confirmation is due (peak_window_s later)",
    )

    @property
    def max_window_s(self) -> float:
        """The longest fit window (slowest lead, longest duration), s."""
        tau = self.vehicle.wheelbase_m / self.min_lead_speed_mps
        return self.pre_s + tau + max(self.durations_s) + self.post_s

    def validate(self, where: str = "TwoAxleConfig") -> None:
        """Cross-field checks."""
        if not self.durations_s or any(not 0 < d <= 3.0 for d in self.durations_s):
            raise ConfigError(f"{where}.durations_s = {self.durations_s}: each in (0, 3] s")
        if list(self.durations_s) != sorted(self.durations_s):
            raise ConfigError(f"{where}.durations_s = {self.durations_s}: must increase")


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
    camera_to_front_axle_m: float = param(
        0.2,
        unit="m",
        ge=-5.0,
        le=10.0,
        help="the ego's front axle is this far ahead of the camera: the time to arrival is"
        " counted to the front axle (the simulator's car: 0.2 m); measure it on the car",
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
    """The ``[anomaly]`` table: which detector, each detector's table, the alerts."""

    detector: str = param(
        "two-axle",
        choices=tuple(DETECTORS),
        help="two-axle: the product's matched filter against the road's background"
        " (docs/detector.md); std: the paper's windowed standard deviation (eq. 1), the"
        " baseline",
    )
    std: DetectorConfig = field(default_factory=DetectorConfig)
    two_axle: TwoAxleConfig = field(default_factory=TwoAxleConfig)
    alert: AlertConfig = field(default_factory=AlertConfig)
    roughness: RoughnessConfig = field(default_factory=RoughnessConfig)
    confirm: ConfirmConfig = field(default_factory=ConfirmConfig)
