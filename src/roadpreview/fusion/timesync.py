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
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from roadpreview.fusion.config import AlignmentConfig
from roadpreview.fusion.gyro import GyroHistory

_MAX_INCREMENT_FRAMES_S = 0.12  # consecutive frames further apart than this give no rate


@dataclass(frozen=True, slots=True)
class OffsetEstimate:
    """One cross-correlation result: the offset (s), the peak correlation, the samples used."""

    offset_s: float
    correlation: float
    n_increments: int
    #: standard deviation of the offset from the residuals and the rate changes (s)
    std_s: float = math.nan


class VisualRateTrack:
    """Chains relative visual measurements into frame-to-frame pitch increments."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.reset()

    def reset(self) -> None:
        self._chain: dict[float, float] = {}
        self._last_t = -math.inf
        # frame-to-frame increments: start time, end time, pitch change
        self.ta: deque[float] = deque()
        self.tb: deque[float] = deque()
        self.d: deque[float] = deque()

    def __len__(self) -> int:
        return len(self.ta)

    def _record(self, ta: float, tb: float, d: float) -> None:
        self.ta.append(ta)
        self.tb.append(tb)
        self.d.append(d)

    def add(self, t_ref: float, t: float, dphi: float) -> None:
        """A trusted-quality measurement; extends the chain and records an increment."""
        chain = self._chain
        if t_ref in chain:
            chain[t] = chain[t_ref] + dphi
        else:  # a key frame the chain does not know: start a new chain there
            chain.clear()
            chain[t_ref] = 0.0
            chain[t] = dphi
        prev = self._last_t
        if prev < t and prev in chain and t - prev <= _MAX_INCREMENT_FRAMES_S:
            self._record(prev, t, chain[t] - chain[prev])
        elif t_ref < t and t - t_ref <= _MAX_INCREMENT_FRAMES_S and t_ref != prev:
            self._record(t_ref, t, dphi)
        self._last_t = max(self._last_t, t)
        old = t - self.window_s
        while self.ta and self.ta[0] < old:
            self.ta.popleft()
            self.tb.popleft()
            self.d.popleft()
        if len(chain) > 256:  # keep the recent part of the chain and the key
            keep = {k: v for k, v in chain.items() if k >= t - 5.0 or k == t_ref}
            chain.clear()
            chain.update(keep)


class TimeOffsetEstimator:
    """Sliding-window cross-correlation of visual and gyro pitch rates."""

    def __init__(self, cfg: AlignmentConfig) -> None:
        self.cfg = cfg
        self.track = VisualRateTrack(cfg.window_s)
        n = round((cfg.max_offset_s - cfg.min_offset_s) / cfg.step_s)
        self.lags = cfg.min_offset_s + cfg.step_s * np.arange(n + 1)

    def reset(self) -> None:
        self.track.reset()

    def estimate(self, gyro: GyroHistory) -> OffsetEstimate | None:
        """The offset over the current window, or None when the window cannot tell."""
        cfg = self.cfg
        newest = gyro.newest
        if newest is None or len(self.track) < cfg.min_increments:
            return None
        ta = np.array(self.track.ta)
        tb = np.array(self.track.tb)
        d = np.array(self.track.d)
        ok = tb + cfg.max_offset_s <= newest  # the gyro must cover every shifted interval
        if np.count_nonzero(ok) < cfg.min_increments:
            return None
        ta, tb, d = ta[ok], tb[ok], d[ok]
        span = tb - ta
        v = d / span
        # winsorise gross visual errors at 6 MADs (Pearson is not robust)
        med = float(np.median(v))
        mad = float(np.median(np.abs(v - med))) * 1.4826 + 1e-12
        v = np.clip(v, med - 6 * mad, med + 6 * mad)
        if float(np.std(v)) < cfg.min_rate_std_rad_s:
            return None
        vc = v - v.mean()
        vv = float((vc**2).sum())
        since = float(ta[0]) + cfg.min_offset_s

        def rates_at(lags: np.ndarray) -> np.ndarray:
            """Gyro mean rate over every visual interval shifted by each lag (lags, n)."""
            lg = lags[:, None]
            g = gyro.integral_at(np.concatenate([(tb + lg).ravel(), (ta + lg).ravel()]), since)
            n = lags.size * ta.size
            return (g[:n] - g[n:]).reshape(lags.size, ta.size) / span

        def corr(rates: np.ndarray) -> np.ndarray:
            gc = rates - rates.mean(axis=1, keepdims=True)
            return (gc @ vc) / (np.sqrt((gc**2).sum(axis=1) * vv) + 1e-300)

        # coarse (4 steps) over the whole range, then every step around the coarse peak
        coarse = self.lags[::4]
        jc = int(np.argmax(corr(rates_at(coarse))))
        ic = 4 * jc
        lags = self.lags[max(ic - 6, 0) : ic + 7]
        rates = rates_at(lags)
        r = corr(rates)
        j = int(np.argmax(r))
        if j == 0 or j == r.size - 1:
            return None  # at the edge of the search range (or of an ambiguous coarse peak)
        r0, rm, rp = float(r[j]), float(r[j - 1]), float(r[j + 1])
        curv = rm - 2.0 * r0 + rp
        delta = 0.5 * (rm - rp) / curv if curv < 0 else 0.0
        delta = min(max(delta, -0.5), 0.5)
        # precision: least squares in tau of v = g(tau) + c; Var(tau) = s_res² / sum(g'(tau)²)
        g0 = rates[j] - rates[j].mean()
        slope = float(np.dot(g0, vc) / (np.dot(g0, g0) + 1e-300))
        res = vc - slope * g0
        dg = (rates[j + 1] - rates[j - 1]) / (2.0 * cfg.step_s)
        dg = dg - dg.mean()
        info = float(np.dot(dg, dg)) / max(float(np.mean(res**2)), 1e-300)
        return OffsetEstimate(
            offset_s=float(lags[j] + delta * cfg.step_s),
            correlation=r0,
            n_increments=int(ta.size),
            std_s=1.0 / math.sqrt(info) if info > 0 else math.inf,
        )
