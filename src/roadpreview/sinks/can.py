"""CAN sinks: the alerts, confirmations and status as E2E-protected frames
(``data/roadpreview.dbc``), on a live bus or in a log file.

Per active alert ``RP_ALERT`` then ``RP_ALERT_DETAIL`` as it is emitted and every
repetition period after (on the frames' clock, with distance and time to arrival as of
that frame), until the ego has passed its spot; then ``RP_ALERT_END`` (PASSED, or
CANCELLED, also for every alert still active at close). `AlertRepeater`
(`roadpreview.canbus.repetition`) decides what goes out when. Per confirmation
``RP_CONFIRM`` at its frame (with the running precision after it), and ``RP_STATUS`` +
``RP_ROAD_STATUS`` (and ``RP_INPUT_STATUS`` while the inputs have problems) when the
loop says the status is due. Every sink uses one `OutputEncoders` bundle, so a log holds
exactly the frames a bus would get.

On a live bus the status does not wait for the loop: `CanBusSink` with a `StatusCycle`
sends it from a `roadpreview.canbus.cyclic.CyclicSender` of its own, every period of the
cycle's clock, built at each send from the newest status the loop handed the sink (with
every frame, at every status period); a loop held up by a burst of input or a slow frame
then holds up nothing but the status's content (its heartbeat stops changing, as the
DBC says a stalled video pipeline shows).
"""

from __future__ import annotations

import logging
import math
import threading
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import can

from roadpreview.canbus.cyclic import CyclicSender
from roadpreview.canbus.logio import CanLogWriter
from roadpreview.canbus.output import OutputEncoders
from roadpreview.canbus.repetition import AlertEnd, AlertRepeater, AlertSend, RepetitionConfig
from roadpreview.clock import Clock
from roadpreview.sinks import Sink
from roadpreview.supervision import Supervision
from roadpreview.types import Alert, CameraFrame, ConfirmationResult, Status

if TYPE_CHECKING:
    from roadpreview.pipeline.config import PipelineConfig
    from roadpreview.pipeline.pipeline import FrameResult
    from roadpreview.pipeline.run_summary import RunSummary

log = logging.getLogger(__name__)


def repetition_config(config: PipelineConfig) -> RepetitionConfig:
    """The alerts' repetition from the pipeline's configuration: the period
    (``[can] alert_repeat_period_s``), the ego's geometry and the limits the alerts and
    the ego's check use (``[anomaly.alert]``, ``[anomaly.confirm]``)."""
    alert, confirm = config.anomaly.alert, config.anomaly.confirm
    return RepetitionConfig(
        period_s=config.can.alert_repeat_period_s,
        camera_to_front_axle_m=alert.camera_to_front_axle_m,
        wheelbase_m=confirm.wheelbase_m,
        min_speed_mps=alert.min_speed_mps,
        max_age_s=confirm.max_wait_s,
    )


class CanSink(Sink, ABC):
    """Encodes the output; subclasses put each frame somewhere (`_emit`). ``repetition``:
    how alerts are repeated and ended (default: `RepetitionConfig`'s defaults; a run
    passes `repetition_config` of its configuration)."""

    def __init__(
        self, *, detector: str = "two-axle", repetition: RepetitionConfig | None = None
    ) -> None:
        self.encoders = OutputEncoders(detector=detector)
        self.repeater = AlertRepeater(repetition)
        self.frames_out = 0  #: CAN frames emitted
        self.t_last = -math.inf  #: the newest time the sink was called with (frame, status)

    @abstractmethod
    def _emit(self, msg: can.Message) -> bool:
        """Put one frame out; False if it could not be (counted by the subclass)."""

    def _emit_all(self, msgs: Sequence[can.Message]) -> None:
        for msg in msgs:
            self.frames_out += self._emit(msg)

    def _send(self, items: Sequence[AlertSend | AlertEnd]) -> None:
        for item in items:
            if isinstance(item, AlertEnd):
                self._emit_all([self.encoders.end.encode(item)])
            else:
                self._emit_all(self.encoders.alert_frames(item))

    def _confirmations(
        self, t_s: float, confirmations: Sequence[ConfirmationResult], status: Status
    ) -> None:
        encode = self.encoders.confirm.encode
        frames = []
        for c in confirmations:  # under the alert's id on CAN, which is then free again
            frames.append(
                encode(
                    replace(c, alert_id=self.repeater.can_id(c.alert_id)),
                    status.precision,
                    timestamp=t_s,
                )
            )
            self.repeater.release(c.alert_id)
        self._emit_all(frames)

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self.t_last = max(self.t_last, result.t)
        self._send(
            self.repeater.frame(
                result.t,
                result.ego_speed_mps,
                (*result.provisional, *result.alerts),
                result.cancelled,
            )
        )
        self._confirmations(result.t, result.confirmations, status)
        preview = result.preview
        if preview is not None and preview.valid.any():  # (none: no RP_PREVIEW this cycle)
            self._emit_all(self.encoders.preview_frames(preview, timestamp=result.t))

    def on_status(self, t_s: float, status: Status) -> None:
        self.t_last = max(self.t_last, t_s)
        self._emit_all(self.encoders.status_frames(status, timestamp=t_s))

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        # at the last frame's time: the ego drove nothing since, so the speed is not needed
        self.t_last = max(self.t_last, t_s)
        self._send(self.repeater.frame(t_s, None, alerts))

    def close(self, summary: RunSummary) -> None:
        """The alerts still active end CANCELLED (STOPPED), every end not yet repeated goes
        out now (stamped with the newest time seen); subclasses then close their output."""
        self._send(self.repeater.close(self.t_last if math.isfinite(self.t_last) else None))


