"""Cyclic CAN frames sent from a supervised thread of their own, on a `Clock`.

python-can's cyclic tasks (``bus.send_periodic``, ``can.broadcastmanager``) send fixed
messages from a thread on ``time.perf_counter``: ``modify_data`` swaps the payload, a
``modifier_callback`` edits it before each send. roadpreview's periodic outputs need more
than a payload swap: every transmission carries its own E2E alive counter and CRC, the
content is the run loop's newest state, ``RP_INPUT_STATUS`` goes out only while the
inputs have problems (IfActive), and tests run on virtual time. So `CyclicSender` keeps
python-can's schedule, a fixed rate (the next send is due one period after the one
scheduled, not after the one done; `roadpreview.clock.Cycle`), and asks a ``build``
callback for the frames of each cycle at the moment they go out (an iterable: each frame
is sent as soon as it is built). Each frame is stamped with ``stamp()`` just before it is
handed to ``send``.

Supervised (`roadpreview.supervision.SupervisedThread`): a send that fails is logged and
counted by ``send`` (it returns False) and the cycle goes on; an exception out of a cycle
(``build`` failing) kills the thread, which is logged, counted and started again after a
backoff, the schedule carrying on where it was; after too many deaths in a row the sender
gives up and says so (``on_failed``).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Iterable

import can

from roadpreview.clock import Clock, Cycle, sleep_until
from roadpreview.supervision import SupervisedThread, Supervision

log = logging.getLogger(__name__)


class CyclicSender:
    """``build()``'s frames every ``period_s`` of ``clock``, each handed to ``send``
    (module docstring). ``send`` returns False for a frame that could not go out (it
    counts and logs it); an exception from it is counted here and logged once per run of
    failures."""

    def __init__(
        self,
        name: str,
        build: Callable[[], Iterable[can.Message]],
        send: Callable[[can.Message], bool],
        *,
        clock: Clock,
        period_s: float,
        stamp: Callable[[], float] | None = None,
        supervision: Supervision | None = None,
        on_failed: Callable[[str], None] | None = None,
    ) -> None:
        self.name = name
        self.build = build
        self.send = send
        self.clock = clock
        self.stamp = stamp or clock.now
        self.cycle = Cycle(period_s, fixed_rate=True)
        self.cycles = 0  #: cycles sent
        self.frames = 0  #: frames ``send`` took
        self.send_errors = 0  #: frames ``send`` refused or raised on
        self.skipped = 0  #: periods skipped because a cycle came more than a period late
        self._raising = False  # ``send`` raised on the previous frame (logged once)
        self.thread = SupervisedThread(
            name, self._run, clock=clock, policy=supervision, on_failed=on_failed
        )

    @property
    def deaths(self) -> int:
        """Exceptions out of a cycle (each restarted the thread)."""
        return self.thread.deaths

    @property
    def failed(self) -> str:
        """Why the sender gave up ('' while it runs)."""
        return self.thread.failed

    @property
    def running(self) -> bool:
        return self.thread.running

    def start(self) -> None:
        """Start sending: the first cycle at once (once)."""
        self.thread.start()

    def stop(self, timeout_s: float = 5.0) -> bool:
        """Stop sending and join the thread; False if it did not end (logged)."""
        return self.thread.stop(timeout_s)

    def _run(self, stop: threading.Event) -> None:
        clock, cycle = self.clock, self.cycle
        while not stop.is_set():
            now = clock.now()
            if not cycle.due(now):
                if sleep_until(clock, cycle.next_s, stop):
                    return
                continue
            if math.isfinite(cycle.next_s) and now >= cycle.next_s + cycle.period_s:
                self.skipped += int((now - cycle.next_s) // cycle.period_s)
            cycle.sent(now)
            for msg in self.build():
                msg.timestamp = self.stamp()
                self._send(msg)
            self.cycles += 1

    def _send(self, msg: can.Message) -> None:
        try:
            ok = self.send(msg)
        except Exception as exc:  # the cycle goes on; the next period sends again
            self.send_errors += 1
            if not self._raising:
                log.error(
                    "event=cyclic_send_raised sender=%s id=0x%X errors=%d error=%r",
                    self.name,
                    msg.arbitration_id,
                    self.send_errors,
                    f"{type(exc).__name__}: {exc}",
                )
            self._raising = True
            return
        self._raising = False
        if ok:
            self.frames += 1
        else:
            self.send_errors += 1


__all__ = ["CyclicSender"]
