"""Streaming non-maximum suppression over time: one event per bump.

A value at time t_p is a peak when it is strictly larger than every value
less than ``window_s`` before it and at least as large as every value less
than ``window_s`` after it. The peak is therefore known ``window_s`` after
it happened: `PeakPicker.push` returns it at the first sample at least
``window_s`` later. Ineligible samples (below threshold, undefined) are
pushed as ``-inf`` so that time advances. The maximum over the past window
is kept in a monotonic deque: O(1) amortised per sample.

The peak's description is computed by a callback when the sample becomes
the candidate (the data around it are at hand then, not when it is
confirmed); a rising slope makes each new sample the candidate in turn,
which only happens while the signal is above threshold.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Generic, TypeVar

from roadpreview.anomaly.running import TIME_TOL_S

P = TypeVar("P")


class PeakPicker(Generic[P]):
    """Confirm peaks of a streamed signal that dominate ± ``window_s``."""

    def __init__(self, window_s: float, *, time_tol_s: float = TIME_TOL_S) -> None:
        self.window_s = float(window_s)
        self.time_tol_s = time_tol_s
        self._past: deque[tuple[float, float]] = deque()  # (t, value), values decreasing
        self._cand: tuple[float, float, P] | None = None

    @property
    def pending(self) -> bool:
        """True while a candidate waits for confirmation."""
        return self._cand is not None

    def push(self, t: float, value: float, describe: Callable[[], P]) -> list[P]:
        """Next sample (``describe()`` runs if it becomes the candidate); the confirmed peaks."""
        out: list[P] = []
        horizon = self.window_s - self.time_tol_s
        if self._cand is not None and t - self._cand[0] >= horizon:
            out.append(self._cand[2])
            self._cand = None
        while self._past and self._past[0][0] <= t - horizon:
            self._past.popleft()
        if math.isfinite(value):
            past_max = self._past[0][1] if self._past else -math.inf
            if value > past_max:
                self._cand = (t, value, describe())
            while self._past and self._past[-1][1] <= value:
                self._past.pop()
            self._past.append((t, value))
        return out

    def flush(self) -> list[P]:
        """End of stream: the pending candidate (not followed by a full window), if any."""
        if self._cand is None:
            return []
        payload = self._cand[2]
        self._cand = None
        return [payload]


class OnsetPicker(Generic[P]):
    """One event per excursion, reported when it starts: for alerts that must arrive early.

    An eligible (finite) value starts an event when no eligible value came in the
    ``window_s`` before it; the event is returned at once. Later eligible values
    within ``window_s`` of the previous one belong to the same excursion. One
    bump keeps s above threshold for about one detector window, so this gives
    one event per bump, ``window_s`` plus the rise time earlier than
    `PeakPicker`, at the price of describing the excursion at its onset (a
    smaller s than its peak). Same interface as `PeakPicker`.
    """

    def __init__(self, window_s: float, *, time_tol_s: float = TIME_TOL_S) -> None:
        self.window_s = float(window_s)
        self.time_tol_s = time_tol_s
        self._last_t = -math.inf  # time of the last eligible value

    @property
    def pending(self) -> bool:
        """Never: events are returned when they start."""
        return False

    def push(self, t: float, value: float, describe: Callable[[], P]) -> list[P]:
        """Next sample (``describe()`` runs when it starts an event); the new events."""
        if not math.isfinite(value):
            return []
        starts = t - self._last_t >= self.window_s - self.time_tol_s
        self._last_t = t
        return [describe()] if starts else []

    def flush(self) -> list[P]:
        """Nothing is held back."""
        return []
