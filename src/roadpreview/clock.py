"""The clocks the real-time parts run on, and the one rule for periodic messages.

A `Clock` says what time it is (``now``) and waits (``wait``: until an event is set or a
timeout of its own time passed). The daemon's threads take one: the paced sources and the
merge of the run loop (`roadpreview.loop`), the CAN log player, the cyclic status sender
(`roadpreview.canbus.cyclic`), the systemd watchdog pings. In the product that is
`SystemClock` (Unix time, the time stamps of frames and CAN; its waits are measured on
the monotonic clock, so a step of the system time never stretches one); in tests it is
`VirtualClock`, whose time moves only when the test moves it, so a test of timing runs
on virtual time instead of sleeping and gives the same answer on an idle and on a loaded
machine.

`Cycle` is when a periodic message is due: the run loop's status schedule on the frames'
clock (replay) and the cyclic sender's on a clock (live) share it.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

#: how often a `VirtualClock` waiter looks at an event that is not the clock's own (an
#: event made by `Clock.event` tells the clock when it is set), real seconds
PLAIN_EVENT_POLL_S = 0.002


class Clock(Protocol):
    """What time it is and how to wait for it."""

    def now(self) -> float:
        """The time now, s."""
        ...

    def wait(self, event: threading.Event, timeout_s: float | None) -> bool:
        """Block until ``event`` is set (True) or ``timeout_s`` of this clock passed
        (False; None: no timeout)."""
        ...

    def event(self) -> threading.Event:
        """A new event to `wait` for (a `VirtualClock` learns at once when it is set)."""
        ...


def sleep_until(clock: Clock, t: float, stop: threading.Event) -> bool:
    """Wait until ``clock`` reads ``t`` or ``stop`` is set; True if stopped."""
    if stop.is_set():
        return True
    wait = t - clock.now()
    return wait > 0 and clock.wait(stop, wait)


class SystemClock:
    """The system's clock: ``now`` is ``time.time`` (Unix seconds: the daemon's frames and
    CAN frames are stamped on it) unless another function is given (``time.monotonic``
    for timeouts). Waits are `threading.Event.wait`, measured on the monotonic clock."""

    def __init__(self, now: Callable[[], float] = time.time) -> None:
        self._now = now

    def now(self) -> float:
        return self._now()

    def wait(self, event: threading.Event, timeout_s: float | None) -> bool:
        return event.wait(None if timeout_s is None else max(timeout_s, 0.0))

    def event(self) -> threading.Event:
        return threading.Event()


@dataclass
class _Waiter:
    deadline: float
    event: threading.Event


class _ClockEvent(threading.Event):
    """An event that wakes the `VirtualClock`'s waiters when it is set."""

    def __init__(self, clock: VirtualClock) -> None:
        super().__init__()
        self._clock = clock

    def set(self) -> None:
        if not self.is_set():
            super().set()
            self._clock._kick()


