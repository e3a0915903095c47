"""What a car's motion sensors can physically report: per-quantity ranges and a gyro spike gate.

Integrity checks (E2E CRC, checksums, counters) say a frame arrived as it was sent; they
do not say the value is possible. CRC-8 passes about 1 random payload in 256, and a sensor
can send a clipped or glitched value with a perfect CRC. `PlausibilityConfig` holds the
physical limits of a road car (defaults with their reasons) and `SampleGate` applies them to
each `ImuSample` / `SpeedSample` after the integrity checks:

* ``rejected_range``: a rate, acceleration or speed outside its physical range;
* ``rejected_spike``: a gyro rate far from the median of the last few accepted samples
  (deviation > ``spike_k`` · 1.4826 · MAD + ``spike_floor_rad_s``, over ``spike_window_s``).
  O(1) per sample: a ring of at most ``spike_max_samples`` values per axis.

Values at a DBC signal's limits (``saturated``) are judged by the CAN decoder, which knows
the signal. The CAN decoder, the IMU CSV reader and the heave observer use the same gate,
so one set of limits decides what the estimators may see. Pure math: no I/O; imported by
the estimation packages as well as by ``canbus``.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError
from roadpreview.types import ImuSample, InputSample, SpeedSample

#: problem reasons (snake_case, the per-source ``problems`` contract)
REJECTED_RANGE = "rejected_range"
REJECTED_SPIKE = "rejected_spike"
SATURATED = "saturated"
#: a spike gate that rejected ``spike_max_rejects`` samples in a row starts its history again
SPIKE_GATE_RESET = "spike_gate_reset"

RATE_QUANTITIES = ("roll_rate", "pitch_rate", "yaw_rate")
ACCEL_QUANTITIES = ("accel_x", "accel_y", "accel_z")
_IMU_QUANTITIES = RATE_QUANTITIES + ACCEL_QUANTITIES


@dataclass(frozen=True)
class PlausibilityConfig:
    """``[plausibility]``: the physical limits of a road car's motion (the input gate)."""

    roll_rate_max_rad_s: float = param(
        1.5,
        unit="rad/s",
        gt=0.0,
        le=10.0,
        help="|roll rate| above this is rejected: a car's body rolls at a few deg/s in"
        " corners and rarely beyond 30 deg/s on a kerb; 1.5 rad/s (86 deg/s) is 3x the"
        " simulator's harshest bump and below the 163.8 deg/s clip of IMU_RATES",
    )
    pitch_rate_max_rad_s: float = param(
        1.5,
        unit="rad/s",
        gt=0.0,
        le=10.0,
        help="|pitch rate| above this is rejected: body pitch rates stay below ~30 deg/s"
        " even over speed bumps (simulator: 31 deg/s at most); 86 deg/s leaves a 3x margin",
    )
    yaw_rate_max_rad_s: float = param(
        2.0,
        unit="rad/s",
        gt=0.0,
        le=10.0,
        help="|yaw rate| above this is rejected: parking turns reach ~60 deg/s, a spin"
        " ~100 deg/s; 2 rad/s (115 deg/s)",
    )
    accel_max_m_s2: float = param(
        30.0,
        unit="m/s^2",
        gt=0.0,
        le=1000.0,
        help="|specific force| on any axis above this is rejected: 3 g including gravity"
        " and the body's jolt over a pothole (a tyre's grip gives ~1 g horizontally)",
    )
    speed_min_m_s: float = param(
        -0.5,
        unit="m/s",
        le=0.0,
        help="a speed below this is rejected: the speed is a magnitude; some ESCs report a"
        " few cm/s below zero at standstill",
    )
    speed_max_m_s: float = param(
        90.0,
        unit="m/s",
        gt=0.0,
        le=1000.0,
        help="a speed above this is rejected: 324 km/h, beyond a road car",
    )
    spike_window_s: float = param(
        0.05,
        unit="s",
        gt=0.0,
        le=1.0,
        help="the gyro spike gate compares a rate with the median of the accepted rates of"
        " this long: 5 samples at 100 Hz; longer windows lag the 10-20 rad/s² of a body"
        " crossing a bump",
    )
    spike_max_samples: int = param(
        8, ge=3, le=64, help="at most this many samples in the spike gate's window (ring size)"
    )
    spike_min_samples: int = param(
        3,
        ge=1,
        le=64,
        help="fewer accepted samples in the window (start, after a gap): no spike check",
    )
    spike_k: float = param(
        6.0,
        unit="",
        gt=0.0,
        le=100.0,
        help="a deviation beyond spike_k robust standard deviations (1.4826 MAD of the"
        " window) plus the floor is a spike",
    )
    spike_floor_rad_s: float = param(
        0.6,
        unit="rad/s",
        ge=0.0,
        le=10.0,
        help="physical floor of the spike gate: a clean simulated drive's largest deviation"
        " from the 5-sample median is 0.36 rad/s (a wheel hitting a bump edge); 0.6 rad/s"
        " (34 deg/s in 10 ms) is no body motion",
    )
    spike_max_rejects: int = param(
        3,
        ge=1,
        le=100,
        help="after this many spikes in a row the gate forgets its window and takes the"
        " next sample: a lasting change is the signal, and the range gate still applies",
    )
    e2e_max_delta_counter: int = param(
        2,
        ge=1,
        le=14,
        help="AUTOSAR E2E P01 MaxDeltaCounter: a counter that advances by more (two or more"
        " frames lost in a row) is counted e2e_counter_jump; the frame is still taken (its"
        " CRC and the range and spike gates judge the payload) and the counter re-synced",
    )
    stamp_step_max_s: float = param(
        1.0,
        unit="s",
        gt=0.0,
        le=3600.0,
        help="a frame stamped this much (or 10 cycle times, if more) after its message's"
        " previous one is held back until the next frame confirms the new time (one sample"
        " lost after a real gap; a single +1 h stamp is dropped)",
    )
    stamp_resync_s: float = param(
        0.5,
        unit="s",
        gt=0.0,
        le=60.0,
        help="frames stamped before their message's newest one for this long (their own"
        " stamps advancing: the sender's clock stepped back) are taken again, counted"
        " 'resynced': the drive goes on instead of waiting for the old time",
    )
    enabled: bool = param(True, help="false: no range or spike gate on the values (diagnosis only)")

    def validate(self, where: str = "PlausibilityConfig") -> None:
        """Ranges and cross-field checks; raise `ConfigError`."""
        check_ranges(self, where)
        if self.spike_min_samples > self.spike_max_samples:
            raise ConfigError(
                f"{where}.spike_min_samples = {self.spike_min_samples}: must be <="
                f" spike_max_samples = {self.spike_max_samples}"
            )

    def limits(self, quantity: str) -> tuple[float, float]:
        """(low, high) of a quantity (`RATE_QUANTITIES`, `ACCEL_QUANTITIES`, ``speed``), SI."""
        if quantity == "speed":
            return (self.speed_min_m_s, self.speed_max_m_s)
        if quantity in ACCEL_QUANTITIES:
            return (-self.accel_max_m_s2, self.accel_max_m_s2)
        if quantity in RATE_QUANTITIES:
            m = getattr(self, f"{quantity}_max_rad_s")
            return (-float(m), float(m))
        raise KeyError(quantity)

    def in_range(self, quantity: str, value: float) -> bool:
        """True for a NaN (not available: judged elsewhere) or a value inside the limits."""
        if math.isnan(value):
            return True
        lo, hi = self.limits(quantity)
        return lo <= value <= hi


