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
* `CanLogPlayer` plays a log onto a bus in a thread of its own, re-stamped onto the
  receiver's clock and paced by it (``roadpreview run --can-log``): the daemon is fed
  from a log as from a car. Garbled frames and send errors are logged and counted.

Sending roadpreview's outputs is `roadpreview.sinks.can.CanBusSink`: the run loop
schedules the status for a bus and a log alike. Logging to a file: a ``can.Logger`` is
itself a listener; pass it to `CanReceiver` (``extra_listeners``).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import Any, Protocol

import can

from roadpreview.canbus.logio import CanLogReader
from roadpreview.clock import Clock, SystemClock, sleep_until
from roadpreview.errors import ConfigError, InputDataError, MissingDependencyError, OperationError

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
    """A listener that only queues frames; when the queue is full it drops and counts them.
    ``arrived`` is set with every frame queued (a consumer that waits on a clock clears it
    before it looks at the queue)."""

    def __init__(
        self, maxsize: int = DEFAULT_QUEUE_SIZE, *, arrived: threading.Event | None = None
    ) -> None:
        if maxsize < 1:
            raise ConfigError(f"queue size {maxsize}: must be >= 1")
        self.queue: queue.Queue[can.Message] = queue.Queue(maxsize=maxsize)
        self.dropped = 0  #: frames lost because the queue was full
        self.errors = 0  #: exceptions the bus reported to the notifier
        self.arrived = arrived or threading.Event()
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        """Queue the frame (the notifier thread calls this: nothing else happens here)."""
        try:
            self.queue.put_nowait(msg)
            self.arrived.set()
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
        arrived: threading.Event | None = None,
    ) -> None:
        self.bus = bus
        self.listener = BoundedQueueListener(maxsize, arrived=arrived)
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


class Schedule(Protocol):
    """When a time stamp is due: `roadpreview.loop.Pace` is one."""

    def start(self, t0: float) -> None:
        """Anchor the schedule at the first time stamp if it is not anchored yet."""
        ...

    def sleep_until(self, t: float, stop: threading.Event) -> bool:
        """Wait until time stamp ``t`` is due or ``stop`` is set; True if stopped."""
        ...


class WallClock:
    """The default `Schedule`: a time stamp is due when ``clock`` (default: the system's,
    Unix time) reads it."""

    def __init__(self, clock: Clock | None = None) -> None:
        self.clock = clock or SystemClock()

    def start(self, t0: float) -> None:
        pass

    def sleep_until(self, t: float, stop: threading.Event) -> bool:
        return sleep_until(self.clock, t, stop)


