"""Supervised threads: a thread whose work raised is logged, counted and started again
after a backoff, and given up on after too many deaths in a row.

`Supervision` is the policy; the run loop applies it to its sources (`roadpreview.loop`:
a source's iterator that raises is read again) and `SupervisedThread` to a thread of
its own (the cyclic status sender, `roadpreview.canbus.cyclic`). Each death is logged
``event=thread_died`` with the error (the loop's name the source, ``source=``; this
module's the thread, ``thread=``), each restart ``event=thread_restarted`` here, and
giving up ``event=thread_gave_up``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

from roadpreview.clock import Clock
from roadpreview.errors import OperationError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Supervision:
    """How a thread (or a source) whose work raised is restarted (module docstring)."""

    #: deaths in a row after which the run ends with an error (the daemon exits non-zero)
    max_restarts: int = 5
    backoff_s: float = 0.1  #: the first restart waits this long, s
    max_backoff_s: float = 2.0  #: ... and every further one twice as long, up to this, s
    #: a thread (a live source) that ran this long since its last restart starts the
    #: count again, s
    healthy_s: float = 10.0

    def __post_init__(self) -> None:
        if self.max_restarts < 0:
            raise ValueError(f"max_restarts {self.max_restarts}: must be >= 0")
        if not (0 <= self.backoff_s <= self.max_backoff_s):
            raise ValueError(
                f"backoff_s {self.backoff_s} s must be in [0, max_backoff_s = "
                f"{self.max_backoff_s} s]"
            )

    def backoff(self, in_row: int) -> float:
        """The wait before the restart after the ``in_row``-th death in a row, s."""
        return float(min(self.backoff_s * 2.0 ** max(in_row - 1, 0), self.max_backoff_s))


class ThreadFailed(OperationError):
    """A supervised thread kept dying (`Supervision.max_restarts`)."""


class SupervisedThread:
    """``target(stop)`` in a thread of its own, run again when it raises (module
    docstring), until `stop`. ``target`` returns when ``stop`` is set. Waits (the
    backoff) and the healthy time are on ``clock``. After ``max_restarts`` deaths in a
    row the thread ends, ``failed`` says why and ``on_failed(failed)`` is called (from
    the thread)."""

    def __init__(
        self,
        name: str,
        target: Callable[[threading.Event], None],
        *,
        clock: Clock,
        policy: Supervision | None = None,
        on_failed: Callable[[str], None] | None = None,
    ) -> None:
        self.name = name
        self.target = target
        self.clock = clock
        self.policy = policy or Supervision()
        self.on_failed = on_failed
        self.deaths = 0  #: exceptions out of ``target``
        self.restarts = 0  #: times ``target`` was run again
        self.failed = ""  #: why the thread gave up ('' while it has not)
        self.stop_event = clock.event()
        self._thread: threading.Thread | None = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Start the thread (once)."""
        if self._thread is not None:
            raise OperationError(f"{self.name}: started already")
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> bool:
        """Stop and join the thread; False (logged) if it is still running after
        ``timeout_s`` of real time."""
        self.stop_event.set()
        if self._thread is None:
            return True
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.error("event=thread_hangs thread=%s", self.name)
            return False
        return True

    def _run(self) -> None:
        policy, stop = self.policy, self.stop_event
        in_row = 0  # deaths since the target last ran healthy_s
        while not stop.is_set():
            started = self.clock.now()
            try:
                self.target(stop)
                return
            except Exception as exc:
                self.deaths += 1
                error = f"{type(exc).__name__}: {exc}".splitlines()[0]
                in_row = 1 if self.clock.now() - started >= policy.healthy_s else in_row + 1
                log.error(
                    "event=thread_died thread=%s error=%r deaths=%d in_row=%d",
                    self.name,
                    error,
                    self.deaths,
                    in_row,
                )
                log.debug("thread %s: the exception", self.name, exc_info=True)
                if in_row > policy.max_restarts:
                    self.failed = (
                        f"{self.name}: the thread died {in_row} times in a row "
                        f"(last: {error}); giving up"
                    )
                    log.error("event=thread_gave_up thread=%s error=%r", self.name, error)
                    if self.on_failed is not None:
                        self.on_failed(self.failed)
                    return
            if self.clock.wait(stop, policy.backoff(in_row)):
                return
            self.restarts += 1
            log.warning("event=thread_restarted thread=%s restarts=%d", self.name, self.restarts)


__all__ = ["SupervisedThread", "Supervision", "ThreadFailed"]
