"""Reference receivers of roadpreview's outputs: `AlertReceiver` follows each alert's life
(provisional, confirmed, ended) from the decoded frames, `PreviewAssembler` puts the
``RP_PREVIEW`` pages of one snapshot back into a `RoadPreview`.

Both take what `OutputDecoder` gives (E2E CRC and counter checked there) and ignore the
rest, so one decoder can feed both; `PreviewAssembler.push_frame` decodes a raw frame
itself. No clocks: time is the frames' reception time stamps. docs/can-interface.md says
what a chassis controller does in each state.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, replace
from enum import Enum

import can
import numpy as np
from cantools.database.can import Database

from roadpreview.canbus.received import (
    OutputDecoder,
    ReceivedAlert,
    ReceivedAlertDetail,
    ReceivedAlertEnd,
    ReceivedOutput,
    ReceivedPreviewHeader,
    ReceivedPreviewPage,
)
from roadpreview.canbus.repetition import EndCause, EndReason
from roadpreview.errors import ConfigError
from roadpreview.types import AlertState, RoadPreview

#: an active alert with neither RP_ALERT nor RP_ALERT_DETAIL for this long is dropped
#: (5 periods of 100 ms: the sender has stopped; docs/can-interface.md)
STALE_S = 0.5


class ReceiverState(Enum):
    """Where one ``AlertId`` stands at the receiver (`AlertReceiver`)."""

    NONE = "none"  #: never seen: do nothing
    PROVISIONAL = "provisional"  #: pre-arm within the actuator's limits
    CONFIRMED = "confirmed"  #: act on the refined height and length
    ENDED = "ended"  #: release (how: `ReceivedAlertLife.end`)


@dataclass(frozen=True, slots=True)
class ReceivedAlertLife:
    """One alert as the receiver knows it: its state and the last frames about it."""

    alert_id: int  #: the 8-bit ``AlertId``
    state: ReceiverState
    t_start_s: float  #: reception time of its first frame, s
    t_last_s: float  #: reception time of its last RP_ALERT / RP_ALERT_DETAIL / end, s
    alert: ReceivedAlert | None = None  #: its last RP_ALERT (None: none received yet)
    detail: ReceivedAlertDetail | None = None  #: its last RP_ALERT_DETAIL
    end: ReceivedAlertEnd | None = None  #: its RP_ALERT_END (the first of the repetitions)
    t_confirmed_s: float = math.nan  #: when it became CONFIRMED (NaN: not yet / never), s
    was_provisional: bool = False  #: it was PROVISIONAL before (not confirmed at once)
    stale: bool = False  #: ENDED by silence (no RP_ALERT_END arrived within `STALE_S`)

    @property
    def reason(self) -> EndReason | None:
        """Why it ended, as its RP_ALERT_END says (None: not ended, or ended by silence)."""
        return None if self.end is None else self.end.reason

    @property
    def cause(self) -> EndCause | None:
        """The full cause of its end (None: not ended, or ended by silence)."""
        return None if self.end is None else self.end.cause


@dataclass(frozen=True, slots=True)
class AlertTransition:
    """An alert changed its state at ``t_s`` (the reception time of the frame that says so)."""

    alert_id: int
    before: ReceiverState
    after: ReceiverState
    t_s: float
    life: ReceivedAlertLife  #: the alert after the change


class AlertReceiver:
    """Decoded frames in, the state of each ``AlertId`` out: a reference receiver.

    States and what a chassis controller does in each (docs/can-interface.md, "Alert
    states at the receiver"):

    * NONE: the id is unknown (never seen, or ended and not seen again). Nothing to do.
    * PROVISIONAL: an ``RP_ALERT`` arrived, and its ``RP_ALERT_DETAIL`` says PROVISIONAL
      or has not arrived yet (a new id is PROVISIONAL until a detail says CONFIRMED; the
      detail follows its ``RP_ALERT`` at once, so a confirmed alert passes through in the
      same send). The height is a first estimate from the lead's front axle, the
      confidence lower. **Pre-arm**: prepare what is cheap to undo and within the
      actuator's limits (pre-charge, pre-select a damping map, time the arrival), no
      ride-height or energy-costly moves on this height alone.
    * CONFIRMED: a detail said CONFIRMED (never goes back to PROVISIONAL). **Act** on the
      refined ``AlertHeight`` / ``AlertLength``, timed by ``AlertTimeToArrival``.
    * ENDED: ``RP_ALERT_END`` arrived, or neither ``RP_ALERT`` nor ``RP_ALERT_DETAIL``
      for ``stale_s`` (``stale``). PASSED: the rear axle has passed; return to normal.
      CANCELLED: **release** what was prepared, at once but gently; with cause
      NOT_CONFIRMED the anomaly was not confirmed (only a PROVISIONAL alert ends so), with
      STOPPED / TIMEOUT / OVERFLOW roadpreview stopped tracking it. Ended by silence:
      release, the sender may be gone. A later ``RP_ALERT`` with the same id is a new alert.

    `push` returns the transitions a frame causes (the silence rule included: it runs at
    each frame's time, or call `expire`). ``problems`` counts what breaks the protocol:
    ``state_regressed`` (a detail says PROVISIONAL after CONFIRMED; ignored) and
    ``not_confirmed_after_confirmed`` (a CONFIRMED alert ended NOT_CONFIRMED).
    """

    def __init__(self, *, stale_s: float = STALE_S) -> None:
        if not (math.isfinite(stale_s) and stale_s > 0):
            raise ConfigError(f"AlertReceiver stale_s = {stale_s}: must be > 0")
        self.stale_s = stale_s
        self._alerts: dict[int, ReceivedAlertLife] = {}
        self.transitions: list[AlertTransition] = []  #: every transition so far, in order
        self.problems: Counter[str] = Counter()

    def state(self, alert_id: int) -> ReceiverState:
        """The state of ``alert_id`` now."""
        life = self._alerts.get(alert_id)
        return ReceiverState.NONE if life is None else life.state

    def get(self, alert_id: int) -> ReceivedAlertLife | None:
        """What is known of ``alert_id`` (its last life, ended or not; None: never seen)."""
        return self._alerts.get(alert_id)

    @property
    def active(self) -> dict[int, ReceivedAlertLife]:
        """The alerts PROVISIONAL or CONFIRMED now, by id."""
        return {
            i: a
            for i, a in self._alerts.items()
            if a.state in (ReceiverState.PROVISIONAL, ReceiverState.CONFIRMED)
        }

    def push_all(self, items: Iterable[ReceivedOutput | None]) -> list[AlertTransition]:
        """`push` each of ``items``; all the transitions."""
        return [t for item in items for t in self.push(item)]

    def push(self, item: ReceivedOutput | None) -> list[AlertTransition]:
        """One decoded frame (None and other messages: only the silence rule runs)."""
        if item is None:
            return []
        out = self.expire(item.t_rx_s)
        if isinstance(item, ReceivedAlert):
            out += self._on_alert(item)
        elif isinstance(item, ReceivedAlertDetail):
            out += self._on_detail(item)
        elif isinstance(item, ReceivedAlertEnd):
            out += self._on_end(item)
        return out

    def expire(self, now_s: float) -> list[AlertTransition]:
        """End the active alerts silent for longer than ``stale_s`` at ``now_s``."""
        out = []
        for life in list(self.active.values()):
            if now_s - life.t_last_s > self.stale_s:
                out.append(self._move(replace(life, state=ReceiverState.ENDED, stale=True), now_s))
        return out

    def _move(self, life: ReceivedAlertLife, t_s: float, *, new: bool = False) -> AlertTransition:
        """Store ``life``; the transition from its state before (NONE for a ``new`` life)."""
        before = ReceiverState.NONE if new else self.state(life.alert_id)
        self._alerts[life.alert_id] = life
        transition = AlertTransition(life.alert_id, before, life.state, t_s, life)
        self.transitions.append(transition)
        return transition

    def _active(self, alert_id: int) -> ReceivedAlertLife | None:
        life = self._alerts.get(alert_id)
        return None if life is None or life.state == ReceiverState.ENDED else life

    def _start(self, alert_id: int, t: float) -> ReceivedAlertLife:
        return ReceivedAlertLife(alert_id, ReceiverState.PROVISIONAL, t_start_s=t, t_last_s=t)

    def _on_alert(self, rx: ReceivedAlert) -> list[AlertTransition]:
        life = self._active(rx.alert_id)
        if life is None:  # unknown or ended: a new alert, PROVISIONAL until a detail confirms
            started = replace(self._start(rx.alert_id, rx.t_rx_s), alert=rx)
            return [self._move(started, rx.t_rx_s, new=True)]
        self._alerts[rx.alert_id] = replace(life, alert=rx, t_last_s=rx.t_rx_s)
        return []

    def _on_detail(self, rx: ReceivedAlertDetail) -> list[AlertTransition]:
        out = []
        life = self._active(rx.alert_id)
        if life is None:  # its RP_ALERT was lost: the detail starts the alert
            life = self._start(rx.alert_id, rx.t_rx_s)
            out.append(self._move(life, rx.t_rx_s, new=True))
        life = replace(life, detail=rx, t_last_s=rx.t_rx_s)
        if rx.state == AlertState.PROVISIONAL:
            if life.state == ReceiverState.CONFIRMED:
                self.problems["state_regressed"] += 1
            else:
                life = replace(life, was_provisional=True)
            self._alerts[rx.alert_id] = life
        elif life.state == ReceiverState.PROVISIONAL:
            confirmed = replace(life, state=ReceiverState.CONFIRMED, t_confirmed_s=rx.t_rx_s)
            out.append(self._move(confirmed, rx.t_rx_s))
        else:
            self._alerts[rx.alert_id] = life
        return out

    def _on_end(self, rx: ReceivedAlertEnd) -> list[AlertTransition]:
        life = self._alerts.get(rx.alert_id)
        if life is not None and life.state == ReceiverState.ENDED:
            if life.end is None:  # ended by silence before: now the reason is known
                self._alerts[rx.alert_id] = replace(life, end=rx)
            return []  # else a repetition of the end
        confirmed = life is not None and life.state == ReceiverState.CONFIRMED
        if rx.cause == EndCause.NOT_CONFIRMED and confirmed:
            self.problems["not_confirmed_after_confirmed"] += 1
        if life is None:  # its whole life was lost: NONE -> ENDED
            ended = ReceivedAlertLife(
                rx.alert_id, ReceiverState.ENDED, rx.t_rx_s, rx.t_rx_s, end=rx
            )
            return [self._move(ended, rx.t_rx_s, new=True)]
        ended = replace(life, state=ReceiverState.ENDED, end=rx, t_last_s=rx.t_rx_s)
        return [self._move(ended, rx.t_rx_s)]


class PreviewAssembler:
    """``RP_PREVIEW`` pages in, a `RoadPreview` out when a snapshot is complete.

    A header (page 0) opens a snapshot; the bin pages of its ``PreviewCycle`` fill it;
    with the last page it comes out (heights and stds NaN where a bin has none, times on
    the receiver's clock: ``t_s`` = the header's reception minus ``PreviewAge``). A snapshot
    with a page missing never completes: the next header drops it (``dropped``
    ``missing_page``); pages without their header are dropped (``no_header``, once per
    cycle); a page beyond the header's count is ignored (``problems``). Frames come checked
    (E2E CRC and counter) from an `OutputDecoder`; `push_frame` takes raw frames through a
    decoder of its own.
    """

    def __init__(self, db: Database | None = None) -> None:
        self._db = db
        self._decoder: OutputDecoder | None = None
        self._header: ReceivedPreviewHeader | None = None
        self._pages: dict[int, ReceivedPreviewPage] = {}
        self._orphan_cycle: int | None = None
        self.completed = 0  #: snapshots put together
        self.dropped: Counter[str] = Counter()  #: snapshots dropped, by reason
        self.problems: Counter[str] = Counter()  #: pages ignored for breaking the layout

    @property
    def decoder(self) -> OutputDecoder:
        """The decoder of `push_frame` (built on first use)."""
        if self._decoder is None:
            self._decoder = OutputDecoder(self._db)
        return self._decoder

    def push_frame(self, msg: can.Message) -> RoadPreview | None:
        """One raw frame (any message; E2E checked by `decoder`)."""
        return self.push(self.decoder.decode(msg))

    def push(self, item: ReceivedOutput | None) -> RoadPreview | None:
        """One decoded frame; the snapshot it completes, if it does."""
        if isinstance(item, ReceivedPreviewHeader):
            if self._header is not None:
                self.dropped["missing_page"] += 1
            self._header, self._pages, self._orphan_cycle = item, {}, None
            return self._complete()
        if not isinstance(item, ReceivedPreviewPage):
            return None
        header = self._header
        if header is not None and item.cycle == header.cycle and item.page > header.pages:
            self.problems["page_out_of_range"] += 1  # not in the snapshot's header: ignored
            return None
        if header is None or item.cycle != header.cycle:
            if self._orphan_cycle != item.cycle:
                self.dropped["no_header"] += 1
                self._orphan_cycle = item.cycle
            if header is not None and item.cycle != header.cycle:  # the next cycle began
                self.dropped["missing_page"] += 1
                self._header = None
            return None
        self._pages[item.page] = item
        return self._complete()

    def _complete(self) -> RoadPreview | None:
        header = self._header
        if header is None or len(self._pages) < header.pages:
            return None
        tracks = 2 if header.sides else 1
        pages = [self._pages[p] for p in range(1, header.pages + 1)]
        shape = (tracks, -1)
        height = np.array([p.height_m for p in pages], dtype=np.float64).reshape(shape)
        std = np.array([p.std_m for p in pages], dtype=np.float64).reshape(shape)
        self._header, self._pages = None, {}
        self.completed += 1
        return RoadPreview(
            t_s=header.t_preview_s,
            bin_m=header.bin_m,
            start_m=header.start_m,
            height_m=height[:, : header.bins].copy(),
            std_m=std[:, : header.bins].copy(),
            sides=header.sides,
            lead_rear_axle_m=header.lead_rear_axle_m,
        )


__all__ = [
    "STALE_S",
    "AlertReceiver",
    "AlertTransition",
    "PreviewAssembler",
    "ReceivedAlertLife",
    "ReceiverState",
]
