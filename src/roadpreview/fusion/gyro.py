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
from operator import itemgetter

import numpy as np
from numpy.typing import NDArray

from roadpreview.fusion.config import GyroConfig

log = logging.getLogger(__name__)

_DUPLICATE_S = 1e-6  # stamps closer than this are the same sample
_RECENT = 32  # knots searched first by the per-frame queries (frames are near the newest)
_MAX_LOGS_PER_KIND = 20

MEASURED, BRIDGED, OUTAGE, START = 0, 1, 2, 3
_G = itemgetter(0)  # the running integral G of a knot


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
    """Pitch-rate samples sorted by stamp (IMU clock) with running integral, variance, time.

    Knots are kept in two lists: the stamps (searched with `bisect`) and, per knot, the
    tuple (G, V, M, rate, kind) — one append per list and sample, which is most of the
    cost of a sample (`push` runs at the IMU rate).
    """

    _n_regular: int  # regular intervals counted since the period was last set
    _sum_regular: float  # and their sum, s

    def __init__(self, cfg: GyroConfig, rejects: RejectCounter | None = None) -> None:
        self.cfg = cfg
        self.rejects = rejects or RejectCounter("gyro")
        self._q = 0.5 * cfg.noise_density**2  # two-sided PSD: Var(∫ω dt over T) = q T
        self.reset()

    def reset(self) -> None:
        #: stamp of the newest sample (None before the first)
        self.newest: float | None = None
        self._s: list[float] = []  # knot stamps
        # per knot: running integral G, its variance V, measured time M, the rate of the
        # segment ending at the knot, and its kind (MEASURED / BRIDGED / OUTAGE / START)
        self._k: list[tuple[float, float, float, float, int]] = []
        self._range = self.cfg.range_rad_s
        self._set_period(1.0 / self.cfg.rate_hz)  # also counts regular intervals
        self.floor = -math.inf  #: stamps at or before this are committed: late samples
        self._n_trimmed = 0  # knots dropped from the front so far (absolute knot numbers)
        # numpy copies of the stamps and integral (first absolute knot, s, G), for integral_at
        self._arrays: tuple[int, NDArray[np.float64], NDArray[np.float64]] | None = None
        # the end of the interval `motion3` returned last, (G, V, M) and the rate there: the
        # start of the next frame's interval; and the stamp `rate_change` last found a rate
        # for as its start (a key frame's, the same for many frames) with that rate. Cleared
        # when knots are rebuilt (`_insert`); the knots they come from stay otherwise.
        self._end_s = math.nan
        self._end = (0.0, 0.0, 0.0, 0.0)
        self._start_s = math.nan
        self._start_w = 0.0

    # -- input --------------------------------------------------------------------------
    def push(self, t: float, rate: float) -> bool:
        """Add a sample; False (and a log line) when it is rejected."""
        s = self._s
        if s:  # the usual case first: a regular next sample (NaN and inf fail these tests)
            dt = t - s[-1]
            if _DUPLICATE_S < dt <= self._gap_limit and abs(rate) < self._range and t > self.floor:
                k = self._k
                g, v, m, _, _ = k[-1]
                s.append(t)
                k.append((g + rate * dt, v + self._q * dt, m + dt, rate, MEASURED))
                self.newest = t
                n = self._n_regular = self._n_regular + 1
                self._sum_regular += dt
                if n == 64:
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
        g, v, m, w_last, _ = self._k[-1]
        dt = t - s[-1]
        if dt <= self._gap_limit:
            self._knot(t, g + w * dt, v + self._q * dt, m + dt, w, MEASURED)
            return
        gap = dt - self._period
        if dt <= self.cfg.timeout_s:
            self.rejects("gap", "gap of %.4f s before t=%.6f bridged", dt, t)
            w_bridge = 0.5 * (w_last + w)
            g, v, m = g + w_bridge * gap, v + (self.cfg.gap_rate_std_rad_s * gap) ** 2, m + gap
            self._knot(t - self._period, g, v, m, w_bridge, BRIDGED)
        else:
            self.rejects("outage", "no gyro for %.3f s before t=%.6f (IMU outage)", dt, t)
            v = v + (self.cfg.blind_rate_std_rad_s * gap) ** 2
            self._knot(t - self._period, g, v, m, 0.0, OUTAGE)
        p = self._period
        self._knot(t, g + w * p, v + self._q * p, m + p, w, MEASURED)

    def _knot(self, t: float, g: float, v: float, m: float, w: float, kind: int) -> None:
        self.newest = t
        self._s.append(t)
        self._k.append((g, v, m, w, kind))

    def _insert(self, t: float, w: float) -> bool:
        """A sample older than the newest but not committed: sort it in and rebuild after it."""
        s, k = self._s, self._k
        i = bisect.bisect_left(s, t)
        for j in (i - 1, i):
            if 0 <= j < len(s) and k[j][4] == MEASURED and abs(s[j] - t) <= _DUPLICATE_S:
                self.rejects("duplicate", "duplicated stamp t=%.6f: rejected", t)
                return False
        # keep the measured samples before t; re-append t and those after it in order
        j = i - 1
        while j >= 0 and k[j][4] != MEASURED:
            j -= 1
        later = [(s[n], k[n][3]) for n in range(j + 1, len(s)) if k[n][4] == MEASURED]
        cut = j + 1 if j >= 0 else 0
        del s[cut:]
        del k[cut:]
        self._arrays = None  # knots after the cut change
        self._end_s = self._start_s = math.nan
        self.rejects("reordered", "sample at t=%.6f arrived out of order: sorted in", t)
        self._append(t, w)
        for tt, ww in later:
            self._append(tt, ww)
        return True

    # -- queries ------------------------------------------------------------------------
    @property
    def period(self) -> float:
        """Current estimate of the sample period, s."""
        return self._period

    def _at(self, t: float) -> tuple[float, float, float]:
        """(G, V, M) at stamp ``t``; beyond the newest sample the last rate is held."""
        s, k = self._s, self._k
        if t >= s[-1]:
            d = t - s[-1]
            g, v, m, w, _ = k[-1]
            return g + w * d, v + (self.cfg.hold_rate_std_rad_s * d) ** 2, m + d
        if t <= s[0]:
            return k[0][:3]
        i = bisect.bisect_right(s, t)
        a = (t - s[i - 1]) / (s[i] - s[i - 1])
        g0, v0, m0, _, _ = k[i - 1]
        g1, v1, m1, _, _ = k[i]
        return g0 + a * (g1 - g0), v0 + a * (v1 - v0), m0 + a * (m1 - m0)

    def motion(self, s1: float, s2: float) -> Motion:
        """Integral, variance and measured time of the gyro over stamps [s1, s2]."""
        return Motion(*self.motion3(s1, s2))

    def motion3(self, s1: float, s2: float) -> tuple[float, float, float]:
        """`motion` as a plain (dG, dV, dM) tuple: the per-frame call of the back ends."""
        s = self._s
        if not s:
            d = max(s2 - s1, 0.0)
            return 0.0, (self.cfg.hold_rate_std_rad_s * d) ** 2, 0.0
        if s[0] < s1 <= s2 < s[-1]:  # the usual case: both inside the buffer (as `_at`)
            k = self._k
            # a frame interval is at the recent end: search the last knots when they hold it
            lo = len(s) - _RECENT
            if lo <= 0 or s[lo] > s1:
                lo = 0
            if s1 == self._end_s:  # the end of the previous interval (the frame before)
                ga, va, ma, _ = self._end
            else:
                i = lo = bisect.bisect_right(s, s1, lo)
                a = (s1 - s[i - 1]) / (s[i] - s[i - 1])
                g0, v0, m0, _, _ = k[i - 1]
                g1, v1, m1, _, _ = k[i]
                ga, va, ma = g0 + a * (g1 - g0), v0 + a * (v1 - v0), m0 + a * (m1 - m0)
            i = bisect.bisect_right(s, s2, lo)
            a = (s2 - s[i - 1]) / (s[i] - s[i - 1])
            g0, v0, m0, _, _ = k[i - 1]
            g1, v1, m1, _, _ = k[i]
            gb, vb, mb = g0 + a * (g1 - g0), v0 + a * (v1 - v0), m0 + a * (m1 - m0)
            # (and the rate there for `rate_change`: that of the first knot at or after s2)
            self._end_s = s2
            self._end = (gb, vb, mb, k[i - 1][3] if s[i - 1] == s2 else k[i][3])
            dv = vb - va
            return gb - ga, 0.0 if dv < 0.0 else dv, mb - ma  # max(dv, 0.0)
        g1, v1, m1 = self._at(s1)
        g2, v2, m2 = self._at(s2)
        if s1 > s[-1]:  # both extrapolated: the variance of the second part only
            d = s2 - s1
            v1, v2 = 0.0, (self.cfg.hold_rate_std_rad_s * d) ** 2
        return g2 - g1, max(v2 - v1, 0.0), m2 - m1

    def rate_change(self, s1: float, s2: float) -> float:
        """The measured rate of the sample covering stamp ``s2`` minus that covering ``s1``
        (the newest sample's beyond the end; 0 without samples). Per frame, s2 is the end of
        the interval `motion3` returned last and s1 a key frame's stamp, the same from frame
        to frame: their rates are kept rather than searched again."""
        s = self._s
        if not s:
            return 0.0
        k, n = self._k, len(s)
        if s2 == self._end_s:
            w2 = self._end[3]
        else:
            lo = n - _RECENT
            if lo <= 0 or s[lo] >= s2:
                lo = 0
            i = bisect.bisect_left(s, s2, lo)
            w2 = k[i][3] if i < n else k[-1][3]
        if s1 == self._start_s and s[0] < s1:  # (its knot is still there)
            return w2 - self._start_w
        j = bisect.bisect_left(s, s1)
        if j == n:
            return w2 - k[-1][3]  # beyond the newest sample: its rate (not kept, it changes)
        w1 = self._start_w = k[j][3]
        self._start_s = s1
        return w2 - w1

    def integral_at(self, t: NDArray[np.float64], since: float) -> NDArray[np.float64]:
        """G at stamps ``t`` (vectorised), using knots from ``since`` on (for the alignment)."""
        s = self._s
        i0 = max(bisect.bisect_left(s, since) - 1, 0)
        sa, ga = self._knot_arrays()
        return np.interp(t, sa[i0:], ga[i0:])

    def _knot_arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The knot stamps and integral as numpy arrays, extended by the knots appended since
        the last call (converting the whole buffer each time cost 0.2 ms per alignment)."""
        s, k = self._s, self._k
        first = self._n_trimmed
        c = self._arrays
        if c is not None and c[0] + c[1].size > first:
            c_first, sa, ga = c
            drop = first - c_first  # knots trimmed since
            new = c_first + sa.size - first  # knots already converted
            if new < len(s):
                sa = np.concatenate((sa[drop:], np.fromiter(s[new:], np.float64, len(s) - new)))
                g_new = np.fromiter(map(_G, k[new:]), np.float64, len(s) - new)
                ga = np.concatenate((ga[drop:], g_new))
            else:
                sa, ga = sa[drop:], ga[drop:]
        else:
            sa = np.fromiter(s, np.float64, len(s))
            ga = np.fromiter(map(_G, k), np.float64, len(k))
        self._arrays = (first, sa, ga)
        return sa, ga

    def covers(self, t: float) -> bool:
        """True when the buffer holds stamp ``t``: not older than its oldest knot and a real
        sample at or after it has been received."""
        return bool(self._s) and self._s[0] <= t <= self._s[-1]

    def trim(self, before: float) -> None:
        """Forget knots older than stamp ``before`` (keeping one knot before it)."""
        s = self._s
        if len(s) > 257 and s[257] < before:  # amortised: drop in blocks of more than 256
            i = bisect.bisect_left(s, before) - 1
            del s[:i]
            del self._k[:i]
            self._n_trimmed += i
