"""Sinks: where the run loop's output goes. One small protocol (`Sink`) for all of them.

The loop (`roadpreview.loop.run`) calls, in time order:

* ``on_frame(frame, result, status)`` after every camera frame: its `FrameResult`
  (with the alerts and confirmations it raised) and the status after it;
* ``on_status(t_s, status)`` every status period (scheduled in the loop, one place for
  the bus and the log alike);
* ``on_flush(t_s, alerts, status)`` at the end of input: the alerts the detector still
  held back;
* ``close(summary)`` once, also after an error or an interrupt.

Streaming sinks (`CanBusSink`, `CanLogSink`, `AlertsJsonlSink`, `FrameTableSink`) write
as they go, so an interrupt loses nothing written so far; `PlotSink` and
`AnnotatedVideoSink` finish at close.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from roadpreview.types import Alert, CameraFrame, Status

if TYPE_CHECKING:
    from roadpreview.pipeline.pipeline import FrameResult
    from roadpreview.pipeline.run_summary import RunSummary


class Sink:
    """The sink protocol, with do-nothing defaults: a sink overrides what it uses."""

    def on_frame(self, frame: CameraFrame, result: FrameResult, status: Status) -> None:
        """A processed camera frame."""

    def on_status(self, t_s: float, status: Status) -> None:
        """The periodic status, at the frame time ``t_s``."""

    def on_flush(self, t_s: float, alerts: Sequence[Alert], status: Status) -> None:
        """The alerts held back until the end of input (``t_s``: the last frame's time)."""

    def close(self, summary: RunSummary) -> None:
        """The run ended (normally, on an interrupt or on an error): finish the output."""


__all__ = ["Sink"]
