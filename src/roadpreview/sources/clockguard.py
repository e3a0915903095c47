"""`ClockGuard`: one source's time stamps kept on the drive's clock, sample by sample.

A source's clock can misbehave in three ways; the guard tells them apart by looking at
the samples that follow (it holds a suspect sample until ``confirm`` samples decide):

* **one sample out of order** (stamped before its predecessor) or **one sample far in the
  future** (a +1 h stamp): the samples after it continue the old time line, so the suspect
  is dropped alone, counted (``out_of_order`` / ``future_stamp``) and logged, at most
  `MAX_WARNINGS` lines per kind (then one line saying that the rest are only counted);
* **a clock step** (the source's clock jumps and stays there): ``confirm`` samples in a
  row continue the suspect's new time line. The step is logged once
  (``event=clock_step source=... step_s=...``), counted (``clock_step``), and from then on
  the step is taken off every stamp (``offset_s``), so the pipeline sees continuous time;
* **a gap** (the source was silent): a forward jump whose samples continue from there.

What a suspect is judged against depends on what the guard knows:

* a file source (no ``clock``): the source's own previous stamp. A stamp going back is
  suspect (a step back is re-aligned to follow the previous sample by the source's usual
  interval); a stamp more than ``max_gap_s`` ahead is suspect, and when the samples after
  it continue from there it is a gap, passed on as it is: in a file nothing tells a
  forward step of the clock from a silence of the same length (docs/fusion.md);
* a live source (``clock``: the loop's clock, read as each sample arrives): a stamp going
  back, or ahead of its arrival by more than ``tolerance_s`` beyond the usual stamp minus
  arrival, is suspect; a lasting one is a step, re-aligned to the usual value. A silence
  moves stamps and arrival alike, and a backlog only delays the arrival: neither is.

A CAN source (one with a ``stamp_filter`` attribute) is guarded frame by frame, before its
decoder, whose per-ID time order would otherwise reject every frame after a stray stamp.

The camera is the drive's time base: replay and the daemon guard the other sources; a
camera frame stamped before its predecessor is skipped by the run loop (docs/fusion.md).

``problems`` (reason -> count) are the guard's counts plus the wrapped source's own
``problems`` (if it has any); ``errors`` adds the samples the guard dropped to the
source's.
"""

from __future__ import annotations

import copy
import logging
import math
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace
from typing import Any, TypeVar

from roadpreview.sources import Source
from roadpreview.types import Sample

log = logging.getLogger(__name__)

T = TypeVar("T")

#: warning lines per kind of dropped sample; the rest are counted
MAX_WARNINGS = 5


