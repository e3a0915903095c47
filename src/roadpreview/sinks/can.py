"""CAN sinks: the alerts, confirmations and status as E2E-protected frames
(``data/roadpreview.dbc``), on a live bus or in a log file.

Per alert ``RP_ALERT`` then ``RP_ALERT_DETAIL`` as it is emitted, per confirmation
``RP_CONFIRM`` at its frame (with the running precision after it), and ``RP_STATUS`` +
``RP_ROAD_STATUS`` when the loop says the status is due. Both sinks use one
`OutputEncoders` bundle, so a log holds exactly the frames a bus would get.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import can

from roadpreview.canbus.logio import CanLogWriter
from roadpreview.canbus.output import OutputEncoders
from roadpreview.sinks import Sink
from roadpreview.types import Alert, CameraFrame, ConfirmationResult, Status

if TYPE_CHECKING:
    from roadpreview.pipeline.pipeline import FrameResult
    from roadpreview.pipeline.run_summary import RunSummary

log = logging.getLogger(__name__)


class CanSink(Sink, ABC):
    """Encodes the output; subclasses put each frame somewhere (`_emit`)."""

    def __init__(self, *, detector: str = "two-axle") -> None:
        self.encoders = OutputEncoders(detector=detector)
        self.frames_out = 0  #: CAN frames emitted

    @abstractmethod
    def _emit(self, msg: can.Message) -> bool:
        """Put one frame out; False if it could not be (counted by the subclass)."""

    def _emit_all(self, msgs: Sequence[can.Message]) -> None:
        for msg in msgs:
            self.frames_out += self._emit(msg)

    def _alerts(self, t_s: float, alerts: Sequence[Alert]) -> None:
        for a in alerts:
            self._emit_all(self.encoders.alert_frames(a, timestamp=t_s))

    def _confirmations(
        self, t_s: float, confirmations: Sequence[ConfirmationResult], status: Status
    ) -> None:
        encode = self.encoders.confirm.encode
        self._emit_all([encode(c, status.precision, timestamp=t_s) for c in confirmations])

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        self._alerts(result.t, result.alerts)
        self._confirmations(result.t, result.confirmations, status)

    def on_status(self, t_s: float, status: Status) -> None:
        self._emit_all(self.encoders.status_frames(status, timestamp=t_s))

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        self._alerts(t_s, alerts)


class CanMemorySink(CanSink):
    """The output frames kept in a list (``messages``), stamped with the pipeline's time."""

    def __init__(self, *, detector: str = "two-axle") -> None:
        super().__init__(detector=detector)
        self.messages: list[can.Message] = []

    def _emit(self, msg: can.Message) -> bool:
        self.messages.append(msg)
        return True


class CanLogSink(CanSink):
    """The output frames in a CAN log (format by suffix: BLF, ASC, candump, ...), written
    as they come and stamped with the pipeline's time of the frame that raised them."""

    def __init__(self, path: str | Path, *, detector: str = "two-axle") -> None:
        super().__init__(detector=detector)
        self.path = Path(path)
        self.writer = CanLogWriter(self.path)

    def _emit(self, msg: can.Message) -> bool:
        self.writer.write(msg)
        return True

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        super().on_frame(frame, result, status)
        if result.alerts or result.confirmations:  # on disk as they happen (an interrupt)
            self.writer.flush()

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        super().on_flush(t_s, alerts, status)
        self.writer.flush()

    def close(self, summary: RunSummary) -> None:
        self.writer.close()


class CanBusSink(CanSink):
    """The output frames sent on a bus (stamped with the pipeline's time, which is the
    wall clock in the daemon; the receiver stamps them again); a send error is logged and
    counted, never raised (the daemon goes on). ``record`` also writes every frame sent
    to a CAN log. At close the last status (after the flush) is sent once more."""

    def __init__(
        self,
        bus: can.BusABC,
        *,
        detector: str = "two-axle",
        record: str | Path | None = None,
    ) -> None:
        super().__init__(detector=detector)
        self.bus = bus
        self.send_errors = 0  #: frames the bus refused
        self.record = CanLogWriter(record) if record is not None else None
        self._last: tuple[float, Status] | None = None  # the newest time and status seen

    def _emit(self, msg: can.Message) -> bool:
        try:
            self.bus.send(msg)
        except can.CanError as exc:
            self.send_errors += 1
            log.error(
                "event=can_send_failed id=0x%X errors=%d error=%r",
                msg.arbitration_id,
                self.send_errors,
                str(exc),
            )
            return False
        if self.record is not None:
            self.record.write(msg)
        return True

    def _note(self, t_s: float, status: Status) -> None:
        t_last = self._last[0] if self._last is not None else t_s
        self._last = (max(t_s, t_last), status)

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        super().on_frame(frame, result, status)
        self._note(result.t, status)

    def on_status(self, t_s: float, status: Status) -> None:
        super().on_status(t_s, status)
        self._note(t_s, status)

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        super().on_flush(t_s, alerts, status)
        self._note(t_s, status)

    def close(self, summary: RunSummary) -> None:
        try:
            if self._last is not None:  # the last word: the counts after the flush
                CanSink.on_status(self, *self._last)
        finally:
            if self.record is not None:
                self.record.close()


__all__ = ["CanBusSink", "CanLogSink", "CanMemorySink", "CanSink"]
