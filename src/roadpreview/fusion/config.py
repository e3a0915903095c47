"""Settings of the fusion back ends: typed dataclasses with units, reasons and ranges.

A TOML ``[fusion]`` table maps onto these classes (``roadpreview.configtools``)::

    [fusion]
    backend = "kalman"           # chosen by `make_fusion`, not a field here
    gate_sigma = 4.0
    [fusion.gyro]
    noise_density = 0.00026      # rad/s/sqrt(Hz)
    [fusion.alignment]
    initial_offset_s = 0.03

Angles and rates are SI (rad, rad/s); the help text gives degrees for orientation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError

DEG = math.pi / 180.0


@dataclass(frozen=True)
class GyroConfig:
    """The gyro stream: sensor limits, noise model, gaps and late samples."""

    range_rad_s: float = param(
        2000.0 * DEG,
        unit="rad/s",
        gt=0.0,
        help="full scale (phone MEMS ±2000 °/s); a value at or beyond it is absurd or saturated",
    )
    rate_hz: float = param(
        100.0,
        unit="Hz",
        ge=10.0,
        le=2000.0,
        help="first guess of the sample rate (CAN IMUs 100 Hz); re-estimated from the stamps",
    )
    noise_density: float = param(
        0.015 * DEG,
        unit="rad/s/√Hz",
        gt=0.0,
        help="one-sided white rate noise density (a phone in its holder, 0.015 °/s/√Hz)",
    )
    bias_prior_std_rad_s: float = param(
        2.0 * DEG,
        unit="rad/s",
        gt=0.0,
        help="initial bias uncertainty: phone offsets after run-time calibration are 0.5-4 °/s",
    )
    initial_bias_rad_s: float = param(0.0, unit="rad/s", help="bias estimate at the start")
    bias_random_walk: float = param(
        0.003 * DEG,
        unit="rad/s/√s",
        gt=0.0,
        help="bias drift (a phone's, about 0.02 °/s over a minute); larger values forget the"
        " bias faster and let it wander more",
    )
    gap_factor: float = param(
        2.5,
        gt=1.0,
        le=100.0,
        help="an interval longer than this many sample periods is a gap (bridged, logged)",
    )
    gap_rate_std_rad_s: float = param(
        3.0 * DEG,
        unit="rad/s",
        gt=0.0,
        help="uncertainty of the pitch rate across a bridged gap (rough-road rate changes)",
    )
    hold_rate_std_rad_s: float = param(
        5.0 * DEG,
        unit="rad/s",
        gt=0.0,
        help="change of the pitch rate while the last gyro rate is held beyond the newest"
        " sample (a few tens of ms)",
    )
    blind_rate_std_rad_s: float = param(
        20.0 * DEG,
        unit="rad/s",
        gt=0.0,
        help="pitch rate where there is no gyro at all (IMU lost, outage): bumps reach 20 °/s",
    )
    timeout_s: float = param(
        0.2,
        unit="s",
        gt=0.0,
        le=5.0,
        help="no gyro for this long (frame time minus newest sample) = IMU lost: VISUAL_ONLY",
    )
    reorder_window_s: float = param(
        0.01,
        unit="s",
        ge=0.0,
        le=1.0,
        help="gyro this close to the newest sample is not yet committed, so out-of-order"
        " samples within it are still accepted",
    )
    history_s: float = param(
        15.0,
        unit="s",
        ge=1.0,
        help="gyro history kept (covers the time-alignment window)",
    )


@dataclass(frozen=True)
class VisionConfig:
    """How far a visual measurement is trusted."""

    std_scale: float = param(
        4.0,
        unit="",
        ge=1.0,
        le=100.0,
        help="the estimator's curvature std times this is the measurement's std: on the 720p"
        " wild drives the increments' error against the truth is 3-6 times the std it reports"
        " (the Sampson errors of a frame are not independent: rolling terrain, the ego's"
        " heave and sway, which F(phi) leaves out). With the raw std 40 % of the increments"
        " lay beyond 4 sigma and the Kalman gate locked vision out (docs/fusion.md)",
    )
    min_std_rad: float = param(
        0.007 * DEG,
        unit="rad",
        gt=0.0,
        help="added in quadrature to the scaled std: the error floor of an increment (0.009"
        " deg at one frame apart on the wild drives, whatever std the estimator reports)",
    )
    low_inlier_ratio: float = param(
        0.5,
        gt=0.0,
        le=1.0,
        help="below this inlier ratio the variance is inflated by (low / ratio)²",
    )
    min_inlier_ratio: float = param(
        0.15,
        ge=0.0,
        le=1.0,
        help="below this inlier ratio a measurement counts as a vision failure",
    )
    max_abs_dphi_rad: float = param(
        0.35,
        unit="rad",
        gt=0.0,
        help="a relative pitch beyond 20 ° is not a car's: treated as a failure",
    )

    def variance(self, std: float) -> float:
        """The variance of a visual increment whose estimator reports ``std`` (rad²)."""
        return (self.std_scale * std) ** 2 + self.min_std_rad**2


@dataclass(frozen=True)
class ModeConfig:
    """Mode switching: loss detection, re-validation (hysteresis), no step at a switch."""

    loss_frames: int = param(
        2,
        ge=1,
        le=100,
        help="consecutive failed frames before vision is declared lost (a single bad frame"
        " is bridged by the gyro without a switch)",
    )
    loss_time_s: float = param(
        0.5,
        unit="s",
        ge=0.0,
        le=10.0,
        help="and those failures (or the back end's rejections) must span this long since"
        " the last good frame (15 frames at 30 Hz): on rough roads the fit fails on single"
        " frames (wheel hop, blur), and while the ego crosses a bump its increments disagree"
        " with the gyro for a few frames, while the frames between still measure; leaving"
        " FUSED for each made the mode flap 40-90 times a minute on class D/E roads. The gyro"
        " bridges the gap; a validating vision survives gaps this short",
    )
    vision_timeout_s: float = param(
        0.25,
        unit="s",
        gt=0.0,
        help="no visual news at all for this long = vision lost",
    )
    revalidation_s: float = param(
        0.3,
        unit="s",
        ge=0.0,
        le=10.0,
        help="after a loss, vision must be good and agree with the gyro this long (9 frames"
        " at 30 Hz) before it is trusted again",
    )
    consistency_sigma: float = param(
        4.0,
        gt=0.0,
        help="re-validation: |visual - gyro increment| within this many sigmas",
    )
    level_capture_s: float = param(
        2.0,
        unit="s",
        ge=0.0,
        help="after vision is re-acquired, corrections of the key frame's own estimate (the"
        " drift of the loss, explained by the bias learnt after it) are this long taken as"
        " level changes and eased in, not stepped",
    )
    level_ease_s: float = param(
        5.0,
        unit="s",
        ge=0.0,
        help="time constant with which such a level change enters the output; 0 = at once",
    )


@dataclass(frozen=True)
class AlignmentConfig:
    """Camera-IMU time offset by cross-correlation of visual and gyro pitch rates."""

    enabled: bool = param(True, help="estimate the offset; False keeps initial_offset_s")
    initial_offset_s: float = param(
        0.0,
        unit="s",
        ge=-0.5,
        le=0.5,
        help="IMU stamp minus camera time used until the first estimate",
    )
    prior_std_s: float = param(
        0.04,
        unit="s",
        gt=0.0,
        help="uncertainty of the initial offset (CAN / app latency of 0-80 ms)",
    )
    min_std_s: float = param(
        0.0005,
        unit="s",
        gt=0.0,
        help="floor of the estimated offset's std (above it the correlation's own precision)",
    )
    min_offset_s: float = param(-0.1, unit="s", ge=-1.0, help="search range, low end")
    max_offset_s: float = param(0.15, unit="s", le=1.0, help="search range, high end")
    step_s: float = param(
        0.002,
        unit="s",
        gt=0.0,
        le=0.05,
        help="lag grid of the correlation (finer than one IMU sample); the peak is then"
        " refined by a parabola",
    )
    window_s: float = param(10.0, unit="s", ge=2.0, help="sliding correlation window")
    max_wait_s: float = param(
        10.0,
        unit="s",
        ge=0.0,
        help="the gyro is fused only once the offset is estimated (a 30-80 ms error would"
        " pull the pitch by tenths of a degree), or after this long with initial_offset_s",
    )
    update_period_s: float = param(
        4.0,
        unit="s",
        gt=0.0,
        help="re-estimate this often (every 0.5 s until the first estimate)",
    )
    min_increments: int = param(
        45, ge=10, help="visual frame-to-frame increments needed in the window (1.5 s at 30 Hz)"
    )
    min_correlation: float = param(
        0.6,
        gt=0.0,
        lt=1.0,
        help="peak correlation below this is no estimate (flat road, noisy vision)",
    )
    min_rate_std_rad_s: float = param(
        0.3 * DEG,
        unit="rad/s",
        ge=0.0,
        help="the gyro rate must vary at least this much over the window (excitation)",
    )

    def validate(self, where: str = "alignment") -> None:
        check_ranges(self, where)
        if self.max_offset_s - self.min_offset_s < 4 * self.step_s:
            raise ConfigError(
                f"{where}.max_offset_s = {self.max_offset_s}: the search range must span at"
                f" least 4 steps above min_offset_s = {self.min_offset_s}"
            )
        if not self.min_offset_s <= self.initial_offset_s <= self.max_offset_s:
            raise ConfigError(
                f"{where}.initial_offset_s = {self.initial_offset_s}: outside the search range"
                f" [{self.min_offset_s}, {self.max_offset_s}]"
            )


@dataclass(frozen=True)
class FusionConfig:
    """Settings shared by the `kalman` and `factor-graph` back ends."""

    gyro: GyroConfig = field(default_factory=GyroConfig)
    vision: VisionConfig = field(default_factory=VisionConfig)
    modes: ModeConfig = field(default_factory=ModeConfig)
    alignment: AlignmentConfig = field(default_factory=AlignmentConfig)

    def validate(self, where: str = "fusion") -> None:
        check_ranges(self, where)
        self.alignment.validate(f"{where}.alignment")
        if self.gyro.history_s < self.alignment.window_s + 1.0:
            raise ConfigError(
                f"{where}.gyro.history_s = {self.gyro.history_s}: must exceed"
                f" alignment.window_s + 1 s = {self.alignment.window_s + 1.0}"
            )


@dataclass(frozen=True)
class KalmanConfig(FusionConfig):
    """`kalman`: filterpy KalmanFilter on [phi, bias, clones of phi at recent frames]."""

    gate_sigma: float = param(
        4.0,
        gt=0.0,
        help="Mahalanobis gate: innovations beyond 4 sigma are outliers (an inlier is"
        " rejected with probability 6e-5)",
    )
    max_consecutive_rejections: int = param(
        5,
        ge=1,
        help="this many gated frames in a row = vision lost (re-validated against the gyro)",
    )
    n_clones: int = param(
        4,
        ge=2,
        le=32,
        help="stochastic clones of phi at recent frame times (key frames are pinned)",
    )


@dataclass(frozen=True)
class FactorGraphConfig(FusionConfig):
    """`factor-graph`: gtsam fixed-lag smoother over frame-time pitch and bias states."""

    lag_s: float = param(2.0, unit="s", gt=0.1, le=30.0, help="smoother window")
    smoother: str = param(
        "incremental",
        choices=("incremental", "batch"),
        help="iSAM2-based IncrementalFixedLagSmoother, or the BatchFixedLagSmoother (LM)",
    )
    robust_loss: str = param(
        "huber",
        choices=("huber", "cauchy", "none"),
        help="m-estimator on the visual factors (Huber: Gaussian for inliers)",
    )
    robust_k: float = param(3.0, gt=0.0, help="m-estimator threshold in sigmas")
    gyro_factor: str = param(
        "linear",
        choices=("linear", "custom"),
        help="gyro between-factor as gtsam's C++ linear factor (exact: the model is linear) or"
        " as a Python CustomFactor (same result, about 1.5x slower: a callback per evaluation)",
    )
    bias_node_every_s: float = param(
        0.5,
        unit="s",
        ge=0.0,
        help="a new bias state this often (0: every frame); the bias barely moves in 0.5 s",
    )
    relinearize_threshold_rad: float = param(
        1e-4,
        unit="rad",
        gt=0.0,
        help="iSAM2 relinearises a state that moved more than this (0.006 °, about one visual"
        " sigma), which refreshes the robust weights; the model is otherwise linear",
    )
    relinearize_skip: int = param(
        1, ge=1, help="iSAM2 checks for relinearisation every this many updates"
    )
    rebuild_every_s: float = param(
        0.0,
        unit="s",
        ge=0.0,
        help="re-create the smoother from its current estimate this often (0: never);"
        " bounds memory if the incremental smoother grows",
    )


@dataclass(frozen=True)
class ImuOnlyConfig:
    """`imu-only`: the integrated gyro, the paper's drifting IMU comparison."""

    gyro: GyroConfig = field(default_factory=GyroConfig)
    bias_rad_s: float = param(
        0.0, unit="rad/s", help="bias subtracted; 0 = uncorrected, as the paper's comparison"
    )
    time_offset_s: float = param(
        0.0, unit="s", ge=-0.5, le=0.5, help="IMU stamp minus camera time (not estimated)"
    )


@dataclass(frozen=True)
class VisualOnlyConfig:
    """`visual-only`: the visual pitch chained over key frames, the paper's compensation."""

    vision: VisionConfig = field(default_factory=VisionConfig)
    loss_frames: int = param(
        1, ge=1, help="failed frames before the mode says DEGRADED (no filter to bridge)"
    )
