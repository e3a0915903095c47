"""Camera-IMU time offset: cross-correlation of the visual and the gyro pitch rate.

The offset τ is the IMU stamp minus the camera time of the same instant
(positive when the gyro stamps lag, e.g. CAN latency): a gyro sample stamped
s belongs to camera time s - τ.

Visual rates come from consecutive frames: relative measurements against the
same key frame are chained into one visual pitch track, and the difference of
two consecutive frames divided by their spacing is the mean rate over that
interval. For a candidate τ the gyro's mean rate over exactly the same
interval, shifted by τ, is read from its running integral (so the comparison
is exact whatever the two sampling rates). The Pearson correlation over a
sliding window (bias-free: means are removed) is evaluated on a lag grid finer
than one IMU sample; the peak is refined by a parabola through it and its two
neighbours. The peak correlation is the confidence. No estimate is made from a
window that is too short, too flat (no excitation) or whose peak lies on the
edge of the search range.

Cost (an estimate every `AlignmentConfig.update_period_s`, 10 s of increments
on 45 lags): the gyro integral is read once per distinct frame time and lag
(consecutive increments share a frame), time by time so that `np.interp`'s
search starts next to the point before; the numpy statistics are written as
their elementary steps (the same operations, so the same numbers, without the
generic dispatch that was a third of the time at these sizes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.fusion.config import AlignmentConfig
from roadpreview.fusion.gyro import GyroHistory

_MAX_INCREMENT_FRAMES_S = 0.12  # consecutive frames further apart than this give no rate
_CUT_BLOCK = 256  # expired increments are deleted from the front in blocks of this many
_QUEUE_MAX = 256  # measurements queued by `VisualRateTrack.add` before they are chained


@dataclass(frozen=True, slots=True)
class OffsetEstimate:
    """One cross-correlation result: the offset (s), the peak correlation, the samples used."""

    offset_s: float
    correlation: float
    n_increments: int
    #: standard deviation of the offset from the residuals and the rate changes (s)
    std_s: float = math.nan


class VisualRateTrack:
    """Chains relative visual measurements into frame-to-frame pitch increments.

    The increments of the sliding window are ``ta``, ``tb`` (start and end frame times) and
    ``d`` (pitch change). They are kept in three lists with the index of the oldest one still
    in the window, and the expired front is cut off in blocks. `add` runs per measurement
    and only queues it; the queue is chained, in order, when the track is read (or grows
    long): one loop with its state in local variables instead of a call and its attribute
    reads per measurement, the same increments.
    """

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.reset()

    def reset(self) -> None:
        self._chain: dict[float, float] = {}
        self._last_t = -math.inf
        # frame-to-frame increments: start time, end time, pitch change (from index _head on)
        self._ta: list[float] = []
        self._tb: list[float] = []
        self._d: list[float] = []
        self._head = 0
        self._queue: list[tuple[float, float, float]] = []  # added, not chained yet

    def __len__(self) -> int:
        if self._queue:
            self._chain_queued()
        return len(self._ta) - self._head

    @property
    def ta(self) -> list[float]:
        """Start frame times of the increments in the window (a copy)."""
        if self._queue:
            self._chain_queued()
        return self._ta[self._head :]

    @property
    def tb(self) -> list[float]:
        """End frame times of the increments in the window (a copy)."""
        if self._queue:
            self._chain_queued()
        return self._tb[self._head :]

    @property
    def d(self) -> list[float]:
        """Pitch changes of the increments in the window (a copy)."""
        if self._queue:
            self._chain_queued()
        return self._d[self._head :]

    def arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``ta``, ``tb`` and ``d`` as numpy arrays (`np.fromiter`: a list of floats is
        converted faster than by `np.array`, which first inspects every element)."""
        if self._queue:
            self._chain_queued()
        h = self._head
        n = len(self._ta) - h
        return (
            np.fromiter(self._ta[h:], np.float64, n),
            np.fromiter(self._tb[h:], np.float64, n),
            np.fromiter(self._d[h:], np.float64, n),
        )

    def add(self, t_ref: float, t: float, dphi: float) -> None:
        """A trusted-quality measurement; extends the chain and records an increment (when
        the track is next read)."""
        queue = self._queue
        queue.append((t_ref, t, dphi))
        if len(queue) >= _QUEUE_MAX:
            self._chain_queued()

    def _chain_queued(self) -> None:
        """Chain the queued measurements, in the order they were added."""
        chain, ta, tb, d = self._chain, self._ta, self._tb, self._d
        prev, h, window = self._last_t, self._head, self.window_s
        for t_ref, t, dphi in self._queue:
            phi_ref = chain.get(t_ref)  # (one dict lookup each: the keys are float frame times)
            if phi_ref is not None:
                phi = phi_ref + dphi
            else:  # a key frame the chain does not know: start a new chain there
                chain.clear()
                chain[t_ref] = 0.0
                phi = dphi
            chain[t] = phi
            if (
                prev < t
                and t - prev <= _MAX_INCREMENT_FRAMES_S
                and (phi_prev := chain.get(prev)) is not None
            ):
                ta.append(prev)
                tb.append(t)
                d.append(phi - phi_prev)
            elif t_ref < t and t - t_ref <= _MAX_INCREMENT_FRAMES_S and t_ref != prev:
                ta.append(t_ref)
                tb.append(t)
                d.append(dphi)
            if t > prev:
                prev = t
            # drop the increments that started before the window
            if h < len(ta) and ta[h] < t - window:
                old = t - window
                n = len(ta)
                while h < n and ta[h] < old:
                    h += 1
                if h >= _CUT_BLOCK:  # cut the expired front off the lists now and then
                    del ta[:h], tb[:h], d[:h]
                    h = 0
            if len(chain) > 256:  # keep the recent part of the chain and the key
                _keep_recent(chain, t - 5.0, t_ref)
        self._last_t, self._head = prev, h
        self._queue.clear()


