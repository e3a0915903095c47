"""Ego camera heave from the IMU accelerometer: the vertical displacement Δz_cam(t) of the
camera over the detector's time scale (``docs/method.md``, "Heave").

A camera that rises by Δz moves a lead vehicle at distance d down in the image by
f Δz / d pixels. The paper's eq. (4) removes only the rotation (f tan φ); when the ego
itself crosses a bump its camera heaves by centimetres, i.e. several pixels at 10-20 m,
and the detector takes that for the lead's bump. `HeaveObserver` estimates Δz_cam so
that the pipeline can subtract f Δz_cam / d as well.

Per accelerometer sample (IMU clock, ~100 Hz, O(1) scalar work):

1. world-vertical specific force ``f_Z = f_x sin φ + f_z cos φ`` (body x forward, z up;
   φ the fused pitch, nose up +; roll is not estimated by the pipeline and is taken as 0:
   its effect, f_z (1 - cos ρ) + f_y sin ρ, is slow and goes with the gravity term);
2. the camera's lever arm: the camera is ``imu_to_camera_forward_m`` = L ahead of the IMU,
   so it rises by an extra L sin φ; its acceleration L d²(sin φ)/dt² is taken from the
   differences of consecutive gyro pitch rates (L cos φ Δω / Δt), so the gyro bias
   cancels and the term goes through exactly the same filter as the accelerometer;
3. gravity and the accelerometer bias: a slow running mean of the sum (expanding mean at
   the start, then time constant ``gravity_tau_s``) is subtracted;
4. double integration through a second-order high-pass,
   ``z'' = a - 2 ζ ω₀ z' - ω₀² z`` (ω₀ = 2π ``cutoff_hz``): above the cutoff it is the
   displacement, below it drift from noise and bias changes is bounded.

Queries come at frame times on the IMU clock (frame time + the fusion's time offset):
linear interpolation in a short history, or extrapolation with the velocity state for
at most ``max_extrapolation_s`` beyond the newest sample (the IMU stamps of a frame's
instant arrive after the frame when they lag).

Every sample passes the input plausibility gate first (`roadpreview.plausibility`, the
same ranges and gyro spike gate as the CAN decoder and the IMU CSV reader): a pitch rate
or a specific force outside the car's physical range, or a pitch rate spike, is not
integrated (counted in ``counts``: ``rejected_range``, ``rejected_spike``). A single
absurd value would otherwise enter the double integration, or the lever arm's
difference quotient, and leave kilometres of heave.

No accelerometer (absent, NaN), a gap longer than ``max_gap_s`` (the filter restarts
and needs ``warmup_s`` again) or a query outside the history: the estimate is
unavailable (``HeaveEstimate.available`` False, ``dz_m`` NaN) and the pipeline applies
no heave term. Out-of-order samples are dropped and logged.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from dataclasses import dataclass

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError
from roadpreview.plausibility import (
    REJECTED_RANGE,
    REJECTED_SPIKE,
    PlausibilityConfig,
    SpikeGate,
)
from roadpreview.types import ImuSample

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class HeaveConfig:
    """``[heave]``: the camera heave term of the compensation (``docs/method.md``)."""

    enabled: bool = param(
        True,
        help="subtract f Δz_cam / d from y (and the halves) when the heave and the lead's"
        " distance are known; false: the paper's eq. (4) only",
    )
    imu_to_camera_forward_m: float = param(
        1.0,
        unit="m",
        ge=-5.0,
        le=5.0,
        help="calibration: the camera's longitudinal offset ahead of the IMU (positive: the"
        " camera is in front). 1.0 m is an IMU in the ESC cluster at the centre of gravity"
        " and a windscreen camera, the simulator's geometry; measure it on the car",
    )
    cutoff_hz: float = param(
        0.2,
        unit="Hz",
        gt=0.0,
        le=2.0,
        help="corner of the second-order high-pass of the double integration: its phase"
        " lead at the 1-2 Hz of a bump crossing stays below 10 deg (the 1 s detector"
        " window passes those), while the drift of 400 µg/√Hz noise and a bias random"
        " walk stays at a few mm",
    )
    damping: float = param(
        0.7,
        unit="",
        gt=0.1,
        le=2.0,
        help="damping ratio ζ of the high-pass: 0.7 is maximally flat, no ringing",
    )
    gravity_tau_s: float = param(
        10.0,
        unit="s",
        gt=0.1,
        le=600.0,
        help="time constant of the running mean that removes gravity and the accelerometer"
        " bias (an expanding mean until this long after a restart)",
    )
    max_gap_s: float = param(
        0.1,
        unit="s",
        gt=0.0,
        le=5.0,
        help="a longer interval between accelerometer samples restarts the filter: ten"
        " samples at 100 Hz cannot be bridged by holding the acceleration",
    )
    warmup_s: float = param(
        3.0,
        unit="s",
        ge=0.0,
        le=60.0,
        help="after a (re)start the estimate is unavailable this long: the unknown initial"
        " vertical velocity decays as exp(-ζ ω₀ t), to 7 % after 3 s at 0.2 Hz, and at the"
        " very start the gravity mean has averaged out the motion",
    )
    max_extrapolation_s: float = param(
        0.1,
        unit="s",
        ge=0.0,
        le=1.0,
        help="a query this far beyond the newest sample is extrapolated with the velocity"
        " (IMU stamps lagging the camera by up to 80 ms), farther is unavailable",
    )
    history_s: float = param(
        1.0,
        unit="s",
        gt=0.0,
        le=60.0,
        help="samples kept for interpolation at frame times (queries lag the newest sample"
        " by at most a frame plus the time offset)",
    )
    distance_hold_s: float = param(
        0.5,
        unit="s",
        ge=0.0,
        le=5.0,
        help="pipeline: a frame without a lead distance uses the last one this long, so the"
        " heave term does not switch on and off with single missing distances",
    )
    min_distance_m: float = param(
        5.0,
        unit="m",
        ge=0.0,
        le=50.0,
        help="pipeline: no heave term below this lead distance (the term is held): at"
        " driving speed a lead this close is more often a wrong box than a real gap, and"
        " f Δz / d would blow the observer's few mm of error up to pixels",
    )
    max_accel_m_s2: float = param(
        100.0,
        unit="m/s^2",
        gt=0.0,
        help="a specific force beyond this is absurd (a broken frame): the sample is dropped",
    )

    def validate(self, where: str = "HeaveConfig") -> None:
        """Ranges and cross-field checks; raise `ConfigError`."""
        check_ranges(self, where)
        if self.history_s < self.max_gap_s:
            raise ConfigError(
                f"{where}.history_s = {self.history_s} s: must be >= max_gap_s = {self.max_gap_s} s"
            )


@dataclass(frozen=True, slots=True)
class HeaveEstimate:
    """The camera's high-passed vertical displacement at one query time."""

    t: float  #: query time (IMU clock), s
    dz_m: float  #: Δz_cam, m, world up positive (NaN when unavailable)
    available: bool  #: False: no heave term may be applied
    lever_arm: bool  #: the lever-arm term is included (gyro rates were seen)
    reason: str = ""  #: why not available ("" when it is)