class SpikeGate:
    """The spike gate of one gyro axis (module doc): `check` a value, `accept` it if taken."""

    def __init__(self, config: PlausibilityConfig) -> None:
        self.config = config
        self._ring: deque[tuple[float, float]] = deque(maxlen=config.spike_max_samples)
        self._rejects = 0
        self.resets = 0  #: times the gate forgot its window after spike_max_rejects spikes

    def is_spike(self, t: float, value: float) -> bool:
        """True if ``value`` at ``t`` is a spike against the recent accepted values."""
        c = self.config
        ring = self._ring
        while ring and ring[0][0] < t - c.spike_window_s:
            ring.popleft()
        if len(ring) < c.spike_min_samples:
            return False
        vals = sorted(v for _, v in ring)
        med = _median_sorted(vals)
        mad = _median_sorted(sorted(abs(v - med) for v in vals))
        return abs(value - med) > c.spike_k * 1.4826 * mad + c.spike_floor_rad_s

    def rejected(self) -> bool:
        """Note a rejection; True when this one made the gate forget its window."""
        self._rejects += 1
        if self._rejects >= self.config.spike_max_rejects:
            self._ring.clear()
            self._rejects = 0
            self.resets += 1
            return True
        return False

    def accept(self, t: float, value: float) -> None:
        """Add an accepted value to the window."""
        if math.isfinite(value):
            self._ring.append((t, value))
        self._rejects = 0

    def clear(self) -> None:
        self._ring.clear()
        self._rejects = 0