class CanLogPlayer:
    """Play a CAN log onto a bus from a thread, at its recorded pace, re-stamped.

    A frame recorded at ``t`` is stamped ``t - anchor_log_s + anchor_s`` and sent when
    ``schedule`` says that stamp is due: ``anchor_log_s`` (default: the log's first
    frame) lines up with ``anchor_s`` on the receiver's clock (default: when `start` is
    called, on ``clock``, the system's by default). A bus that keeps the sender's stamps
    (python-can ``virtual`` with ``preserve_timestamps=True``) hands them on as they are;
    a real bus stamps frames on arrival, which is the same time when ``schedule`` is the
    wall clock. With ``loop`` the log starts over when it ends, each lap stamped one log
    span (plus ``lap_gap_s``) later. A frame stamped before its predecessor is skipped,
    as the log sources do.

    Nothing stops the thread but `stop`: garbled frames (the reader logs and skips
    them), frames the bus refuses and skipped frames are logged and counted in
    ``errors``; an unexpected failure is logged, counted and ends the playing only.
    """

    def __init__(
        self,
        path: str | Path,
        bus: can.BusABC,
        *,
        anchor_s: float | None = None,
        anchor_log_s: float | None = None,
        schedule: Schedule | None = None,
        loop: bool = False,
        lap_gap_s: float = 0.01,
        clock: Clock | None = None,
    ) -> None:
        self.path = Path(path)
        CanLogReader(self.path)  # the suffix is checked here
        if not self.path.is_file():
            raise InputDataError(f"{self.path}: CAN log not found")
        self.bus = bus
        self.anchor_s = anchor_s
        self.anchor_log_s = anchor_log_s
        self.clock = clock or SystemClock()
        self.schedule: Schedule = schedule or WallClock(self.clock)
        self.loop = loop
        self.lap_gap_s = lap_gap_s
        self.sent = 0  #: frames sent
        self.send_errors = 0  #: frames the bus refused
        self.out_of_order = 0  #: frames stamped before their predecessor (skipped)
        self.garbled = 0  #: garbled frames the reader skipped (all laps)
        self.failures = 0  #: unexpected failures (each ended the playing)
        self.laps = 0  #: times the log was played to its end
        self._stop = self.clock.event()
        self._thread: threading.Thread | None = None

    @property
    def errors(self) -> int:
        return self.send_errors + self.out_of_order + self.garbled + self.failures

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Start playing (once)."""
        if self._thread is not None:
            raise OperationError(f"{self.path}: the player was started already")
        if self.anchor_s is None:
            self.anchor_s = self.clock.now()
        self._thread = threading.Thread(target=self._run, name="can-log-player", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop playing and wait for the thread (the bus stays its owner's)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                log.error("event=can_log_player_hangs path=%s", self.path)

    def _run(self) -> None:
        try:
            shift: float | None = None  # receiver's clock minus the log's (first lap: unset)
            while not self._stop.is_set():
                first, last, shift = self._lap(shift)
                if self._stop.is_set():
                    return
                if math.isnan(first):
                    log.error("event=can_log_empty path=%s", self.path)
                    return
                self.laps += 1
                if not self.loop:
                    return
                shift += last - first + self.lap_gap_s
        except Exception:
            self.failures += 1
            log.exception("event=can_log_player_failed path=%s sent=%d", self.path, self.sent)
        finally:
            log.info(
                "event=can_log_player_end path=%s laps=%d sent=%d errors=%d",
                self.path,
                self.laps,
                self.sent,
                self.errors,
            )

    def _lap(self, shift: float | None) -> tuple[float, float, float]:
        """Play the log once: its first and last time stamps (NaN: no frame) and the shift
        used (``shift``, or on the first lap the one the anchors give)."""
        reader = CanLogReader(self.path)
        first = last = math.nan
        try:
            for msg in reader:
                if self._stop.is_set():
                    break
                t = float(msg.timestamp)
                if math.isnan(first):
                    first = last = t
                    if shift is None:
                        assert self.anchor_s is not None
                        anchor_log = self.anchor_log_s if self.anchor_log_s is not None else t
                        shift = self.anchor_s - anchor_log
                elif t < last:
                    self.out_of_order += 1
                    if self.out_of_order <= 10 or self.out_of_order % 1000 == 0:
                        log.warning(
                            "event=can_log_out_of_order path=%s t=%.6f back_s=%.6f count=%d",
                            self.path,
                            t,
                            last - t,
                            self.out_of_order,
                        )
                    continue
                last = t
                assert shift is not None
                msg.timestamp = t + shift
                self.schedule.start(msg.timestamp)
                if self.schedule.sleep_until(msg.timestamp, self._stop):
                    break
                self._send(msg)
        finally:
            self.garbled += len(reader.problems)
        return first, last, shift if shift is not None else 0.0

    def _send(self, msg: can.Message) -> None:
        try:
            self.bus.send(msg)
            self.sent += 1
        except (can.CanError, OSError, ValueError) as exc:
            self.send_errors += 1
            if self.send_errors <= 10 or self.send_errors % 1000 == 0:
                log.error(
                    "event=can_log_send_failed path=%s id=0x%X count=%d error=%r",
                    self.path,
                    msg.arbitration_id,
                    self.send_errors,
                    exc,
                )