def _keep_recent(chain: dict[float, float], oldest: float, key: float) -> None:
    """Drop the chain's frames before ``oldest``, but the key frame ``key``. (A function of its
    own: a comprehension in the chaining loop would make the loop's ``t`` and ``t_ref`` cell
    variables, slower to read on every pass.)"""
    keep = {k: v for k, v in chain.items() if k >= oldest or k == key}
    chain.clear()
    chain.update(keep)


class TimeOffsetEstimator:
    """Sliding-window cross-correlation of visual and gyro pitch rates."""

    def __init__(self, cfg: AlignmentConfig) -> None:
        self.cfg = cfg
        self.track = VisualRateTrack(cfg.window_s)
        n = round((cfg.max_offset_s - cfg.min_offset_s) / cfg.step_s)
        self.lags: NDArray[np.float64] = cfg.min_offset_s + cfg.step_s * np.arange(n + 1.0)
        self._coarse = self.lags[::4]  # the coarse grid: every 4th lag

    def reset(self) -> None:
        self.track.reset()

    def estimate(self, gyro: GyroHistory) -> OffsetEstimate | None:
        """The offset over the current window, or None when the window cannot tell."""
        cfg = self.cfg
        newest = gyro.newest
        if newest is None or len(self.track) < cfg.min_increments:
            return None
        ta, tb, d = self.track.arrays()
        ok = tb + cfg.max_offset_s <= newest  # the gyro must cover every shifted interval
        n = int(np.count_nonzero(ok))
        if n < cfg.min_increments:
            return None
        if n < ok.size:  # (as a rule the newest few: then views, not copies)
            ta, tb, d = (ta[:n], tb[:n], d[:n]) if ok[:n].all() else (ta[ok], tb[ok], d[ok])
        span = tb - ta
        v = d / span
        # winsorise gross visual errors at 6 MADs (Pearson is not robust); the numpy
        # functions are written out as their elementary steps (the same numbers: np.median's
        # order statistics, np.clip's max-min, np.std's and np.mean's sums), which saves
        # their generic dispatch, a third of the cost at these sizes
        med = _median(v)
        mad = _median(np.abs(v - med)) * 1.4826 + 1e-12
        v = np.minimum(np.maximum(v, med - 6 * mad), med + 6 * mad)
        add = np.add.reduce  # (the ndarray.sum method goes through a Python function)
        vc = v - float(add(v)) / n
        vv = float(add(np.square(vc)))
        if math.sqrt(vv / n) < cfg.min_rate_std_rad_s:  # np.std(v)
            return None
        since = float(ta[0]) + cfg.min_offset_s
        # the gyro integral is read at the end of every increment and at the starts that
        # are not the end of the increment before (consecutive frames share one)
        new_start = np.empty(n, dtype=bool)
        new_start[0] = True
        np.not_equal(ta[1:], tb[:-1], out=new_start[1:])
        extra = new_start.nonzero()[0]
        times = np.concatenate((tb, ta[extra]))
        at_start = np.arange(-1, n - 1)  # where G(ta) is in `times`
        at_start[extra] = np.arange(n, n + extra.size)
        span_col = span[:, None]

        def rates_at(lags: NDArray[np.float64]) -> NDArray[np.float64]:
            """Gyro mean rate over every visual interval shifted by each lag (lags, n)."""
            # the integral is read time by time, all lags of a time together: successive
            # points are then a lag step apart, next to the last one found (np.interp
            # starts its search there), rather than a frame apart
            g = gyro.integral_at((times[:, None] + lags).ravel(), since)
            g = g.reshape(times.size, lags.size)
            rates = (g[:n] - g.take(at_start, axis=0)) / span_col
            return rates.T.copy()  # (lags, n), laid out (C order) as `corr` reduces it

        def corr(rates: NDArray[np.float64]) -> NDArray[np.float64]:
            gc = rates - add(rates, axis=1, keepdims=True) / n  # rates.mean(axis=1)
            r: NDArray[np.float64] = (gc @ vc) / (np.sqrt(add(np.square(gc), axis=1) * vv) + 1e-300)
            return r

        # coarse (4 steps) over the whole range, then every step around the coarse peak
        jc = int(corr(rates_at(self._coarse)).argmax())
        ic = 4 * jc
        lags = self.lags[max(ic - 6, 0) : ic + 7]
        rates = rates_at(lags)
        r = corr(rates)
        j = int(r.argmax())
        if j == 0 or j == r.size - 1:
            return None  # at the edge of the search range (or of an ambiguous coarse peak)
        r0, rm, rp = float(r[j]), float(r[j - 1]), float(r[j + 1])
        curv = rm - 2.0 * r0 + rp
        delta = 0.5 * (rm - rp) / curv if curv < 0 else 0.0
        delta = min(max(delta, -0.5), 0.5)
        # precision: least squares in tau of v = g(tau) + c; Var(tau) = s_res² / sum(g'(tau)²)
        g0 = rates[j] - float(add(rates[j])) / n
        slope = float(g0.dot(vc) / (g0.dot(g0) + 1e-300))
        res = vc - slope * g0
        dg = (rates[j + 1] - rates[j - 1]) / (2.0 * cfg.step_s)
        dg = dg - float(add(dg)) / n
        info = float(dg.dot(dg)) / max(float(add(np.square(res))) / n, 1e-300)
        return OffsetEstimate(
            offset_s=float(lags[j] + delta * cfg.step_s),
            correlation=r0,
            n_increments=n,
            std_s=1.0 / math.sqrt(info) if info > 0 else math.inf,
        )


def _median(v: NDArray[np.float64]) -> float:
    """``np.median(v)`` of a finite vector (the same order statistics and mean of the middle
    two), without its generic machinery."""
    h = v.size // 2
    part = v.copy()  # (what np.partition does before the method)
    if v.size % 2:
        part.partition(h)
        return float(part[h])
    part.partition((h - 1, h))
    return (float(part[h - 1]) + float(part[h])) / 2
