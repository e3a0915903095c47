"""The ego's vertical acceleration per camera frame, from the IMU's z specific force.

Per accelerometer sample (O(1) scalar work): the slow part, gravity, the
sensor's bias and the slow tilt of the body on hills, is removed by
subtracting an exponential running mean (``highpass_tau_s``); what is left
is the body's bouncing (1-2 Hz), its crossing of bumps and the wheel hop,
as far as the IMU's rate carries it. Samples accumulate until the pipeline
takes the frame's summary (`EgoVerticalMonitor.take`): the RMS and the
largest magnitude since the previous take. NaN without samples.

Implausible values (beyond ``max_accel_mps2``) and samples that go back in
time are dropped and counted in ``problems``.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

from roadpreview.configtools import check_ranges, param


@dataclass(frozen=True)
class EgoVerticalConfig:
    """``[ego]``: how the ego's vertical acceleration is summarised per frame."""

    highpass_tau_s: float = param(
        0.5,
        unit="s",
        gt=0.0,
        le=60.0,
        help="time constant of the running mean subtracted (a 0.3 Hz high-pass): keeps the"
        " 1-2 Hz body bounce, drops gravity, bias and hills",
    )
    max_gap_s: float = param(
        0.2, unit="s", gt=0.0, le=10.0, help="a longer gap restarts the running mean"
    )
    max_accel_mps2: float = param(
        100.0, unit="m/s^2", gt=0.0, help="a specific force beyond this is a broken sample"
    )


@dataclass(frozen=True, slots=True)
class EgoVertical:
    """The ego's band-passed vertical acceleration over one frame interval, m/s²."""

    rms_mps2: float = math.nan
    peak_mps2: float = math.nan
    n_samples: int = 0


class EgoVerticalMonitor:
    """Accelerometer samples in, one `EgoVertical` per camera frame out."""

    def __init__(self, config: EgoVerticalConfig | None = None) -> None:
        self.config = config or EgoVerticalConfig()
        check_ranges(self.config, "EgoVerticalConfig")
        self.problems: Counter[str] = Counter()
        self._t = -math.inf
        self._mean = math.nan
        #: (stamp, band-passed acceleration) of the samples not taken yet
        self._pending: deque[tuple[float, float]] = deque()

    def push(self, t: float, accel_z_mps2: float) -> None:
        """One sample of the z specific force (body up, gravity included) at ``t``."""
        c = self.config
        if not (math.isfinite(t) and math.isfinite(accel_z_mps2)):
            return
        if abs(accel_z_mps2) > c.max_accel_mps2:
            self.problems["implausible"] += 1
            return
        if t <= self._t:
            self.problems["out_of_order"] += 1
            return
        dt = t - self._t
        self._t = t
        if dt > c.max_gap_s or not math.isfinite(self._mean):
            self._mean = accel_z_mps2
            return
        self._mean += (1.0 - math.exp(-dt / c.highpass_tau_s)) * (accel_z_mps2 - self._mean)
        self._pending.append((t, accel_z_mps2 - self._mean))

    def take(self, until: float = math.inf) -> EgoVertical:
        """The summary of the samples stamped up to ``until`` since the previous take (NaN
        without any); later ones stay for the next take. (The run loop holds a frame until
        the IMU has caught up with it: the frame at t takes the samples stamped up to t, as
        without the hold.)"""
        pending = self._pending
        sum_sq, peak, n = 0.0, 0.0, 0
        while pending and pending[0][0] <= until:
            a = pending.popleft()[1]
            sum_sq += a * a
            peak = max(peak, abs(a))
            n += 1
        if n == 0:
            return EgoVertical()
        return EgoVertical(math.sqrt(sum_sq / n), peak, n)