class CanMemorySink(CanSink):
    """The output frames kept in a list (``messages``), stamped with the pipeline's time."""

    def __init__(
        self, *, detector: str = "two-axle", repetition: RepetitionConfig | None = None
    ) -> None:
        super().__init__(detector=detector, repetition=repetition)
        self.messages: list[can.Message] = []

    def _emit(self, msg: can.Message) -> bool:
        self.messages.append(msg)
        return True


class CanLogSink(CanSink):
    """The output frames in a CAN log (format by suffix: BLF, ASC, candump, ...), written
    as they come and stamped with the pipeline's time of the frame that raised them."""

    def __init__(
        self,
        path: str | Path,
        *,
        detector: str = "two-axle",
        repetition: RepetitionConfig | None = None,
    ) -> None:
        super().__init__(detector=detector, repetition=repetition)
        self.path = Path(path)
        self.writer = CanLogWriter(self.path)

    def _emit(self, msg: can.Message) -> bool:
        self.writer.write(msg)
        return True

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        super().on_frame(frame, result, status)
        if result.alerts or result.provisional or result.cancelled or result.confirmations:
            self.writer.flush()

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        super().on_flush(t_s, alerts, status)
        self.writer.flush()

    def close(self, summary: RunSummary) -> None:
        try:
            super().close(summary)
        finally:
            self.writer.close()


#: send errors logged one by one; after them one line every `SEND_ERROR_LOG_EVERY`
SEND_ERRORS_LOGGED = 5
SEND_ERROR_LOG_EVERY = 1000


@dataclass(frozen=True)
class StatusCycle:
    """The periodic status (RP_STATUS, RP_ROAD_STATUS, RP_INPUT_STATUS while the inputs
    have problems) sent by a thread of its own every ``period_s`` of ``clock`` (the
    frames' clock: a `roadpreview.loop.Pace`, or the system's monotonic clock with
    ``stamp`` the frames' clock for the time stamps), supervised by ``supervision``;
    ``on_failed`` hears when the sender gave up."""

    clock: Clock
    period_s: float = 0.1
    stamp: Callable[[], float] | None = None  #: the frames' time stamps (default: clock)
    supervision: Supervision = field(default_factory=Supervision)
    on_failed: Callable[[str], None] | None = None


