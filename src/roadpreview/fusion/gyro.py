"""The gyro pitch-rate stream, buffered by time stamp and kept as a running integral.

Each sample is taken as the mean rate over the interval since the previous
sample (a MEMS output data rate with its decimation filter; the simulator's
``sampling="average"``), so the integral of the rate is exact at the sample
stamps and linear in between. The buffer keeps three running sums at knots:

* ``G`` the integral of the measured rate (rad),
* ``V`` the variance that integral carries (white rate noise, bridged gaps),
* ``M`` the time covered by measurements (s): the bias acts only there.

Any back end then predicts over [s1, s2] with ``G(s2) - G(s1) - b (M(s2) - M(s1))``
and process variance ``V(s2) - V(s1)``, whatever the number of samples in
between (the IMU-rate prediction, composed exactly for the linear model).

Bad input never reaches these sums: a NaN or infinite value or stamp, a rate
at or beyond the sensor range (absurd or saturated), a duplicated stamp and a
sample older than what is already committed are rejected with a log line.
Samples out of order but not yet committed are sorted in. A gap up to the
IMU timeout is bridged by the mean of the rates on both sides, with the
variance of `GyroConfig.gap_rate_std_rad_s`; a longer one is an outage that
adds no rate and no bias, only the variance of an unmeasured rate.
"""

from __future__ import annotations

import bisect
import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.fusion.config import GyroConfig

log = logging.getLogger(__name__)

_DUPLICATE_S = 1e-6  # stamps closer than this are the same sample
_MAX_LOGS_PER_KIND = 20

MEASURED, BRIDGED, OUTAGE, START = 0, 1, 2, 3


@dataclass(frozen=True, slots=True)
class Motion:
    """What the gyro says about one interval: integral, its variance, measured time."""

    dG: float  #: integral of the measured rate, rad
    dV: float  #: variance of that integral, rad²
    dM: float  #: duration covered by measurements (the bias acts there), s


class RejectCounter:
    """Counts rejected inputs by kind and logs the first few of each kind."""

    def __init__(self, what: str) -> None:
        self.what = what
        self.counts: dict[str, int] = {}

    def __call__(self, kind: str, msg: str, *args: object) -> None:
        n = self.counts.get(kind, 0) + 1
        self.counts[kind] = n
        if n <= _MAX_LOGS_PER_KIND:
            log.warning("%s: " + msg, self.what, *args)
            if n == _MAX_LOGS_PER_KIND:
                log.warning("%s: further '%s' events are counted, not logged", self.what, kind)


