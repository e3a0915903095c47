"""roadpreview's output messages: per active alert and period ``RP_ALERT`` +
``RP_ALERT_DETAIL``, at its end ``RP_ALERT_END``, per checked alert ``RP_CONFIRM``,
every 100 ms ``RP_STATUS`` + ``RP_ROAD_STATUS``, and per road preview the pages of
``RP_PREVIEW`` (`PreviewEncoder`).

`AlertEncoder`, `AlertDetailEncoder`, `AlertEndEncoder`, `ConfirmEncoder`,
`StatusEncoder`, `RoadStatusEncoder` and `PreviewEncoder` turn an `AlertSend` (an alert as
of one send, `roadpreview.canbus.repetition`) / an `AlertEnd` / a `ConfirmationResult` / a
`Status` / a `RoadPreview` into ``can.Message``s through cantools (physical values in,
the DBC does the bits), with an AUTOSAR E2E profile 1 header: an alive counter per
message (0..14, +1 per frame) and the CRC from ``autosar-e2e``. Values
outside a signal's range saturate at its limits (the DBC comments say so);
unknown values go out as ``SignalNotAvailable``. The receiving side is
`roadpreview.canbus.received` (`OutputDecoder`, frame by frame) and
`roadpreview.canbus.receiver` (`AlertReceiver`, `PreviewAssembler`).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping

import can
import numpy as np
from cantools.database.can import Database
from cantools.database.can import Message as MessageDef
from numpy.typing import NDArray

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
    encode_protected,
    load_database,
)
from roadpreview.canbus.repetition import AlertEnd, AlertSend, EndCause
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.types import (
    ISO8608_CLASSES,
    Alert,
    ConfirmationResult,
    RoadPreview,
    RoadState,
    Status,
)

log = logging.getLogger(__name__)

SIGNAL_NOT_AVAILABLE = "SignalNotAvailable"
_DEG = math.pi / 180.0
_KMH = 1.0 / 3.6  #: m/s per km/h
#: ``DetailDetector`` code of each detector name (``anomaly.detector``)
DETECTOR_CODES = {"std": 0, "two-axle": 1}
#: reference of the G_d(n0) levels on CAN: 10 log10(G_d(n0) / 1e-6 m³)
GD_REF_M3 = 1e-6
#: the largest cause the 2-bit ``RP_ALERT_END.EndCause`` carries (version 1); a larger one
#: goes out as NONE there and in full in ``EndCauseEx``
END_CAUSE_V1_MAX = EndCause.OVERFLOW

# RP_PREVIEW (docs/can-interface.md): page 0 the header, pages 1.. four bins each
#: bins per ``RP_PREVIEW`` page (``PreviewHeight0..3`` / ``PreviewStd0..3``)
PREVIEW_BINS_PER_PAGE = 4
#: most bins per track in one snapshot (``PreviewBins`` maximum): 60 m at 0.5 m, so that two
#: tracks fit the 6-bit ``PreviewPage`` (1 + 2 x 30 = 61 pages)
PREVIEW_MAX_BINS = 120
#: ``PreviewCycle`` runs 0..3, +1 per snapshot
PREVIEW_CYCLE_MODULUS = 4
#: ``PreviewHeight*`` step and its raw range; raw -128 is "no valid estimate"
PREVIEW_HEIGHT_LSB_MM = 2.0
PREVIEW_HEIGHT_RAW_MAX = 127
#: ``PreviewStd*`` step and its raw maximum (7: at least 28 mm; also sent for a bin without
#: an estimate)
PREVIEW_STD_LSB_MM = 4.0
PREVIEW_STD_RAW_MAX = 7


class _ProtectedEncoder:
    """Encode one E2E-protected message of the DBC, with its alive counter."""

    def __init__(self, name: str, db: Database | None, channel: int | str | None) -> None:
        self.db = db or load_database()
        self.message: MessageDef = self.db.get_message_by_name(name)
        self.layout = e2e_layout(self.message)
        self.channel = channel
        self.counter = 0  #: alive counter of the next frame (0..14)
        self.saturated: Counter[str] = Counter()  #: values clipped to a signal's range, by signal

    def _fit(self, signal: str, value: float | None) -> float | str:
        """Physical value in range, or SignalNotAvailable for None / NaN."""
        sig = self.message.get_signal_by_name(signal)
        if value is None or not math.isfinite(value):
            if sig.choices is None or SIGNAL_NOT_AVAILABLE not in map(str, sig.choices.values()):
                raise InputDataError(f"{self.message.name}.{signal}: a value is required")
            return SIGNAL_NOT_AVAILABLE
        lo = float(sig.minimum) if sig.minimum is not None else -math.inf
        hi = float(sig.maximum) if sig.maximum is not None else math.inf
        if not lo <= value <= hi:
            self.saturated[signal] += 1
            log.debug("%s.%s = %g saturates at [%g, %g]", self.message.name, signal, value, lo, hi)
            value = min(max(value, lo), hi)
        return value

    def _frame(self, values: Mapping[str, float | int | str], timestamp: float) -> can.Message:
        data = encode_protected(self.message, values, self.counter, layout=self.layout)
        self.counter = (self.counter + 1) % E2E_COUNTER_MODULUS
        return can.Message(
            timestamp=timestamp,
            arbitration_id=self.message.frame_id,
            is_extended_id=False,
            dlc=self.message.length,
            data=data,
            channel=self.channel,
            is_rx=False,
        )


class AlertEncoder(_ProtectedEncoder):
    """`AlertSend` -> ``RP_ALERT`` frame (module docstring). An `Alert` is sent as at its
    emission (`AlertSend.at_emission`)."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_ALERT, db, channel)

    def values(self, send: AlertSend | Alert) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of one send."""
        send = _as_send(send)
        alert = send.alert
        return {
            "AlertSide": int(alert.side),
            "AlertFusionMode": int(alert.mode),
            "AlertId": send.can_id % 256,
            "AlertDistance": self._fit("AlertDistance", send.distance_m),
            "AlertTimeToArrival": self._fit("AlertTimeToArrival", send.time_to_arrival_s),
            "AlertHeight": self._fit("AlertHeight", alert.height_mm),
            "AlertLength": self._fit("AlertLength", alert.length_m),
            "AlertConfidence": self._fit("AlertConfidence", _scaled(alert.confidence, 100.0)),
        }

    def encode(self, send: AlertSend | Alert, *, timestamp: float | None = None) -> can.Message:
        """The next ``RP_ALERT`` frame (time stamp: ``timestamp``, default the send's time)."""
        send = _as_send(send)
        ts = send.t_s if timestamp is None else timestamp
        return self._frame(self.values(send), float(ts))


class AlertDetailEncoder(_ProtectedEncoder):
    """`AlertSend` -> ``RP_ALERT_DETAIL`` frame, sent right after each ``RP_ALERT`` (module
    docstring).

    ``detector`` names the detector that raised the alert (``anomaly.detector``,
    a key of `DETECTOR_CODES`); `Alert` does not say."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_ALERT_DETAIL, db, channel)

    def values(
        self, send: AlertSend | Alert, detector: str = "two-axle"
    ) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of one send's details."""
        send = _as_send(send)
        alert = send.alert
        return {
            "DetailDetector": detector_code(detector),
            "AlertState": int(alert.state),
            "AlertId": send.can_id % 256,
            "AlertHeightStd": self._fit("AlertHeightStd", alert.height_std_mm),
            "AlertScore": self._fit("AlertScore", alert.severity_px),
            "AlertLeadSpeed": self._fit("AlertLeadSpeed", _scaled(alert.lead_speed_mps, 1 / _KMH)),
            "AlertCrossingAge": self._fit(
                "AlertCrossingAge", send.age_s if send.age_s >= 0 else None
            ),
        }

    def encode(
        self,
        send: AlertSend | Alert,
        detector: str = "two-axle",
        *,
        timestamp: float | None = None,
    ) -> can.Message:
        """The next ``RP_ALERT_DETAIL`` frame (time stamp: ``timestamp``, default the send's
        time)."""
        send = _as_send(send)
        ts = send.t_s if timestamp is None else timestamp
        return self._frame(self.values(send, detector), float(ts))


class AlertEndEncoder(_ProtectedEncoder):
    """`AlertEnd` -> ``RP_ALERT_END`` frame (module docstring)."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_ALERT_END, db, channel)

    def values(self, end: AlertEnd) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of ``end``: the full cause in
        ``EndCauseEx``, and in the version-1 ``EndCause`` when it fits (else NONE)."""
        cause = int(end.cause)
        return {
            "EndReason": int(end.reason),
            "EndCause": cause if cause <= END_CAUSE_V1_MAX else int(EndCause.NONE),
            "EndCauseEx": cause,
            "EndAlertId": end.can_id % 256,
            "EndAlertSends": min(max(end.sends, 0), 255),
            "EndDistance": self._fit("EndDistance", end.distance_m),
        }

    def encode(self, end: AlertEnd, *, timestamp: float | None = None) -> can.Message:
        """The next ``RP_ALERT_END`` frame (time stamp: ``timestamp``, default the end's)."""
        ts = end.t_s if timestamp is None else timestamp
        return self._frame(self.values(end), float(ts))


class ConfirmEncoder(_ProtectedEncoder):
    """`ConfirmationResult` -> ``RP_CONFIRM`` frame (module docstring)."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_CONFIRM, db, channel)

    def values(
        self, result: ConfirmationResult, precision: float | None = None, *, t_s: float
    ) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of ``result`` sent at ``t_s``;
        ``precision``: the running precision after it, 0..1 (None: not available)."""
        age = t_s - result.t_arrival_s  # NaN when the spot was not reached
        return {
            "ConfirmOutcome": int(result.outcome),
            "ConfirmAlertId": result.alert_id % 256,
            "ConfirmPeakAccel": self._fit("ConfirmPeakAccel", result.peak_mps2),
            "ConfirmBackgroundAccel": self._fit("ConfirmBackgroundAccel", result.background_mps2),
            "ConfirmArrivalAge": self._fit("ConfirmArrivalAge", age),
            "ConfirmPrecision": self._fit("ConfirmPrecision", _scaled(precision, 100.0)),
        }

    def encode(
        self,
        result: ConfirmationResult,
        precision: float | None = None,
        *,
        timestamp: float | None = None,
    ) -> can.Message:
        """The next ``RP_CONFIRM`` frame (time stamp: ``timestamp``, default when the outcome
        was decided)."""
        ts = float(result.t_s if timestamp is None else timestamp)
        return self._frame(self.values(result, precision, t_s=ts), ts)


class StatusEncoder(_ProtectedEncoder):
    """`Status` -> ``RP_STATUS`` frame (module docstring)."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_STATUS, db, channel)
        self.errors_sent = 0  #: ``input_errors_total`` of the last encoded frame

    def values(self, status: Status) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of ``status`` as the next frame.

        ``StatusInputErrors`` is the increase of ``input_errors_total`` since the last
        frame `encode` made (the DBC's "since the previous status frame"), saturating;
        a total that went down (a restarted pipeline) counts from zero again."""
        return {
            "StatusFusionMode": int(status.mode),
            "StatusSuppression": int(status.suppressed) & 0b111,
            "StatusPitch": self._fit("StatusPitch", _scaled(status.pitch_rad, 1 / _DEG)),
            "StatusGyroBias": self._fit(
                "StatusGyroBias", _scaled(status.gyro_bias_rad_s, 1 / _DEG)
            ),
            "StatusTextureQuality": self._fit(
                "StatusTextureQuality", _scaled(status.texture_quality, 100.0)
            ),
            "StatusTimeOffset": self._fit("StatusTimeOffset", _scaled(status.time_offset_s, 1e3)),
            "StatusAlertCount": status.alerts_sent % 16,
            "StatusInputErrors": min(self._new_errors(status), 15),
            "StatusHeartbeat": status.frames_processed % 8,
        }

    def _new_errors(self, status: Status) -> int:
        total = max(status.input_errors_total, 0)
        return total - self.errors_sent if total >= self.errors_sent else total

    def encode(self, status: Status, *, timestamp: float = 0.0) -> can.Message:
        """The next ``RP_STATUS`` frame."""
        frame = self._frame(self.values(status), float(timestamp))
        self.errors_sent = max(status.input_errors_total, 0)
        return frame


class RoadStatusEncoder(_ProtectedEncoder):
    """`Status` -> ``RP_ROAD_STATUS`` frame, sent with every ``RP_STATUS`` (module docstring)."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_ROAD_STATUS, db, channel)

    def values(self, status: Status) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of ``status``'s road part."""
        road = status.road or RoadState()
        return {
            "RoadClass": road.class_index,
            "RoadClassEgo": _class_code(road.ego_class),
            "RoadClassLead": _class_code(road.lead_class),
            "RoadGdEgo": self._fit("RoadGdEgo", _gd_db(road.ego_gd_n0)),
            "RoadGdLead": self._fit("RoadGdLead", _gd_db(road.lead_gd_n0)),
            "OnlinePrecision": self._fit("OnlinePrecision", _scaled(status.precision, 100.0)),
            "ConfirmedCount": max(status.confirmed, 0) % 256,
            "NotFeltCount": max(status.not_felt, 0) % 256,
        }

    def encode(self, status: Status, *, timestamp: float = 0.0) -> can.Message:
        """The next ``RP_ROAD_STATUS`` frame."""
        return self._frame(self.values(status), float(timestamp))


#: RP_INPUT_STATUS signal -> the problem reasons it counts (`roadpreview.canbus.decode`,
#: `roadpreview.plausibility`); the reasons of a source's ``problems``
INPUT_STATUS_GROUPS: dict[str, tuple[str, ...]] = {
    "InputRangeRejects": ("rejected_range",),
    "InputSpikeRejects": ("rejected_spike",),
    "InputSaturated": ("saturated",),
    "InputE2eErrors": ("e2e_crc", "e2e_counter_stuck", "e2e_counter_jump"),
    "InputFormatErrors": (
        "rejected_id_format",
        "rejected_dlc",
        "unknown_id",
        "decode_error",
        "not_data_frame",
    ),
    "InputStampErrors": ("rejected_stamp", "stamp_jump", "out_of_order", "resynced"),
}
#: reasons that are noted, not rejected: they do not set InputDegraded
_TAKEN_REASONS = frozenset({"e2e_counter_jump", "resynced", "spike_gate_reset"})


class InputStatusEncoder(_ProtectedEncoder):
    """`Status` -> ``RP_INPUT_STATUS`` frame: the input problems of the last period, grouped."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_INPUT_STATUS, db, channel)
        self.sent: dict[str, int] = {}  #: ``input_problems_total`` of the last encoded frame
        self._last_degraded = False

    def due(self, status: Status) -> bool:
        """True when a frame is to be sent with this status period: while the inputs have
        new problems, and once more after they stop (the all-clear frame); a clean drive
        sends none (send type IfActive)."""
        return self._last_degraded or any(n > 0 for n in self._new(status).values())

    def _new(self, status: Status) -> dict[str, int]:
        """Per reason, the increase since the last frame (a total that went down: a restart,
        counted from zero again)."""
        out: dict[str, int] = {}
        for reason, total in status.input_problems_total.items():
            total = max(int(total), 0)
            before = self.sent.get(reason, 0)
            out[reason] = total - before if total >= before else total
        return out

    def values(self, status: Status) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of ``status``'s input part."""
        new = self._new(status)
        values: dict[str, float | int | str] = {
            signal: min(sum(new.get(r, 0) for r in reasons), 255)
            for signal, reasons in INPUT_STATUS_GROUPS.items()
        }
        values["InputDegraded"] = int(any(n > 0 for r, n in new.items() if r not in _TAKEN_REASONS))
        return values

    def encode(self, status: Status, *, timestamp: float = 0.0) -> can.Message:
        """The next ``RP_INPUT_STATUS`` frame."""
        values = self.values(status)
        frame = self._frame(values, float(timestamp))
        self.sent = {r: max(int(v), 0) for r, v in status.input_problems_total.items()}
        self._last_degraded = any(int(v) > 0 for k, v in values.items() if k in INPUT_STATUS_GROUPS)
        return frame


class PreviewEncoder(_ProtectedEncoder):
    """`RoadPreview` -> the ``RP_PREVIEW`` frames of one snapshot: the header (page 0), then
    the bin pages, four bins a page, the left (or only) track's pages first.

    Heights go out in steps of 2 mm (raw -128: no estimate), standard deviations in steps
    of 4 mm up to 28 mm (meaning at least that); both saturate (``saturated``). A track
    longer than ``max_bins`` (at most `PREVIEW_MAX_BINS`) loses its far bins
    (``truncated`` counts the snapshots cut). Every snapshot has the next ``PreviewCycle``
    (0..3); every frame the next E2E alive counter. The receiving side is
    `roadpreview.canbus.receiver.PreviewAssembler`.
    """

    def __init__(
        self,
        db: Database | None = None,
        *,
        channel: int | str | None = None,
        max_bins: int = PREVIEW_MAX_BINS,
    ) -> None:
        super().__init__(RP_PREVIEW, db, channel)
        if not 0 <= max_bins <= PREVIEW_MAX_BINS:
            raise ConfigError(f"PreviewEncoder max_bins = {max_bins}: 0..{PREVIEW_MAX_BINS}")
        self.max_bins = max_bins
        self.cycle = 0  #: ``PreviewCycle`` of the next snapshot (0..3)
        self.truncated = 0  #: snapshots with more than ``max_bins`` bins per track

    def _check(self, preview: RoadPreview) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        height = np.asarray(preview.height_m, dtype=np.float64)
        std = np.asarray(preview.std_m, dtype=np.float64)
        tracks = 2 if preview.sides else 1
        if height.ndim != 2 or height.shape[0] != tracks or std.shape != height.shape:
            raise InputDataError(
                f"RoadPreview.height_m {height.shape} / std_m {std.shape}: both must be"
                f" ({tracks}, bins) for sides={preview.sides}"
            )
        if not (math.isfinite(preview.bin_m) and preview.bin_m > 0):
            raise InputDataError(f"RoadPreview.bin_m = {preview.bin_m}: must be > 0")
        return height, std

    def header_values(
        self, preview: RoadPreview, *, timestamp: float | None = None
    ) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of the header page (page 0), without
        ``PreviewCycle``; ``timestamp``: the frame's time (default the preview's)."""
        height, _ = self._check(preview)
        ts = preview.t_s if timestamp is None else timestamp
        return {
            "PreviewPage": 0,
            "PreviewBins": min(height.shape[1], self.max_bins),
            "PreviewSides": int(preview.sides),
            "PreviewBinLength": self._fit("PreviewBinLength", preview.bin_m),
            "PreviewStart": self._fit("PreviewStart", preview.start_m),
            "PreviewLeadRearAxle": self._fit("PreviewLeadRearAxle", preview.lead_rear_axle_m),
            "PreviewAge": self._fit("PreviewAge", ts - preview.t_s),
        }

    def page_values(self, preview: RoadPreview) -> list[dict[str, float | int | str]]:
        """The physical signal values (before E2E) of the bin pages 1.., in order, without
        ``PreviewCycle``."""
        height, std = self._check(preview)
        n = min(height.shape[1], self.max_bins)
        slots = -(-n // PREVIEW_BINS_PER_PAGE) * PREVIEW_BINS_PER_PAGE  # per track
        h = np.full((height.shape[0], slots), np.nan)
        sd = np.full_like(h, np.nan)
        h[:, :n] = height[:, :n] * 1e3
        sd[:, :n] = std[:, :n] * 1e3
        valid = np.isfinite(h) & np.isfinite(sd)
        h_raw = np.rint(np.where(valid, h, 0.0) / PREVIEW_HEIGHT_LSB_MM)
        sd_raw = np.rint(np.where(valid, sd, math.inf) / PREVIEW_STD_LSB_MM)
        self.saturated["PreviewHeight"] += int(
            np.count_nonzero(valid & (np.abs(h_raw) > PREVIEW_HEIGHT_RAW_MAX))
        )
        self.saturated["PreviewStd"] += int(
            np.count_nonzero(valid & ((sd_raw > PREVIEW_STD_RAW_MAX) | (sd_raw < 0)))
        )
        lim = PREVIEW_HEIGHT_RAW_MAX
        h_mm = np.clip(h_raw, -lim, lim) * PREVIEW_HEIGHT_LSB_MM
        sd_mm = np.clip(sd_raw, 0, PREVIEW_STD_RAW_MAX) * PREVIEW_STD_LSB_MM
        pages: list[dict[str, float | int | str]] = []
        for row in range(0, valid.size, PREVIEW_BINS_PER_PAGE):  # one page per 4 slots
            page: dict[str, float | int | str] = {"PreviewPage": len(pages) + 1}
            for i, k in enumerate(range(row, row + PREVIEW_BINS_PER_PAGE)):
                ok = bool(valid.flat[k])
                page[f"PreviewHeight{i}"] = float(h_mm.flat[k]) if ok else SIGNAL_NOT_AVAILABLE
                page[f"PreviewStd{i}"] = float(sd_mm.flat[k])
            pages.append(page)
        return pages

    def encode(self, preview: RoadPreview, *, timestamp: float | None = None) -> list[can.Message]:
        """The frames of one snapshot, header first (time stamp: ``timestamp``, default the
        preview's time; ``PreviewAge`` is the difference)."""
        ts = float(preview.t_s if timestamp is None else timestamp)
        header = self.header_values(preview, timestamp=ts)
        pages = self.page_values(preview)
        if preview.height_m.shape[1] > self.max_bins:
            self.truncated += 1
            log.debug("RP_PREVIEW: %d bins cut to %d", preview.height_m.shape[1], self.max_bins)
        cycle = self.cycle
        self.cycle = (self.cycle + 1) % PREVIEW_CYCLE_MODULUS
        return [self._frame({**v, "PreviewCycle": cycle}, ts) for v in (header, *pages)]


def preview_page_count(bins: int, sides: bool) -> int:
    """``RP_PREVIEW`` frames of one snapshot with ``bins`` bins per track, the header
    included: 1 + ceil(bins / 4) per track."""
    return 1 + (2 if sides else 1) * -(-bins // PREVIEW_BINS_PER_PAGE)


class OutputEncoders:
    """roadpreview's output messages, encoded from one database for one detector: what a
    run sends per alert and period (RP_ALERT, then RP_ALERT_DETAIL), at an alert's end
    (RP_ALERT_END), per confirmation (RP_CONFIRM), periodically (RP_STATUS,
    RP_ROAD_STATUS) and per road preview (RP_PREVIEW). Shared by the live sender and the
    replay's log so that both send the same frames in the same order."""

    def __init__(self, db: Database | None = None, *, detector: str = "two-axle") -> None:
        detector_code(detector)  # an unknown name fails here, not at the first alert
        self.detector = detector
        self.alert = AlertEncoder(db)
        self.detail = AlertDetailEncoder(self.alert.db)
        self.end = AlertEndEncoder(self.alert.db)
        self.confirm = ConfirmEncoder(self.alert.db)
        self.status = StatusEncoder(self.alert.db)
        self.road = RoadStatusEncoder(self.alert.db)
        self.input = InputStatusEncoder(self.alert.db)
        self.preview = PreviewEncoder(self.alert.db)

    def alert_frames(
        self, send: AlertSend | Alert, *, timestamp: float | None = None
    ) -> list[can.Message]:
        """One send of an alert: its ``RP_ALERT``, then its ``RP_ALERT_DETAIL``."""
        return [
            self.alert.encode(send, timestamp=timestamp),
            self.detail.encode(send, self.detector, timestamp=timestamp),
        ]

    def preview_frames(
        self, preview: RoadPreview, *, timestamp: float | None = None
    ) -> list[can.Message]:
        """One road-preview snapshot: its ``RP_PREVIEW`` pages, header first."""
        return self.preview.encode(preview, timestamp=timestamp)

    def status_frames(self, status: Status, *, timestamp: float = 0.0) -> list[can.Message]:
        """The periodic frames: ``RP_STATUS``, ``RP_ROAD_STATUS``, then ``RP_INPUT_STATUS``
        while the inputs have problems (and once after: `InputStatusEncoder.due`)."""
        return list(self.iter_status_frames(status, timestamp=timestamp))

    def iter_status_frames(
        self, status: Status, *, timestamp: float = 0.0
    ) -> Iterator[can.Message]:
        """`status_frames` one at a time, each encoded when it is asked for (a sender that
        sends each as it comes puts RP_STATUS out before the others are encoded)."""
        yield self.status.encode(status, timestamp=timestamp)
        yield self.road.encode(status, timestamp=timestamp)
        if self.input.due(status):
            yield self.input.encode(status, timestamp=timestamp)


def detector_code(detector: str) -> int:
    """The ``DetailDetector`` code of a detector name; `ConfigError` for a name without one."""
    code = DETECTOR_CODES.get(detector)
    if code is None:
        raise ConfigError(
            f"anomaly.detector = {detector!r}: no DetailDetector code on CAN;"
            f" one of {sorted(DETECTOR_CODES)}"
        )
    return code


def _as_send(send: AlertSend | Alert) -> AlertSend:
    return send if isinstance(send, AlertSend) else AlertSend.at_emission(send)


def _scaled(x: float | None, factor: float) -> float | None:
    return None if x is None else x * factor


def _class_code(iso_class: str | None) -> int:
    """0 unknown, 1..8 = ISO 8608 A..H."""
    return 0 if iso_class is None else ISO8608_CLASSES.index(iso_class) + 1


def _gd_db(gd_n0_m3: float) -> float | None:
    """10 log10(G_d(n0) / 1e-6 m³); None when there is no (positive) estimate."""
    if not (math.isfinite(gd_n0_m3) and gd_n0_m3 > 0):
        return None
    return 10.0 * math.log10(gd_n0_m3 / GD_REF_M3)


def alert_frames(
    alerts: Iterable[Alert],
    encoders: OutputEncoders | None = None,
    *,
    detector: str = "two-axle",
) -> list[can.Message]:
    """``RP_ALERT`` + ``RP_ALERT_DETAIL`` frames of ``alerts`` (two per alert, in that order)
    at their emission times, each sent once as `AlertSend.at_emission` (for
    `write_can_log`; a run repeats them, `roadpreview.sinks.can`); ``detector``:
    ``anomaly.detector`` (when no ``encoders`` are given)."""
    enc = encoders or OutputEncoders(detector=detector)
    return [m for a in alerts for m in enc.alert_frames(a)]