class ClockGuard:
    """``source`` with its clock checked and re-aligned (module docstring)."""

    def __init__(
        self,
        source: Source,
        *,
        clock: Callable[[], float] | None = None,
        confirm: int = 4,
        max_gap_s: float = 1.0,
        tolerance_s: float = 0.3,
    ) -> None:
        """``clock``: the loop's clock for a live source (None: judged by its own stamps);
        ``confirm``: samples in a row on a new time line that make it a step (or a gap);
        ``max_gap_s``: a file source's forward jump beyond this is suspect;
        ``tolerance_s``: a live source's stamp minus arrival may wander this much."""
        if confirm < 1 or not (max_gap_s > 0.0 and tolerance_s > 0.0):
            raise ValueError("ClockGuard: confirm >= 1, max_gap_s > 0, tolerance_s > 0")
        self.source = source
        self.name = source.name
        self.live = source.live
        self.clock = clock
        self.confirm = confirm
        self.max_gap_s = max_gap_s
        self.tolerance_s = tolerance_s
        self.offset_s = 0.0  #: taken off the stamps now (the sum of the steps found), s
        self.steps: list[tuple[float, float]] = []  #: (stamp on the drive's clock, step s)
        self.dropped = 0  #: samples dropped alone
        self.counts: Counter[str] = Counter()  #: the guard's own problem counts
        self._last = -math.inf  # the newest stamp passed on (re-aligned)
        self._interval = math.nan  # the source's usual interval between stamps, s
        self._lag = math.nan  # live: the usual stamp minus arrival, s
        # a CAN source guarded frame by frame (its decoder keeps per-ID time order)
        self._frame_level = hasattr(source, "stamp_filter")
        if self._frame_level:
            source.stamp_filter = self._frames  # type: ignore[attr-defined]

    # -- the Source protocol --------------------------------------------------------------
    @property
    def errors(self) -> int:
        return self.source.errors + self.dropped

    @property
    def problems(self) -> Counter[str]:
        """Reason -> count: the guard's and the wrapped source's (``problems``)."""
        merged = Counter(getattr(self.source, "problems", None) or {})
        merged.update(self.counts)
        return merged

    def close(self) -> None:
        self.source.close()

    def seek(self, t_s: float) -> None:
        """Ask the wrapped source to jump to ``t_s`` (if it can; `WindowedSource`)."""
        seek = getattr(self.source, "seek", None)
        if callable(seek):
            seek(t_s)

    def __iter__(self) -> Iterator[Sample]:
        if self._frame_level:  # the source's frames are guarded before they are decoded
            return iter(self.source)
        return self.guard(self.source, _stamp, _restamp)

    def guard(
        self,
        items: Iterable[T],
        stamp: Callable[[T], float],
        restamp: Callable[[T, float], T],
    ) -> Iterator[T]:
        """``items`` (samples, or a CAN source's frames) with their stamps checked: lone
        suspects dropped, steps taken off (``restamp(item, t)``); module docstring."""
        held: list[tuple[T, float, float]] = []  # suspects and the items after them
        clock = self.clock
        for item in items:
            t = stamp(item)
            arrival = clock() if clock is not None else math.nan
            if not held:
                if self._fits(t, arrival):
                    yield self._pass(item, t, arrival, restamp)
                else:
                    held.append((item, t, arrival))
                continue
            if self._fits(t, arrival):  # the old time line goes on: the suspects were alone
                for _, th, _ in held:
                    self._drop(th)
                held.clear()
                yield self._pass(item, t, arrival, restamp)
                continue
            prev = held[-1][1]
            if prev <= t <= prev + self.max_gap_s:  # the suspect's time line goes on
                held.append((item, t, arrival))
                if len(held) > self.confirm:
                    self._new_line(held[0][1], held[0][2])
                    for h, th, a in held:
                        yield self._pass(h, th, a, restamp)
                    held.clear()
            else:  # neither: the suspects were alone, this one is a new suspect
                for _, th, _ in held:
                    self._drop(th)
                held[:] = [(item, t, arrival)]
        for _, th, _ in held:  # the input ended while they were suspect
            self._drop(th)

    def _frames(self, frames: Iterable[Any]) -> Iterator[Any]:
        """A CAN source's frames (``can.Message``) guarded before they are decoded."""
        return self.guard(frames, _frame_stamp, _frame_restamp)

    # -- the judgement --------------------------------------------------------------------
    def _fits(self, t: float, arrival: float) -> bool:
        """Does raw stamp ``t`` continue the time line the guard follows?"""
        c = t - self.offset_s
        if not math.isfinite(c):
            return False
        last = self._last
        if c < last:  # (before the first sample last is -inf)
            return False
        if self.clock is not None and math.isfinite(arrival):
            # ahead of the arrival beyond the tolerance; late arrival (a backlog) is no step
            lag = self._lag
            return math.isnan(lag) or c - arrival - lag <= self.tolerance_s
        return c - last <= self.max_gap_s

    def _pass(self, item: T, t: float, arrival: float, restamp: Callable[[T, float], T]) -> T:
        """The item re-aligned; the guard's state follows it."""
        c = t - self.offset_s
        last = self._last
        if math.isfinite(last) and c > last:
            dt = c - last
            interval = self._interval
            if math.isnan(interval):
                self._interval = dt
            elif dt < 10.0 * interval:  # (not a gap) the usual interval, smoothed
                self._interval = interval + 0.05 * (dt - interval)
        self._last = max(last, c)
        if self.clock is not None and math.isfinite(arrival):
            lag = c - arrival
            # the usual lag: its smallest recent value (queueing only delays the arrival)
            self._lag = lag if math.isnan(self._lag) else min(lag, self._lag + 0.01)
        return item if self.offset_s == 0.0 else restamp(item, c)

    def _new_line(self, t: float, arrival: float) -> None:
        """The held items continue a new time line from raw stamp ``t``: a step (re-aligned)
        or, for a file source's forward jump, a gap (passed on as it is)."""
        c = t - self.offset_s
        if self.clock is not None and math.isfinite(arrival) and not math.isnan(self._lag):
            step = c - arrival - self._lag  # the stamp moved against the arrival
        elif c < self._last:  # a file source's clock went back
            interval = self._interval if math.isfinite(self._interval) else 0.0
            step = c - (self._last + interval)
        else:  # a forward jump in a file: a gap (or a step nothing can tell from one)
            log.info(
                "%s: no sample for %.3f s before %.6f (a gap; a clock step forward would look"
                " the same)",
                self.name,
                c - self._last,
                c,
            )
            return
        self.offset_s += step
        self.steps.append((c - step, step))
        self.counts["clock_step"] += 1
        log.warning(
            "event=clock_step source=%s step_s=%.6f t=%.6f re-aligned: offset_s=%.6f",
            self.name,
            step,
            c - step,
            self.offset_s,
        )

    def _drop(self, t: float) -> None:
        c = t - self.offset_s
        kind = "out_of_order" if c < self._last else "future_stamp"
        n = self.counts[kind] = self.counts[kind] + 1
        self.dropped += 1
        if n <= MAX_WARNINGS:
            log.warning(
                "%s: %s sample stamped %.6f (the source's clock is at %.6f): dropped alone%s",
                self.name,
                kind.replace("_", "-"),
                t,
                self._last,
                "; further ones are counted, not logged" if n == MAX_WARNINGS else "",
            )


def _stamp(sample: Sample) -> float:
    return sample.t_s


def _restamp(sample: Sample, t: float) -> Sample:
    return replace(sample, t_s=t)


def _frame_stamp(msg: Any) -> float:
    return float(msg.timestamp)


def _frame_restamp(msg: Any, t: float) -> Any:
    out = copy.copy(msg)
    out.timestamp = t
    return out


__all__ = ["MAX_WARNINGS", "ClockGuard"]
