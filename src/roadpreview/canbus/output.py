"""roadpreview's output messages: ``RP_ALERT`` (per anomaly) and ``RP_STATUS`` (every 100 ms).

`AlertEncoder` and `StatusEncoder` turn an `Alert` / a `Status` into a
``can.Message`` through cantools (physical values in, the DBC does the
bits), with an AUTOSAR E2E profile 1 header: an alive counter per message
(0..14, +1 per frame) and the CRC from ``autosar-e2e``. Values outside a
signal's range saturate at its limits (the DBC comments say so); unknown
values go out as ``SignalNotAvailable``. `OutputDecoder` is the receiving
side (the chassis ECU, a test, a monitor): it checks CRC and counter and
gives `ReceivedAlert` / `ReceivedStatus` in SI units, None for "not
available".
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import can
import e2e.p01
from cantools.database.can import Database
from cantools.database.can import Message as MessageDef
from cantools.database.namedsignalvalue import NamedSignalValue

from roadpreview.anomaly.alert import Alert
from roadpreview.anomaly.base import Side, SuppressionReason
from roadpreview.canbus.dbc import (
    E2E_COUNTER_MODULUS,
    RP_ALERT,
    RP_STATUS,
    e2e_layout,
    encode_protected,
    load_database,
)
from roadpreview.canbus.decode import signal_values
from roadpreview.errors import InputDataError
from roadpreview.fusion.mode import FusionMode

log = logging.getLogger(__name__)

SIGNAL_NOT_AVAILABLE = "SignalNotAvailable"
_DEG = math.pi / 180.0


@dataclass(frozen=True, slots=True)
class Status:
    """What ``RP_STATUS`` reports; None: not available."""

    mode: FusionMode  #: current fusion mode
    pitch_rad: float | None = None  #: fused camera pitch, nose up +, rad
    gyro_bias_rad_s: float | None = None  #: estimated gyro pitch-rate bias, rad/s
    texture_quality: float | None = None  #: background texture quality, 0..1
    time_offset_s: float | None = None  #: IMU stamp minus camera stamp, s
    suppressed: SuppressionReason = SuppressionReason.NONE  #: why alerts are held back now
    alerts_sent: int = 0  #: alerts sent since start
    #: input frames dropped since start; the encoder sends the increase since its last frame
    input_errors_total: int = 0
    frames_processed: int = 0  #: camera frames processed since start


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
    """`Alert` -> ``RP_ALERT`` frame (module docstring)."""

    def __init__(self, db: Database | None = None, *, channel: int | str | None = None) -> None:
        super().__init__(RP_ALERT, db, channel)

    def values(self, alert: Alert) -> dict[str, float | int | str]:
        """The physical signal values (before E2E) of ``alert``."""
        age = alert.t_emit_s - alert.t_s
        return {
            "AlertSide": int(alert.side),
            "AlertFusionMode": int(alert.mode),
            "AlertDistance": self._fit("AlertDistance", alert.distance_m),
            "AlertTimeToArrival": self._fit("AlertTimeToArrival", alert.time_to_arrival_s),
            "AlertSeverity": self._fit("AlertSeverity", alert.severity_px),
            "AlertHeight": self._fit("AlertHeight", alert.height_mm),
            "AlertConfidence": self._fit("AlertConfidence", 100.0 * alert.confidence),
            "AlertEventAge": self._fit("AlertEventAge", age if age >= 0 else None),
        }

    def encode(self, alert: Alert, *, timestamp: float | None = None) -> can.Message:
        """The next ``RP_ALERT`` frame (time stamp: ``timestamp``, default the alert's emission)."""
        ts = alert.t_emit_s if timestamp is None else timestamp
        return self._frame(self.values(alert), float(ts))


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

        def scaled(x: float | None, factor: float) -> float | None:
            return None if x is None else x * factor

        return {
            "StatusFusionMode": int(status.mode),
            "StatusSuppression": int(status.suppressed) & 0b111,
            "StatusPitch": self._fit("StatusPitch", scaled(status.pitch_rad, 1 / _DEG)),
            "StatusGyroBias": self._fit("StatusGyroBias", scaled(status.gyro_bias_rad_s, 1 / _DEG)),
            "StatusTextureQuality": self._fit(
                "StatusTextureQuality", scaled(status.texture_quality, 100.0)
            ),
            "StatusTimeOffset": self._fit("StatusTimeOffset", scaled(status.time_offset_s, 1e3)),
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


def alert_frames(alerts: Iterable[Alert], encoder: AlertEncoder | None = None) -> list[can.Message]:
    """``RP_ALERT`` frames of ``alerts`` at their emission times (for `write_can_log`)."""
    enc = encoder or AlertEncoder()
    return [enc.encode(a) for a in alerts]


# --- receiving ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReceivedAlert:
    """An ``RP_ALERT`` frame as a receiver sees it (SI units; None: not available)."""

    t_rx_s: float  #: reception time stamp of the frame, s
    counter: int  #: E2E alive counter
    distance_m: float | None
    time_to_arrival_s: float | None
    event_age_s: float | None
    severity_px: float
    height_mm: float | None
    side: Side
    confidence: float  #: 0..1
    mode: FusionMode

    @property
    def time_left_s(self) -> float | None:
        """Time from this frame until the ego reaches the anomaly (None if unknown)."""
        if self.time_to_arrival_s is None or self.event_age_s is None:
            return None
        return self.time_to_arrival_s - self.event_age_s


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


class OutputDecoder:
    """Decode roadpreview's output frames; CRC and counter checked, bad frames counted.

    ``decode`` returns None for a frame that is not ``RP_ALERT`` / ``RP_STATUS``
    or fails a check; ``problems`` counts the reasons (``crc``, ``length``,
    ``counter_repeated``) and ``lost`` the frames a counter jump says were
    missed.
    """

    def __init__(self, db: Database | None = None) -> None:
        self.db = db or load_database()
        self._messages = {
            m.frame_id: m for m in (self.db.get_message_by_name(n) for n in (RP_ALERT, RP_STATUS))
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
        return m, dict(signal_values(m, data)), counter

    def decode(self, msg: can.Message) -> ReceivedAlert | ReceivedStatus | None:
        """The content of one output frame, or None (module docstring)."""
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

        t = float(msg.timestamp)
        if m.name == RP_ALERT:
            return ReceivedAlert(
                t_rx_s=t,
                counter=counter,
                distance_m=opt("AlertDistance"),
                time_to_arrival_s=opt("AlertTimeToArrival"),
                event_age_s=opt("AlertEventAge"),
                severity_px=float(opt("AlertSeverity") or 0.0),
                height_mm=opt("AlertHeight"),
                side=Side(code("AlertSide")),
                confidence=float(opt("AlertConfidence", 0.01) or 0.0),
                mode=FusionMode(code("AlertFusionMode")),
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