class HeaveObserver:
    """Streaming estimate of the camera's vertical displacement (module docstring).

    Push every `ImuSample` (rates and accelerations may come in separate samples),
    tell it the fused pitch once per frame with `set_pitch`, query at frame times on
    the IMU clock with `at`.
    """

    def __init__(
        self, config: HeaveConfig | None = None, plausibility: PlausibilityConfig | None = None
    ) -> None:
        self.config = config or HeaveConfig()
        self.config.validate()
        self.plausibility = plausibility or PlausibilityConfig()
        self.plausibility.validate()
        c = self.config
        w0 = 2.0 * math.pi * c.cutoff_hz
        self._k_v = 2.0 * c.damping * w0
        self._k_z = w0 * w0
        self._phi = 0.0
        self.counts: Counter[str] = Counter()
        self._history: deque[tuple[float, float, float]] = deque()
        self.reset()

    # -- state ----------------------------------------------------------------------------
    def _reset_state(self) -> None:
        """Restart the integration (z = v = 0); the gravity + bias mean is kept: it does
        not change across a gap."""
        self._z = 0.0
        self._v = 0.0
        self._started = False
        self._t_start = math.nan
        self._rate_prev = math.nan  # pitch rate at the previous integration step
        self._history.clear()

    def reset(self) -> None:
        """Forget everything (a new drive)."""
        self._reset_state()
        self._g = math.nan  # running mean of the vertical specific force (gravity + bias)
        self._n = 0  # samples in that mean
        self._t_last = -math.inf  # newest accepted accelerometer stamp (kept over restarts)
        self._rate_t = -math.inf
        self._rate = math.nan
        self._spike = SpikeGate(self.plausibility)

    def _note(self, kind: str, msg: str, *args: object) -> None:
        self.counts[kind] += 1
        if self.counts[kind] == 1:
            log.warning("heave: " + msg, *args)
        elif self.counts[kind] == 2:
            log.warning("heave: further '%s' events are counted, not logged", kind)

    # -- inputs ---------------------------------------------------------------------------
    def set_pitch(self, phi_rad: float) -> None:
        """The fused camera pitch (rad, nose up +) used to rotate the specific force."""
        if math.isfinite(phi_rad):
            self._phi = phi_rad

    def push(self, sample: ImuSample) -> None:
        """One IMU sample: its pitch rate (lever arm) and/or its specific force."""
        rate = sample.rates_rad_s[1]
        gate = self.plausibility
        if not math.isnan(rate) and gate.enabled:
            if not gate.in_range("pitch_rate", rate):
                self._note(REJECTED_RANGE, "pitch rate %r rad/s at %r s; dropped", rate, sample.t_s)
                rate = math.nan
            elif self._spike.is_spike(sample.t_s, rate):
                self._spike.rejected()
                self._note(REJECTED_SPIKE, "pitch rate spike %r rad/s at %r s", rate, sample.t_s)
                rate = math.nan
            else:
                self._spike.accept(sample.t_s, rate)
        if math.isfinite(rate):
            if sample.t_s >= self._rate_t:
                self._rate_t = sample.t_s
                self._rate = rate
            else:
                self._note("rate_out_of_order", "pitch rate at %.6f s is late; dropped", sample.t_s)
        fx, _, fz = sample.accel_m_s2
        if math.isnan(fz):
            if not sample.has_rates:
                self._note("no_accel", "sample at %.6f s has no vertical acceleration", sample.t_s)
            return
        self.push_accel(sample.t_s, fx, fz)

    def push_accel(self, t: float, fx: float, fz: float) -> None:
        """Specific force along body x (forward) and z (up), m/s², at IMU stamp ``t``."""
        c = self.config
        if not (math.isfinite(t) and math.isfinite(fz)) or abs(fz) > c.max_accel_m_s2:
            self._note("bad_accel", "implausible acceleration %r m/s² at %r s; dropped", fz, t)
            return
        gate = self.plausibility
        if gate.enabled and not (gate.in_range("accel_z", fz) and gate.in_range("accel_x", fx)):
            self._note(REJECTED_RANGE, "acceleration (%r, %r) m/s² at %r s; dropped", fx, fz, t)
            return
        if t <= self._t_last:
            self._note(
                "out_of_order",
                "acceleration at %.6f s is not after the previous one (%.6f s); dropped",
                t,
                self._t_last,
            )
            return
        dt = t - self._t_last
        self._t_last = t
        if dt > c.max_gap_s:
            if self._started:
                self._note("gap", "no acceleration for %.3f s before %.6f s; restarting", dt, t)
            self._reset_state()
        phi = self._phi
        cphi = math.cos(phi)
        f_z = fz * cphi + (fx * math.sin(phi) if math.isfinite(fx) else 0.0)
        # lever arm: the camera's extra vertical acceleration L d²(sin φ)/dt² from the change
        # of the gyro pitch rate since the previous step (the bias cancels in the difference)
        rate = self._rate if t - self._rate_t <= c.max_gap_s else math.nan
        if not self._started:
            self._started = True
            self._t_start = t
            if self._n == 0:
                self._g = f_z
                self._n = 1
            self._rate_prev = rate
            self._history.append((t, 0.0, 0.0))
            return
        a = f_z
        if math.isfinite(rate) and math.isfinite(self._rate_prev):
            a += c.imu_to_camera_forward_m * cphi * (rate - self._rate_prev) / dt
        self._rate_prev = rate
        self._n += 1
        # gravity + bias: expanding mean, then exponential with gravity_tau_s
        alpha = max(1.0 / self._n, dt / c.gravity_tau_s)
        self._g += alpha * (a - self._g)
        a -= self._g
        v_new = self._v + (a - self._k_v * self._v - self._k_z * self._z) * dt
        self._z += 0.5 * (self._v + v_new) * dt
        self._v = v_new
        hist = self._history
        hist.append((t, self._z, self._v))
        while hist and hist[0][0] < t - c.history_s:
            hist.popleft()

    # -- output ---------------------------------------------------------------------------
    @property
    def lever_arm(self) -> bool:
        """True when gyro pitch rates are coming in (the lever-arm term is included)."""
        return math.isfinite(self._rate) and self._t_last - self._rate_t <= self.config.max_gap_s

    def at(self, t: float) -> HeaveEstimate:
        """Δz_cam at time ``t`` on the IMU clock (see the module docstring)."""
        c = self.config
        hist = self._history
        lever = self.lever_arm
        if not hist:
            return HeaveEstimate(t, math.nan, False, lever, "no acceleration")
        if t - self._t_start < c.warmup_s:
            return HeaveEstimate(t, math.nan, False, lever, "warming up")
        t_new, z_new, v_new = hist[-1]
        if t >= t_new:
            ahead = t - t_new
            if ahead > c.max_extrapolation_s:
                return HeaveEstimate(
                    t, math.nan, False, lever, f"no acceleration for {ahead:.3f} s"
                )
            return HeaveEstimate(t, z_new + v_new * ahead, True, lever)
        if t < hist[0][0]:
            return HeaveEstimate(t, math.nan, False, lever, "before the history")
        # queries come just behind the newest sample: scan backwards
        i = len(hist) - 2
        while i > 0 and hist[i][0] > t:
            i -= 1
        ta, za, _ = hist[i]
        tb, zb, _ = hist[i + 1]
        w = (t - ta) / (tb - ta) if tb > ta else 1.0
        return HeaveEstimate(t, za + w * (zb - za), True, lever)