class GyroHistory:
    """Pitch-rate samples sorted by stamp (IMU clock) with running integral, variance, time."""

    def __init__(self, cfg: GyroConfig, rejects: RejectCounter | None = None) -> None:
        self.cfg = cfg
        self.rejects = rejects or RejectCounter("gyro")
        self._q = 0.5 * cfg.noise_density**2  # two-sided PSD: Var(∫ω dt over T) = q T
        self.reset()

    def reset(self) -> None:
        self._s: list[float] = []  # knot stamps
        self._g: list[float] = []  # running integral at the knots
        self._v: list[float] = []  # running variance
        self._m: list[float] = []  # running measured time
        self._w: list[float] = []  # rate of the segment ending at the knot
        self._kind: list[int] = []  # MEASURED / BRIDGED / OUTAGE / START
        self._range = self.cfg.range_rad_s
        self._set_period(1.0 / self.cfg.rate_hz)  # also counts regular intervals
        self.floor = -math.inf  #: stamps at or before this are committed: late samples
        self.n_accepted = 0

    # -- input --------------------------------------------------------------------------
    def push(self, t: float, rate: float) -> bool:
        """Add a sample; False (and a log line) when it is rejected."""
        s = self._s
        if s:  # the usual case first: a regular next sample (NaN and inf fail these tests)
            dt = t - s[-1]
            if _DUPLICATE_S < dt <= self._gap_limit and abs(rate) < self._range and t > self.floor:
                s.append(t)
                self._g.append(self._g[-1] + rate * dt)
                self._v.append(self._v[-1] + self._q * dt)
                self._m.append(self._m[-1] + dt)
                self._w.append(rate)
                self._kind.append(MEASURED)
                self.n_accepted += 1
                self._n_regular += 1
                self._sum_regular += dt
                if self._n_regular == 64:
                    self._set_period(self._sum_regular / 64.0)
                return True
        return self._push_checked(t, rate)

    def _set_period(self, period: float) -> None:
        """The sample period, re-estimated every 64 regular samples (their mean interval)."""
        self._period = period
        self._gap_limit = self.cfg.gap_factor * period
        self._n_regular = 0
        self._sum_regular = 0.0

    def _push_checked(self, t: float, rate: float) -> bool:
        if not (math.isfinite(t) and math.isfinite(rate)):
            self.rejects("nonfinite", "sample (t=%r, rate=%r) is not finite: rejected", t, rate)
            return False
        if abs(rate) >= self.cfg.range_rad_s:
            self.rejects(
                "range",
                "rate %.4g rad/s at t=%.6f is at or beyond the sensor range ±%.4g rad/s"
                " (absurd or saturated): rejected",
                rate,
                t,
                self.cfg.range_rad_s,
            )
            return False
        if t <= self.floor:
            self.rejects(
                "late",
                "sample at t=%.6f arrived after that time was committed (%.6f): rejected",
                t,
                self.floor,
            )
            return False
        s = self._s
        if not s or t > s[-1] + _DUPLICATE_S:
            self._append(t, rate)
            self.n_accepted += 1
            return True
        if abs(t - s[-1]) <= _DUPLICATE_S:
            self.rejects("duplicate", "duplicated stamp t=%.6f: rejected", t)
            return False
        return self._insert(t, rate)

    def _append(self, t: float, w: float) -> None:
        s = self._s
        if not s:
            self._knot(t - self._period, 0.0, 0.0, 0.0, 0.0, START)
            self._knot(t, w * self._period, self._q * self._period, self._period, w, MEASURED)
            return
        dt = t - s[-1]
        if dt <= self._gap_limit:
            self._knot(
                t, self._g[-1] + w * dt, self._v[-1] + self._q * dt, self._m[-1] + dt, w, MEASURED
            )
            return
        gap = dt - self._period
        if dt <= self.cfg.timeout_s:
            self.rejects("gap", "gap of %.4f s before t=%.6f bridged", dt, t)
            w_bridge = 0.5 * (self._w[-1] + w)
            self._knot(
                t - self._period,
                self._g[-1] + w_bridge * gap,
                self._v[-1] + (self.cfg.gap_rate_std_rad_s * gap) ** 2,
                self._m[-1] + gap,
                w_bridge,
                BRIDGED,
            )
        else:
            self.rejects("outage", "no gyro for %.3f s before t=%.6f (IMU outage)", dt, t)
            self._knot(
                t - self._period,
                self._g[-1],
                self._v[-1] + (self.cfg.blind_rate_std_rad_s * gap) ** 2,
                self._m[-1],
                0.0,
                OUTAGE,
            )
        p = self._period
        self._knot(t, self._g[-1] + w * p, self._v[-1] + self._q * p, self._m[-1] + p, w, MEASURED)

    def _knot(self, t: float, g: float, v: float, m: float, w: float, kind: int) -> None:
        self._s.append(t)
        self._g.append(g)
        self._v.append(v)
        self._m.append(m)
        self._w.append(w)
        self._kind.append(kind)

    def _insert(self, t: float, w: float) -> bool:
        """A sample older than the newest but not committed: sort it in and rebuild after it."""
        s = self._s
        i = bisect.bisect_left(s, t)
        for j in (i - 1, i):
            if 0 <= j < len(s) and self._kind[j] == MEASURED and abs(s[j] - t) <= _DUPLICATE_S:
                self.rejects("duplicate", "duplicated stamp t=%.6f: rejected", t)
                return False
        # keep the measured samples before t; re-append t and those after it in order
        j = i - 1
        while j >= 0 and self._kind[j] != MEASURED:
            j -= 1
        later = [(s[k], self._w[k]) for k in range(j + 1, len(s)) if self._kind[k] == MEASURED]
        cut = j + 1 if j >= 0 else 0
        for lst in (self._s, self._g, self._v, self._m, self._w, self._kind):
            del lst[cut:]
        self.rejects("reordered", "sample at t=%.6f arrived out of order: sorted in", t)
        self._append(t, w)
        for tt, ww in later:
            self._append(tt, ww)
        self.n_accepted += 1
        return True

    # -- queries ------------------------------------------------------------------------
    @property
    def newest(self) -> float | None:
        """Stamp of the newest sample (None before the first)."""
        return self._s[-1] if self._s else None

    @property
    def period(self) -> float:
        """Current estimate of the sample period, s."""
        return self._period

    def _at(self, t: float) -> tuple[float, float, float]:
        """(G, V, M) at stamp ``t``; beyond the newest sample the last rate is held."""
        s = self._s
        if t >= s[-1]:
            d = t - s[-1]
            return (
                self._g[-1] + self._w[-1] * d,
                self._v[-1] + (self.cfg.hold_rate_std_rad_s * d) ** 2,
                self._m[-1] + d,
            )
        if t <= s[0]:
            return self._g[0], self._v[0], self._m[0]
        i = bisect.bisect_right(s, t)
        a = (t - s[i - 1]) / (s[i] - s[i - 1])
        return (
            self._g[i - 1] + a * (self._g[i] - self._g[i - 1]),
            self._v[i - 1] + a * (self._v[i] - self._v[i - 1]),
            self._m[i - 1] + a * (self._m[i] - self._m[i - 1]),
        )

    def motion(self, s1: float, s2: float) -> Motion:
        """Integral, variance and measured time of the gyro over stamps [s1, s2]."""
        if not self._s:
            d = max(s2 - s1, 0.0)
            return Motion(0.0, (self.cfg.hold_rate_std_rad_s * d) ** 2, 0.0)
        g1, v1, m1 = self._at(s1)
        g2, v2, m2 = self._at(s2)
        if s1 > self._s[-1]:  # both extrapolated: the variance of the second part only
            d = s2 - s1
            v1, v2 = 0.0, (self.cfg.hold_rate_std_rad_s * d) ** 2
        return Motion(g2 - g1, max(v2 - v1, 0.0), m2 - m1)

    def rate_at(self, t: float) -> float:
        """The measured rate of the sample covering stamp ``t`` (the newest beyond the end)."""
        s = self._s
        if not s:
            return 0.0
        i = min(bisect.bisect_left(s, t), len(s) - 1)
        return self._w[i]

    def integral_at(self, t: NDArray[np.float64], since: float) -> NDArray[np.float64]:
        """G at stamps ``t`` (vectorised), using knots from ``since`` on (for the alignment)."""
        s = self._s
        i0 = max(bisect.bisect_left(s, since) - 1, 0)
        return np.interp(t, np.asarray(s[i0:]), np.asarray(self._g[i0:]))

    def covers(self, t: float) -> bool:
        """True when the buffer holds stamp ``t``: not older than its oldest knot and a real
        sample at or after it has been received."""
        return bool(self._s) and self._s[0] <= t <= self._s[-1]

    def trim(self, before: float) -> None:
        """Forget knots older than stamp ``before`` (keeping one knot before it)."""
        i = bisect.bisect_left(self._s, before) - 1
        if i > 256:  # amortised: drop in blocks
            for lst in (self._s, self._g, self._v, self._m, self._w, self._kind):
                del lst[:i]
