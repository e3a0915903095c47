"""Live CAN: open any python-can bus, receive through a bounded queue, play a log onto a bus.

* `open_bus` opens ``can.Bus(interface=..., channel=...)`` (socketcan, pcan,
  vector, virtual, ...) and turns python-can's errors into ours.
* `BoundedQueueListener` is the only thing the receive thread runs: it puts
  each frame into a bounded queue and counts the frames it had to drop when
  the queue was full. Decoding happens in the consumer, never in python-can's
  ``Notifier`` thread.
* `CanReceiver` wires a ``can.Notifier`` to such a listener.
* `replay` plays a recorded log onto a bus at its recorded pace
  (``can.MessageSync``), for bench tests of a receiver.

Sending roadpreview's outputs is `roadpreview.sinks.can.CanBusSink`: the run loop
schedules the status for a bus and a log alike. Logging to a file: a ``can.Logger`` is
itself a listener; pass it to `CanReceiver` (``extra_listeners``).
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Iterable
from types import TracebackType
from typing import Any

import can

from roadpreview.errors import ConfigError, MissingDependencyError, OperationError

log = logging.getLogger(__name__)

#: default receive queue length: 10 s of a busy 500 kbit/s bus (~4000 frames/s) is 40000
DEFAULT_QUEUE_SIZE = 10_000
#: RP_STATUS and RP_ROAD_STATUS period (the DBC's GenMsgCycleTime), s
STATUS_PERIOD_S = 0.1


def open_bus(interface: str, channel: str | int | None = None, **kwargs: Any) -> can.BusABC:
    """``can.Bus(interface=..., channel=..., **kwargs)`` with errors that say what to do."""
    try:
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except ImportError as exc:
        raise MissingDependencyError(
            f"CAN interface {interface!r} needs a package that is not installed ({exc})"
        ) from None
    except (can.CanInterfaceNotImplementedError, NotImplementedError) as exc:
        raise ConfigError(f"CAN interface {interface!r} is not available here ({exc})") from None
    except (can.CanError, OSError, ValueError) as exc:
        raise OperationError(f"cannot open CAN bus {interface}:{channel} ({exc})") from None


class BoundedQueueListener(can.Listener):
    """A listener that only queues frames; when the queue is full it drops and counts them."""

    def __init__(self, maxsize: int = DEFAULT_QUEUE_SIZE) -> None:
        if maxsize < 1:
            raise ConfigError(f"queue size {maxsize}: must be >= 1")
        self.queue: queue.Queue[can.Message] = queue.Queue(maxsize=maxsize)
        self.dropped = 0  #: frames lost because the queue was full
        self.errors = 0  #: exceptions the bus reported to the notifier
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        """Queue the frame (the notifier thread calls this: nothing else happens here)."""
        try:
            self.queue.put_nowait(msg)
        except queue.Full:
            with self._lock:
                self.dropped += 1

    def on_error(self, exc: Exception) -> None:
        """Count a receive error (the notifier stops after it; see python-can)."""
        with self._lock:
            self.errors += 1
        log.error("CAN receive error: %r", exc)

    def get(self, timeout: float | None = None) -> can.Message | None:
        """The next frame, or None after ``timeout`` seconds (None: wait forever)."""
        try:
            return self.queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def drain(self) -> list[can.Message]:
        """All frames queued now, without waiting."""
        out = []
        while True:
            try:
                out.append(self.queue.get_nowait())
            except queue.Empty:
                return out


class CanReceiver:
    """Receive from a bus through ``can.Notifier`` into a `BoundedQueueListener`.

    Use as a context manager; it stops the notifier on exit but leaves the
    bus to its owner.
    """

    def __init__(
        self,
        bus: can.BusABC,
        *,
        maxsize: int = DEFAULT_QUEUE_SIZE,
        extra_listeners: Iterable[can.Listener] = (),
        timeout_s: float = 0.1,
    ) -> None:
        self.bus = bus
        self.listener = BoundedQueueListener(maxsize)
        self._notifier = can.Notifier(bus, [self.listener, *extra_listeners], timeout=timeout_s)

    @property
    def dropped(self) -> int:
        """Frames dropped because the queue was full."""
        return self.listener.dropped

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next received frame, or None after ``timeout`` seconds."""
        return self.listener.get(timeout)

    def stop(self) -> None:
        """Stop the notifier thread."""
        self._notifier.stop()

    def __enter__(self) -> CanReceiver:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


def replay(
    messages: Iterable[can.Message],
    bus: can.BusABC,
    *,
    pace: bool = True,
    gap_s: float = 0.0001,
    skip_s: float = 60.0,
) -> int:
    """Send recorded frames on ``bus``; return the count.

    ``pace=True`` keeps the recorded time between frames (``can.MessageSync``:
    at least ``gap_s`` between frames, recorded pauses longer than ``skip_s``
    shortened to it); ``pace=False`` sends as fast as the bus takes them.
    """
    source: Iterable[can.Message] = (
        can.MessageSync(messages, timestamps=True, gap=gap_s, skip=skip_s) if pace else messages
    )
    count = 0
    for msg in source:
        try:
            bus.send(msg)
        except can.CanError as exc:
            raise OperationError(
                f"CAN send of 0x{msg.arbitration_id:X} (frame {count}) failed ({exc})"
            ) from None
        count += 1
    return count