class VirtualClock:
    """Time that moves only when told: `advance` / `advance_to` (tests, benchmarks).

    The threads that `wait` on it wake in deadline order as time passes. After every step
    the clock *settles*: it waits (in real time, at most ``settle_timeout_s``) until each
    thread it woke, and each whose event was set, waits again or has ended, so what they
    did at that time is done before time moves on. A thread busy elsewhere (the run loop
    inside a frame) holds the clock until it waits again; a test that wants time to pass
    while a thread is blocked makes that thread block on the clock (``wait`` for an event
    with no timeout), which counts as waiting. A thread that does not settle in time is a
    `TimeoutError` naming it, not a hang. Events from `event` wake waiters at once;
    others are looked at every `PLAIN_EVENT_POLL_S` of real time.
    """

    def __init__(self, start: float = 0.0, *, settle_timeout_s: float = 60.0) -> None:
        self._now = float(start)
        self.settle_timeout_s = settle_timeout_s
        self._cond = threading.Condition()
        self._waiting: dict[threading.Thread, _Waiter] = {}
        self._woken: set[threading.Thread] = set()  # left a wait, not waiting again yet

    def now(self) -> float:
        with self._cond:
            return self._now

    def event(self) -> threading.Event:
        return _ClockEvent(self)

    def _kick(self) -> None:
        with self._cond:
            self._cond.notify_all()

    def wait(self, event: threading.Event, timeout_s: float | None) -> bool:
        me = threading.current_thread()
        own = isinstance(event, _ClockEvent) and event._clock is self
        with self._cond:
            deadline = math.inf if timeout_s is None else self._now + max(timeout_s, 0.0)
            self._woken.discard(me)
            self._waiting[me] = _Waiter(deadline, event)
            self._cond.notify_all()  # a settling `advance` sees this thread waiting again
            try:
                while not event.is_set() and self._now < deadline:
                    self._cond.wait(None if own else PLAIN_EVENT_POLL_S)
            finally:
                del self._waiting[me]
                self._woken.add(me)
                self._cond.notify_all()
            return event.is_set()

    def leave(self) -> None:
        """The calling thread is done with the clock: settling no longer waits for it (a
        test's thread that ran the loop and goes on to check the results)."""
        with self._cond:
            self._woken.discard(threading.current_thread())
            self._cond.notify_all()

    @property
    def waiting(self) -> int:
        """Threads waiting on the clock now."""
        with self._cond:
            return len(self._waiting)

    def next_deadline(self) -> float:
        """The earliest time a waiting thread waits for (inf: none)."""
        with self._cond:
            return min((w.deadline for w in self._waiting.values()), default=math.inf)

    def advance(self, dt: float) -> float:
        """Move time on by ``dt`` s (`advance_to`); the time now."""
        with self._cond:
            target = self._now + dt
        return self.advance_to(target)

    def advance_to(self, t: float) -> float:
        """Move time on to ``t``, waking the waiters in deadline order and settling after
        each step (class docstring); the time now."""
        with self._cond:
            while True:
                self._settle()
                due = [w.deadline for w in self._waiting.values() if w.deadline <= t]
                self._now = max(self._now, min(due, default=t))
                self._cond.notify_all()
                if not due:
                    self._settle()
                    return self._now

    def settle(self) -> None:
        """Wait until no thread that uses the clock has anything left to do now."""
        with self._cond:
            self._settle()

    def _busy(self) -> list[threading.Thread]:
        self._woken = {th for th in self._woken if th.is_alive()}
        ready = [
            th
            for th, w in self._waiting.items()
            if w.event.is_set() or w.deadline <= self._now
        ]
        return ready + [th for th in self._woken if th not in self._waiting]

    def _settle(self) -> None:
        end = time.monotonic() + self.settle_timeout_s
        while busy := self._busy():
            left = end - time.monotonic()
            if left <= 0:
                names = ", ".join(sorted(th.name for th in busy))
                raise TimeoutError(
                    f"VirtualClock at {self._now:.6f}: thread(s) {names} did not wait again "
                    f"within {self.settle_timeout_s:g} s (real)"
                )
            self._cond.wait(min(left, PLAIN_EVENT_POLL_S))


@dataclass
class Cycle:
    """When a periodic message is due: at the first chance, then every ``period_s``.

    ``due(t)`` says whether it is due at ``t``; ``sent(t)`` notes that it went out at
    ``t``. The next one is due a period after that send (the run loop's status on the
    frames' clock: a frame late by a frame interval moves the cycle with it), or, with
    ``fixed_rate``, a period after the one scheduled, as python-can's cyclic tasks keep
    their rate: a send late by less than a period does not move the cycle, one later
    than that skips the periods missed (no burst of stale frames) and starts it again.
    """

    period_s: float
    fixed_rate: bool = False
    next_s: float = -math.inf  #: when the next send is due

    def __post_init__(self) -> None:
        if not (self.period_s > 0 and math.isfinite(self.period_s)):
            raise ValueError(f"period {self.period_s} s: must be positive")

    def due(self, t: float) -> bool:
        return t >= self.next_s

    def sent(self, t: float) -> None:
        if self.fixed_rate and t < self.next_s + self.period_s:
            self.next_s += self.period_s
        else:
            self.next_s = t + self.period_s


__all__ = ["Clock", "Cycle", "SystemClock", "VirtualClock", "sleep_until"]