def _median_sorted(vals: list[float]) -> float:
    n = len(vals)
    mid = n // 2
    return vals[mid] if n % 2 else 0.5 * (vals[mid - 1] + vals[mid])


class SampleGate:
    """Range and spike gate for a stream of samples of one source (module doc).

    `check` returns the reason a sample is rejected ('' when it is taken) and counts it
    in `problems`; a taken sample enters the spike gate's window.
    """

    def __init__(self, config: PlausibilityConfig | None = None) -> None:
        self.config = config or PlausibilityConfig()
        self.config.validate()
        self.problems: Counter[str] = Counter()
        self._spikes = {q: SpikeGate(self.config) for q in RATE_QUANTITIES}

    def reason(self, sample: InputSample) -> tuple[str, str]:
        """(reason, quantity) the sample is implausible for, or ('', '') (nothing counted)."""
        c = self.config
        if not c.enabled:
            return "", ""
        if isinstance(sample, SpeedSample):
            if not c.in_range("speed", sample.speed_mps):
                return REJECTED_RANGE, "speed"
            return "", ""
        for q, v in zip(_IMU_QUANTITIES, sample.rates_rad_s + sample.accel_m_s2, strict=True):
            if not c.in_range(q, v):
                return REJECTED_RANGE, q
        for q, v in zip(RATE_QUANTITIES, sample.rates_rad_s, strict=True):
            if not math.isnan(v) and self._spikes[q].is_spike(sample.t_s, v):
                return REJECTED_SPIKE, q
        return "", ""

    def check(self, sample: InputSample) -> str:
        """'' if the sample is plausible (and now part of the history), else the reason,
        counted in `problems`."""
        reason, quantity = self.reason(sample)
        if reason:
            self.problems[reason] += 1
            if reason == REJECTED_SPIKE and self._spikes[quantity].rejected():
                self.problems[SPIKE_GATE_RESET] += 1
            return reason
        if isinstance(sample, ImuSample):
            for q, v in zip(RATE_QUANTITIES, sample.rates_rad_s, strict=True):
                if not math.isnan(v):
                    self._spikes[q].accept(sample.t_s, v)
        return ""

    def describe(self, sample: InputSample, reason: str) -> str:
        """A short text of what was implausible, for a log line."""
        c = self.config
        if isinstance(sample, SpeedSample):
            lo, hi = c.limits("speed")
            return f"speed {sample.speed_mps:g} m/s (range {lo:g}..{hi:g})"
        for q, v in zip(_IMU_QUANTITIES, sample.rates_rad_s + sample.accel_m_s2, strict=True):
            unit = "rad/s" if q in RATE_QUANTITIES else "m/s^2"
            if reason == REJECTED_RANGE and not c.in_range(q, v):
                lo, hi = c.limits(q)
                return f"{q} {v:g} {unit} (range {lo:g}..{hi:g})"
        if reason == REJECTED_SPIKE:
            return f"gyro rate far from its last {c.spike_window_s * 1000:.0f} ms"
        return reason


__all__ = [
    "ACCEL_QUANTITIES",
    "RATE_QUANTITIES",
    "REJECTED_RANGE",
    "REJECTED_SPIKE",
    "SATURATED",
    "SPIKE_GATE_RESET",
    "PlausibilityConfig",
    "SampleGate",
    "SpikeGate",
]
