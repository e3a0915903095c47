"""roadpreview's output frames as a receiver sees them (the chassis ECU, a test, a monitor):
`OutputDecoder` checks each frame's E2E CRC and alive counter per message and gives
`ReceivedAlert`, `ReceivedAlertDetail`, `ReceivedAlertEnd`, `ReceivedConfirm`,
`ReceivedStatus`, `ReceivedRoadStatus`, `ReceivedInputStatus`, and per ``RP_PREVIEW`` page
`ReceivedPreviewHeader` / `ReceivedPreviewPage`, in SI units, None (NaN in the preview's
bins) for "not available". The sending side is `roadpreview.canbus.output`; what follows
an alert's life and puts the preview pages together is `roadpreview.canbus.receiver`.

A decoder built on a DBC of version 1 (no ``AlertState``, ``EndCauseEx``, ``RP_PREVIEW``)
decodes the frames of version 2 as version 1 did: every alert CONFIRMED, the cause of an
end as ``EndCause`` says (NONE for NOT_CONFIRMED), no preview.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import can
import e2e.p01
from cantools.database.can import Database
from cantools.database.can import Message as MessageDef
from cantools.database.errors import DecodeError
from cantools.database.namedsignalvalue import NamedSignalValue

from roadpreview.canbus.dbc import (
    E2E_COUNTER_MODULUS,
    RP_ALERT,
    RP_ALERT_DETAIL,
    RP_ALERT_END,
    RP_CONFIRM,
    RP_INPUT_STATUS,
    RP_PREVIEW,
    RP_ROAD_STATUS,
    RP_STATUS,
    e2e_layout,
    load_database,
)
from roadpreview.canbus.decode import signal_values
from roadpreview.canbus.output import (
    DETECTOR_CODES,
    GD_REF_M3,
    INPUT_STATUS_GROUPS,
    PREVIEW_BINS_PER_PAGE,
)
from roadpreview.canbus.repetition import EndCause, EndReason
from roadpreview.types import (
    ISO8608_CLASSES,
    AlertState,
    Confirmation,
    FusionMode,
    Side,
    SuppressionReason,
)

_DEG = math.pi / 180.0
_KMH = 1.0 / 3.6  #: m/s per km/h


@dataclass(frozen=True, slots=True)
class ReceivedAlert:
    """An ``RP_ALERT`` frame as a receiver sees it (SI units; None: not available)."""

    t_rx_s: float  #: reception time stamp of the frame, s
    counter: int  #: E2E alive counter
    alert_id: int  #: the alert's 8-bit id (unique among the active alerts)
    distance_m: float | None  #: the ego's front axle to the anomaly now (negative: passed)
    time_to_arrival_s: float | None  #: from this frame, at the current speed
    height_mm: float | None  #: bump +, pothole -
    length_m: float | None  #: along the road
    side: Side
    confidence: float | None  #: 0..1
    mode: FusionMode

    @property
    def arrival_t_s(self) -> float | None:
        """When the ego's front axle reaches the anomaly, on the receiver's clock (None if
        unknown)."""
        return None if self.time_to_arrival_s is None else self.t_rx_s + self.time_to_arrival_s


@dataclass(frozen=True, slots=True)
class ReceivedAlertDetail:
    """An ``RP_ALERT_DETAIL`` frame as a receiver sees it (SI units; None: not available)."""

    t_rx_s: float
    counter: int
    alert_id: int  #: the ``RP_ALERT`` it details (sequence number modulo 256)
    detector: str  #: "std" or "two-axle" (``anomaly.detector``)
    height_std_mm: float | None
    score: float | None  #: the detector's score (std: px; two-axle: background stds)
    lead_speed_mps: float | None
    crossing_age_s: float | None  #: since the lead crossed the anomaly
    #: PROVISIONAL or CONFIRMED (``AlertState``; a version-1 DBC or sender: CONFIRMED)
    state: AlertState = AlertState.CONFIRMED


@dataclass(frozen=True, slots=True)
class ReceivedAlertEnd:
    """An ``RP_ALERT_END`` frame as a receiver sees it (SI units; None: not available)."""

    t_rx_s: float
    counter: int
    alert_id: int  #: the alert that ended (8-bit id)
    reason: EndReason
    #: the full cause: ``EndCauseEx`` when it is not NONE, else ``EndCause`` (a version-1
    #: sender or DBC); NOT_CONFIRMED only from ``EndCauseEx``
    cause: EndCause
    sends: int  #: RP_ALERT frames sent for the alert (saturates at 255)
    distance_m: float | None  #: the front axle to the anomaly then (negative: passed)


@dataclass(frozen=True, slots=True)
class ReceivedConfirm:
    """An ``RP_CONFIRM`` frame as a receiver sees it (SI units; None: not available)."""

    t_rx_s: float
    counter: int
    alert_id: int  #: the alert checked (sequence number modulo 256)
    outcome: Confirmation
    peak_mps2: float | None  #: the ego's peak vertical acceleration at the spot
    background_mps2: float | None  #: the ego's background level then
    arrival_age_s: float | None  #: from the front axle's arrival at the spot to the frame
    precision: float | None  #: running precision after this outcome, 0..1

    @property
    def t_arrival_s(self) -> float | None:
        """When the ego's front axle reached the spot, on the receiver's clock (None if not)."""
        return None if self.arrival_age_s is None else self.t_rx_s - self.arrival_age_s


@dataclass(frozen=True, slots=True)
class ReceivedStatus:
    """An ``RP_STATUS`` frame as a receiver sees it (SI units; None: not available)."""

    t_rx_s: float
    counter: int
    mode: FusionMode
    suppressed: SuppressionReason
    pitch_rad: float | None
    gyro_bias_rad_s: float | None
    texture_quality: float | None  #: 0..1
    time_offset_s: float | None
    alert_count: int  #: alerts sent, modulo 16
    input_errors: int  #: input frames dropped in the last period (saturates at 15)
    heartbeat: int  #: camera frames processed, modulo 8


@dataclass(frozen=True, slots=True)
class ReceivedRoadStatus:
    """An ``RP_ROAD_STATUS`` frame as a receiver sees it (SI units; None: not available)."""

    t_rx_s: float
    counter: int
    iso_class: str | None  #: reported ISO 8608 class "A".."H"
    ego_class: str | None  #: from the ego's vertical acceleration
    lead_class: str | None  #: from the lead's motion (the road ahead)
    ego_gd_n0: float | None  #: G_d(n0) of the road under the ego, m³
    lead_gd_n0: float | None  #: G_d(n0) of the road ahead, m³
    precision: float | None  #: online precision of the checked alerts, 0..1
    confirmed: int  #: confirmed alerts, modulo 256
    not_felt: int  #: not-felt alerts, modulo 256


@dataclass(frozen=True, slots=True)
class ReceivedInputStatus:
    """An ``RP_INPUT_STATUS`` frame as a receiver sees it: input problems of the last period."""

    t_rx_s: float
    counter: int
    degraded: bool  #: samples were rejected in the period
    counts: dict[str, int]  #: signal (`INPUT_STATUS_GROUPS`) -> count, saturating at 255


@dataclass(frozen=True, slots=True)
class ReceivedPreviewHeader:
    """The header page (0) of one ``RP_PREVIEW`` snapshot (SI units; NaN: not available)."""

    t_rx_s: float
    counter: int
    cycle: int  #: ``PreviewCycle``: the same on every page of the snapshot, 0..3
    bins: int  #: bins per track
    sides: bool  #: two tracks (left, then right) or one
    bin_m: float  #: bin length, m
    start_m: float  #: near edge of bin 0 ahead of the ego's front axle, m
    lead_rear_axle_m: float  #: the lead's rear axle ahead of the ego's front axle, m
    age_s: float  #: from the preview's camera frame to this frame, s

    @property
    def pages(self) -> int:
        """Bin pages of the snapshot (the header not counted)."""
        per_track = -(-self.bins // PREVIEW_BINS_PER_PAGE)
        return per_track * (2 if self.sides else 1)

    @property
    def t_preview_s(self) -> float:
        """When the preview was as of, on the receiver's clock (the frame's time if the age is
        not available)."""
        return self.t_rx_s - (self.age_s if math.isfinite(self.age_s) else 0.0)


@dataclass(frozen=True, slots=True)
class ReceivedPreviewPage:
    """One bin page (1..) of an ``RP_PREVIEW`` snapshot: 4 bins, NaN where not available."""

    t_rx_s: float
    counter: int
    cycle: int  #: ``PreviewCycle`` of the snapshot
    page: int  #: ``PreviewPage``, 1..60
    height_m: tuple[float, ...]  #: the 4 bins' heights, m (NaN: no estimate)
    std_m: tuple[float, ...]  #: their standard deviations, m (NaN where the height is)


#: what `OutputDecoder.decode` gives for a good frame
ReceivedOutput = (
    ReceivedAlert
    | ReceivedAlertDetail
    | ReceivedAlertEnd
    | ReceivedConfirm
    | ReceivedStatus
    | ReceivedRoadStatus
    | ReceivedInputStatus
    | ReceivedPreviewHeader
    | ReceivedPreviewPage
)
_OUTPUTS = (
    RP_ALERT,
    RP_ALERT_DETAIL,
    RP_ALERT_END,
    RP_CONFIRM,
    RP_STATUS,
    RP_ROAD_STATUS,
    RP_INPUT_STATUS,
    RP_PREVIEW,
)
#: outputs a DBC of version 1 does not have: decoded when the DBC has them
_OUTPUTS_V2 = (RP_PREVIEW,)


class OutputDecoder:
    """Decode roadpreview's output frames; CRC and counter checked, bad frames counted.

    ``decode`` returns None for a frame that is not one of roadpreview's outputs
    (``RP_ALERT``, ``RP_ALERT_DETAIL``, ``RP_ALERT_END``, ``RP_CONFIRM``, ``RP_STATUS``,
    ``RP_ROAD_STATUS``, ``RP_INPUT_STATUS``, ``RP_PREVIEW``) or fails a check; ``problems``
    counts the reasons (``crc``, ``length``, ``counter_repeated``, ``undecodable``: an
    unknown ``PreviewPage``) and ``lost`` the frames a counter jump says were missed. ``db``
    may be a DBC of version 1 (module docstring).
    """

    def __init__(self, db: Database | None = None) -> None:
        self.db = db or load_database()
        names = {m.name for m in self.db.messages}
        self._messages = {
            m.frame_id: m
            for m in (
                self.db.get_message_by_name(n)
                for n in _OUTPUTS
                if n in names or n not in _OUTPUTS_V2
            )
        }
        self._layouts = {fid: e2e_layout(m) for fid, m in self._messages.items()}
        self._last_counter: dict[int, int] = {}
        self.problems: Counter[str] = Counter()
        self.lost = 0

    def _check(self, msg: can.Message) -> tuple[MessageDef, dict[str, object], int] | None:
        m = self._messages.get(msg.arbitration_id)
        if m is None or msg.is_extended_id:
            return None
        data = bytes(msg.data)
        if len(data) != m.length:
            self.problems["length"] += 1
            return None
        layout = self._layouts[m.frame_id]
        if not e2e.p01.e2e_p01_check(bytearray(data), layout.data_id):
            self.problems["crc"] += 1
            return None
        counter = data[1] & 0x0F  # the E2E P01 counter: bits 8..11 (e2e_layout checks this)
        last = self._last_counter.get(m.frame_id)
        if last is not None:
            delta = (counter - last) % E2E_COUNTER_MODULUS
            if delta == 0:
                self.problems["counter_repeated"] += 1
                return None
            self.lost += delta - 1
        self._last_counter[m.frame_id] = counter
        try:
            values = dict(signal_values(m, data))
        except DecodeError:  # a multiplexor value the DBC does not define
            self.problems["undecodable"] += 1
            return None
        return m, values, counter

    def decode(self, msg: can.Message) -> ReceivedOutput | None:
        """The content of one output frame, or None (class docstring)."""
        checked = self._check(msg)
        if checked is None:
            return None
        m, v, counter = checked

        def opt(name: str, factor: float = 1.0) -> float | None:
            x = v[name]
            if isinstance(x, NamedSignalValue):
                return None
            return float(x) * factor  # type: ignore[arg-type]

        def code(name: str) -> int:
            x = v[name]
            return int(x.value) if isinstance(x, NamedSignalValue) else int(x)  # type: ignore[call-overload]

        def iso(name: str) -> str | None:
            k = code(name)
            return ISO8608_CLASSES[k - 1] if 1 <= k <= len(ISO8608_CLASSES) else None

        def gd(name: str) -> float | None:
            level = opt(name)
            return None if level is None else GD_REF_M3 * 10.0 ** (level / 10.0)

        t = float(msg.timestamp)
        if m.name == RP_ALERT:
            return ReceivedAlert(
                t_rx_s=t,
                counter=counter,
                alert_id=code("AlertId"),
                distance_m=opt("AlertDistance"),
                time_to_arrival_s=opt("AlertTimeToArrival"),
                height_mm=opt("AlertHeight"),
                length_m=opt("AlertLength"),
                side=Side(code("AlertSide")),
                confidence=opt("AlertConfidence", 0.01),
                mode=FusionMode(code("AlertFusionMode")),
            )
        if m.name == RP_ALERT_DETAIL:
            detectors = {c: n for n, c in DETECTOR_CODES.items()}
            state = AlertState(code("AlertState")) if "AlertState" in v else AlertState.CONFIRMED
            return ReceivedAlertDetail(
                t_rx_s=t,
                counter=counter,
                alert_id=code("AlertId"),
                detector=detectors.get(code("DetailDetector"), "unknown"),
                height_std_mm=opt("AlertHeightStd"),
                score=opt("AlertScore"),
                lead_speed_mps=opt("AlertLeadSpeed", _KMH),
                crossing_age_s=opt("AlertCrossingAge"),
                state=state,
            )
        if m.name == RP_ALERT_END:
            cause = code("EndCauseEx") if "EndCauseEx" in v else 0
            return ReceivedAlertEnd(
                t_rx_s=t,
                counter=counter,
                alert_id=code("EndAlertId"),
                reason=EndReason(code("EndReason")),
                cause=EndCause(cause or code("EndCause")),
                sends=code("EndAlertSends"),
                distance_m=opt("EndDistance"),
            )
        if m.name == RP_CONFIRM:
            return ReceivedConfirm(
                t_rx_s=t,
                counter=counter,
                alert_id=code("ConfirmAlertId"),
                outcome=Confirmation(code("ConfirmOutcome")),
                peak_mps2=opt("ConfirmPeakAccel"),
                background_mps2=opt("ConfirmBackgroundAccel"),
                arrival_age_s=opt("ConfirmArrivalAge"),
                precision=opt("ConfirmPrecision", 0.01),
            )
        if m.name == RP_INPUT_STATUS:
            return ReceivedInputStatus(
                t_rx_s=t,
                counter=counter,
                degraded=bool(code("InputDegraded")),
                counts={name: code(name) for name in INPUT_STATUS_GROUPS},
            )
        if m.name == RP_PREVIEW:
            return self._preview(v, t, counter)
        if m.name == RP_ROAD_STATUS:
            return ReceivedRoadStatus(
                t_rx_s=t,
                counter=counter,
                iso_class=iso("RoadClass"),
                ego_class=iso("RoadClassEgo"),
                lead_class=iso("RoadClassLead"),
                ego_gd_n0=gd("RoadGdEgo"),
                lead_gd_n0=gd("RoadGdLead"),
                precision=opt("OnlinePrecision", 0.01),
                confirmed=code("ConfirmedCount"),
                not_felt=code("NotFeltCount"),
            )
        return ReceivedStatus(
            t_rx_s=t,
            counter=counter,
            mode=FusionMode(code("StatusFusionMode")),
            suppressed=SuppressionReason(code("StatusSuppression")),
            pitch_rad=opt("StatusPitch", _DEG),
            gyro_bias_rad_s=opt("StatusGyroBias", _DEG),
            texture_quality=opt("StatusTextureQuality", 0.01),
            time_offset_s=opt("StatusTimeOffset", 1e-3),
            alert_count=code("StatusAlertCount"),
            input_errors=code("StatusInputErrors"),
            heartbeat=code("StatusHeartbeat"),
        )

    @staticmethod
    def _preview(
        v: dict[str, object], t: float, counter: int
    ) -> ReceivedPreviewHeader | ReceivedPreviewPage:
        """One ``RP_PREVIEW`` page (its signals ``v`` as cantools decoded them)."""

        def num(name: str, factor: float = 1.0) -> float:
            x = v[name]
            return math.nan if isinstance(x, NamedSignalValue) else float(x) * factor  # type: ignore[arg-type]

        def code(name: str) -> int:
            x = v[name]
            return int(x.value) if isinstance(x, NamedSignalValue) else int(x)  # type: ignore[call-overload]

        page, cycle = code("PreviewPage"), code("PreviewCycle")
        if page == 0:
            return ReceivedPreviewHeader(
                t_rx_s=t,
                counter=counter,
                cycle=cycle,
                bins=code("PreviewBins"),
                sides=bool(code("PreviewSides")),
                bin_m=num("PreviewBinLength"),
                start_m=num("PreviewStart"),
                lead_rear_axle_m=num("PreviewLeadRearAxle"),
                age_s=num("PreviewAge"),
            )
        height = tuple(num(f"PreviewHeight{i}", 1e-3) for i in range(PREVIEW_BINS_PER_PAGE))
        std = tuple(
            math.nan if math.isnan(h) else num(f"PreviewStd{i}", 1e-3) for i, h in enumerate(height)
        )
        return ReceivedPreviewPage(t, counter, cycle, page, height, std)


__all__ = [
    "OutputDecoder",
    "ReceivedAlert",
    "ReceivedAlertDetail",
    "ReceivedAlertEnd",
    "ReceivedConfirm",
    "ReceivedInputStatus",
    "ReceivedOutput",
    "ReceivedPreviewHeader",
    "ReceivedPreviewPage",
    "ReceivedRoadStatus",
    "ReceivedStatus",
]
