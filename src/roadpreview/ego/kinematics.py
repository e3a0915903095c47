"""Longitudinal kinematics the detector needs besides the trajectory: the ego's speed and
acceleration from its speed samples, the lead's acceleration from its distance, and the
high-pass of the fused pitch that the vision's horizon uses."""

from __future__ import annotations

import math
from collections import deque

import numpy as np


class LeadKinematics:
    """The lead's longitudinal acceleration = the ego's + the second derivative of the
    gap, from a quadratic fit of the distance over a sliding window (robust to the
    frame-to-frame noise of the distance estimate)."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._t: deque[float] = deque()
        self._d: deque[float] = deque()

    def reset(self) -> None:
        """A new lead: forget the old one's distances."""
        self._t.clear()
        self._d.clear()

    def push(self, t: float, distance_m: float, ego_accel: float | None) -> float | None:
        """The lead's acceleration at ``t`` (m/s²; None until the window holds enough)."""
        if math.isfinite(distance_m):
            self._t.append(t)
            self._d.append(distance_m)
        while self._t and self._t[0] < t - self.window_s:
            self._t.popleft()
            self._d.popleft()
        if len(self._t) < 8 or self._t[-1] - self._t[0] < 0.5 * self.window_s:
            return None
        tt = np.fromiter(self._t, float) - t
        coef, cov = np.polyfit(tt, np.fromiter(self._d, float), 2, cov=True)
        rel = 2.0 * float(coef[0])
        rel_std = 2.0 * math.sqrt(max(float(cov[0, 0]), 0.0))
        # shrink towards zero by three standard deviations: the distance estimate jumps
        # while the lead bounces over a bump (its box moves), which is not braking
        rel = math.copysign(max(abs(rel) - 3.0 * rel_std, 0.0), rel)
        return rel + (ego_accel or 0.0)


class EgoSpeed:
    """The ego's latest speed and its acceleration over the last half second."""

    def __init__(self) -> None:
        self.t = math.nan  #: time of the latest finite speed, s
        self.v = math.nan  #: the latest finite speed, m/s
        self.accel: float | None = None  #: m/s² (None until 3 samples span 0.1 s)
        self._history: deque[tuple[float, float]] = deque(maxlen=64)

    @property
    def speed_mps(self) -> float | None:
        """The latest speed (None before the first)."""
        return self.v if math.isfinite(self.v) else None

    def push(self, t: float, v: float) -> None:
        """A speed sample (NaN: not available, ignored)."""
        if not math.isfinite(v):
            return
        self._history.append((t, v))
        self.t, self.v = t, v
        old = [(tt, vv) for tt, vv in self._history if tt >= t - 0.5]
        if len(old) >= 3 and old[-1][0] - old[0][0] > 0.1:
            self.accel = (old[-1][1] - old[0][1]) / (old[-1][0] - old[0][0])


class HorizonFilter:
    """The camera's pitch relative to the road: the fused pitch minus its first-order
    low-pass (time constant ``tau_s``, exact for any frame interval); the slow part is
    the road's grade, which the lead shares."""

    def __init__(self, tau_s: float) -> None:
        self.tau_s = tau_s
        self._slow = math.nan
        self._slow_t = math.nan
        self.pitch_rad = 0.0  #: the high-passed pitch after the last update (0 before)

    def update(self, t: float, phi: float) -> float:
        """Take the fused pitch ``phi`` at ``t``; return the high-passed pitch."""
        if not math.isfinite(self._slow) or not t > self._slow_t:
            if not math.isfinite(self._slow):
                self._slow = phi
            self._slow_t = t if math.isfinite(t) else self._slow_t
        else:
            a = 1.0 - math.exp(-(t - self._slow_t) / self.tau_s)
            self._slow += a * (phi - self._slow)
            self._slow_t = t
        self.pitch_rad = phi - self._slow
        return self.pitch_rad
