"""Running moments over a sliding time window, stable over hours, O(1) per sample.

`WindowedMoments` keeps the count, mean and sum of squared deviations (M2)
of k channels over the samples of the last ``window_s`` seconds. Each push
applies Welford's update for the entering sample and its inverse for every
sample leaving the window. Rounding errors of these updates would random-walk
over a long drive, so every ``recompute_every`` pushes (and whenever M2 turns
negative) the moments are recomputed exactly from the samples in the window
with a two-pass sum: O(window) once every ``recompute_every`` pushes, O(1)
amortised. A NaN value of a channel means "no sample": that channel's
moments skip it, the others use it. The samples live in numpy ring buffers
(window inspection and recomputation are vectorised); the running state is
three floats per channel.

With ``trend=True`` each channel also keeps the mean and M2 of the sample
times and the co-moment of time and value (the same updates, three more
floats), so that `detrended_std_values` gives the spread around the
least-squares line through the window, still O(1) per sample. Times enter
relative to the first sample's time, so that hours of Unix time stamps do
not eat the precision.

Window membership is by time: at time t the window holds the samples with
``t - t_i < window_s - time_tol_s``. At a steady rate r that is the last
``round(window_s * r)`` samples (30 at 30 fps for 1 s); ``time_tol_s``
(1 µs) keeps the sample exactly ``window_s`` old out despite rounding of the
time stamps. Dropped frames simply leave fewer samples in the window.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from roadpreview.errors import ConfigError

FloatArray = NDArray[np.float64]

#: time stamps this close to the window edge count as outside, s
TIME_TOL_S = 1e-6


class WindowedMoments:
    """Count, mean and M2 of ``channels`` values over the last ``window_s`` seconds.

    Every sample may carry ``aux_columns`` extra values (kept, not
    accumulated) so that the window's rows can be inspected with `window`.
    Times must increase (the caller checks).
    """

    def __init__(
        self,
        window_s: float,
        channels: int,
        *,
        aux_columns: int = 0,
        recompute_every: int = 1000,
        time_tol_s: float = TIME_TOL_S,
        capacity: int = 64,
        trend: bool = False,
    ) -> None:
        if not window_s > 0 or channels < 1 or recompute_every < 1 or capacity < 1:
            raise ConfigError(
                f"WindowedMoments(window_s={window_s}, channels={channels},"
                f" recompute_every={recompute_every}): need window > 0 s, >= 1 channel, >= 1"
            )
        self.window_s = float(window_s)
        self.channels = channels
        self.recompute_every = recompute_every
        self.time_tol_s = time_tol_s
        self._t = np.empty(capacity)
        self._x = np.empty((capacity, channels))
        self._aux = np.empty((capacity, aux_columns))
        self._head = 0  # index of the oldest row
        self._size = 0  # rows in the window
        # the running state, per channel: count, mean, M2 (plain floats: for a handful of
        # channels, scalar arithmetic beats numpy's per-call overhead by an order of magnitude)
        self._n = [0] * channels
        self._mean = [0.0] * channels
        self._m2 = [0.0] * channels
        # with trend: per channel the mean and M2 of the times and the time-value co-moment
        self.trend = trend
        self._t0 = math.nan  # time origin of the trend sums
        self._mt = [0.0] * channels
        self._m2t = [0.0] * channels
        self._c = [0.0] * channels
        self._since_recompute = 0
        self.recomputations = 0  #: how often the moments were recomputed exactly

    @property
    def n(self) -> NDArray[np.int64]:
        """Valid samples per channel in the window."""
        return np.array(self._n, dtype=np.int64)

    @property
    def mean(self) -> FloatArray:
        """Mean per channel (0 where there is no sample)."""
        return np.array(self._mean)

    @property
    def m2(self) -> FloatArray:
        """Sum of squared deviations from the mean per channel."""
        return np.array(self._m2)

    # --- ring buffer ------------------------------------------------------------------------

    @property
    def size(self) -> int:
        """Number of samples (valid or not) in the window."""
        return self._size

    @property
    def oldest_t(self) -> float:
        """Time of the oldest sample in the window (NaN when empty)."""
        return float(self._t[self._head]) if self._size else float("nan")

    def _grow(self) -> None:
        order = self._order()
        cap = 2 * len(self._t)
        for name in ("_t", "_x", "_aux"):
            old = getattr(self, name)
            new = np.empty((cap, *old.shape[1:]))
            new[: self._size] = old[order]
            setattr(self, name, new)
        self._head = 0

    def _order(self) -> NDArray[np.intp]:
        return (self._head + np.arange(self._size)) % len(self._t)

    def window(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Copies of the window's rows, oldest first: times (n,), values (n, k), aux (n, m)."""
        order = self._order()
        return self._t[order], self._x[order], self._aux[order]

    # --- updates ----------------------------------------------------------------------------

    def _remove_oldest(self) -> None:
        x = self._x[self._head].tolist()
        tau = float(self._t[self._head]) - self._t0
        self._head = (self._head + 1) % len(self._t)
        self._size -= 1
        n, mean, m2 = self._n, self._mean, self._m2
        trend = self.trend
        mt, m2t, cc = self._mt, self._m2t, self._c
        for c, v in enumerate(x):
            if v != v:  # NaN: this channel had no sample here
                continue
            n1 = n[c] - 1
            if n1 == 0:
                n[c], mean[c], m2[c] = 0, 0.0, 0.0
                mt[c], m2t[c], cc[c] = 0.0, 0.0, 0.0
                continue
            m0 = mean[c]
            m1 = m0 - (v - m0) / n1
            m2[c] -= (v - m0) * (v - m1)
            mean[c] = m1
            n[c] = n1
            if trend:  # the inverse of the co-moment update in _add
                t0 = mt[c]
                t1 = t0 - (tau - t0) / n1
                m2t[c] -= (tau - t0) * (tau - t1)
                cc[c] -= (tau - t1) * (v - m0)
                mt[c] = t1

    def _add(self, x: list[float], t: float) -> None:
        n, mean, m2 = self._n, self._mean, self._m2
        trend = self.trend
        mt, m2t, cc = self._mt, self._m2t, self._c
        tau = t - self._t0
        for c, v in enumerate(x):
            if v != v:
                continue
            n1 = n[c] + 1
            m0 = mean[c]
            m1 = m0 + (v - m0) / n1
            m2[c] += (v - m0) * (v - m1)
            mean[c] = m1
            n[c] = n1
            if trend:  # Welford's co-moment: C += (t - mean_t_old) (v - mean_new)
                d = tau - mt[c]
                t1 = mt[c] + d / n1
                m2t[c] += d * (tau - t1)
                cc[c] += d * (v - m1)
                mt[c] = t1

    def recompute(self) -> None:
        """Recompute count, mean and M2 exactly (two-pass) from the window's samples."""
        t, x, _ = self.window()
        valid = ~np.isnan(x)
        n = valid.sum(axis=0)
        mean = np.where(valid, x, 0.0).sum(axis=0) / np.maximum(n, 1)
        dev = np.where(valid, x - mean, 0.0)
        self._n = [int(v) for v in n]
        self._mean = np.where(n > 0, mean, 0.0).tolist()
        self._m2 = (dev * dev).sum(axis=0).tolist()
        if self.trend:
            if self._size:  # a fresh time origin
                self._t0 = float(t[0])
            tau = np.where(valid, (t - self._t0)[:, None], 0.0)
            mt = tau.sum(axis=0) / np.maximum(n, 1)
            tdev = np.where(valid, tau - mt, 0.0)
            self._mt = np.where(n > 0, mt, 0.0).tolist()
            self._m2t = (tdev * tdev).sum(axis=0).tolist()
            self._c = (tdev * dev).sum(axis=0).tolist()
        self._since_recompute = 0
        self.recomputations += 1

    def push(
        self,
        t: float,
        x: FloatArray | Sequence[float],
        aux: FloatArray | Sequence[float] | None = None,
    ) -> None:
        """Add the sample at time ``t`` (values ``x``, NaN = none) and drop the ones too old."""
        limit = t - self.window_s + self.time_tol_s
        while self._size and self._t[self._head] <= limit:
            self._remove_oldest()
        if self._size == len(self._t):
            self._grow()
        i = (self._head + self._size) % len(self._t)
        self._t[i] = t
        self._x[i] = x
        if aux is not None:
            self._aux[i] = aux
        self._size += 1
        if self._t0 != self._t0:  # NaN: the first sample sets the time origin
            self._t0 = t
        self._add(self._x[i].tolist(), t)
        self._since_recompute += 1
        if self._since_recompute >= self.recompute_every or min(self._m2) < 0.0:
            self.recompute()

    # --- results ----------------------------------------------------------------------------

    def variance(self) -> FloatArray:
        """Population variance (ddof = 0) per channel; NaN where no sample."""
        return np.array(
            [max(m2, 0.0) / n if n else math.nan for n, m2 in zip(self._n, self._m2, strict=True)]
        )

    def std_values(self) -> list[float]:
        """`std` as a list of floats (cheaper per frame)."""
        return [
            math.sqrt(max(m2, 0.0) / n) if n else math.nan
            for n, m2 in zip(self._n, self._m2, strict=True)
        ]

    def detrended_std_values(self) -> list[float]:
        """Population std (ddof = 0) of each channel's residuals from its least-squares line
        in time over the window; NaN where no sample. Needs ``trend=True``."""
        if not self.trend:
            raise ConfigError("WindowedMoments: detrended_std_values needs trend=True")
        out = []
        for n, m2, m2t, c in zip(self._n, self._m2, self._m2t, self._c, strict=True):
            if not n:
                out.append(math.nan)
                continue
            explained = c * c / m2t if m2t > 0.0 else 0.0
            out.append(math.sqrt(max(m2 - explained, 0.0) / n))
        return out

    def counts(self) -> list[int]:
        """Valid samples per channel, as a list."""
        return list(self._n)

    def std(self) -> FloatArray:
        """Population standard deviation (ddof = 0, as ``numpy.std``) per channel; NaN if empty."""
        return np.array(self.std_values())