class CanBusSink(CanSink):
    """The output frames sent on a bus (stamped with the pipeline's time, which is the
    wall clock in the daemon; the receiver stamps them again). A send that fails, with
    whatever exception, costs that frame only: it is counted (``send_errors``, and per
    arbitration id in ``send_failures``), logged (the first `SEND_ERRORS_LOGGED`, then
    every `SEND_ERROR_LOG_EVERY`-th, and once when a send succeeds again) and never
    raised: the next frame, e.g. the next period's RP_STATUS, is sent as usual.
    ``record`` also writes every frame sent to a CAN log. At close the active alerts end
    (CANCELLED, STOPPED) and the last status (after the flush) is sent once more.

    With ``cycle`` the status goes out from ``status_sender`` (a `CyclicSender`, started
    at the first frame), every period of the cycle's clock, from the newest status the
    loop handed the sink, stamped when it is sent; the loop's status schedule then only
    updates that status. Sends from the loop's thread and the sender's are serialised."""

    def __init__(
        self,
        bus: can.BusABC,
        *,
        detector: str = "two-axle",
        record: str | Path | None = None,
        repetition: RepetitionConfig | None = None,
        cycle: StatusCycle | None = None,
    ) -> None:
        super().__init__(detector=detector, repetition=repetition)
        self.bus = bus
        self.send_errors = 0  #: frames the bus refused
        self.send_failures: Counter[int] = Counter()  #: ... per arbitration id
        self._failing = 0  # send errors since the last frame that went out
        self.record = CanLogWriter(record) if record is not None else None
        self._last: tuple[float, Status] | None = None  # the newest time and status seen
        self._lock = threading.Lock()  # one sender at a time: the loop's or the cycle's
        self._started = False  # the status sender was started (once, at the first status)
        self.cycle = cycle
        self.status_sender: CyclicSender | None = None
        if cycle is not None:
            self.status_sender = CyclicSender(
                "can-status",
                self._status_now,
                self._emit_one,
                clock=cycle.clock,
                period_s=cycle.period_s,
                stamp=cycle.stamp,
                supervision=cycle.supervision,
                on_failed=cycle.on_failed,
            )

    def _status_now(self) -> Iterator[can.Message]:
        """The cycle's frames, from the newest status, each encoded as it is sent (the
        sender's thread)."""
        last = self._last
        if last is not None:
            yield from self.encoders.iter_status_frames(last[1], timestamp=last[0])

    def _emit_one(self, msg: can.Message) -> bool:
        with self._lock:
            ok = self._emit(msg)
            self.frames_out += ok
            return ok

    def _emit_all(self, msgs: Sequence[can.Message]) -> None:
        with self._lock:
            super()._emit_all(msgs)

    def _emit(self, msg: can.Message) -> bool:
        try:
            self.bus.send(msg)
        except Exception as exc:  # a bus error, a closed socket, a driver bug: one frame
            self.send_errors += 1
            self.send_failures[msg.arbitration_id] += 1
            self._failing += 1
            n = self.send_errors
            if n <= SEND_ERRORS_LOGGED or n % SEND_ERROR_LOG_EVERY == 0:
                log.error(
                    "event=can_send_failed id=0x%X errors=%d error=%r",
                    msg.arbitration_id,
                    n,
                    f"{type(exc).__name__}: {exc}",
                )
            return False
        if self._failing:
            log.warning(
                "event=can_send_recovered id=0x%X failed_in_row=%d errors=%d",
                msg.arbitration_id,
                self._failing,
                self.send_errors,
            )
            self._failing = 0
        if self.record is not None:
            self.record.write(msg)
        return True

    def _note(self, t_s: float, status: Status) -> None:
        """The newest time and status (one reference: the sender's thread reads it whole)."""
        t_last = self._last[0] if self._last is not None else t_s
        self._last = (max(t_s, t_last), status)
        if self.status_sender is not None and not self._started:
            self._started = True
            self.status_sender.start()

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        super().on_frame(frame, result, status)
        self._note(result.t, status)

    def on_status(self, t_s: float, status: Status) -> None:
        if self.status_sender is None:
            super().on_status(t_s, status)
        else:  # the cycle sends it
            self.t_last = max(self.t_last, t_s)
        self._note(t_s, status)

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        super().on_flush(t_s, alerts, status)
        self._note(t_s, status)

    def close(self, summary: RunSummary) -> None:
        stopped = True
        if self.status_sender is not None:
            stopped = self.status_sender.stop()
        try:
            super().close(summary)
            if self._last is not None and stopped:  # the last word: counts after the flush
                t, status = self._last
                cycle = self.cycle
                if cycle is not None:  # after the cycle's frames, on their clock
                    t = (cycle.stamp or cycle.clock.now)()
                CanSink.on_status(self, t, status)
        finally:
            if self.record is not None:
                self.record.close()


__all__ = [
    "CanBusSink",
    "CanLogSink",
    "CanMemorySink",
    "CanSink",
    "StatusCycle",
    "repetition_config",
]
