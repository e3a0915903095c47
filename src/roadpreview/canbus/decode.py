"""Decode any car's CAN frames into typed IMU and speed samples, through a DBC and a mapping.

`CanInputDecoder(db, mapping)` turns each ``can.Message`` into zero or more
`ImuSample` / `SpeedSample` (``roadpreview.canbus.samples``) in SI units and
roadpreview's sign conventions. **A bad frame never stops the stream**: a
frame with an unknown ID, a wrong length, a failed integrity check (AUTOSAR
E2E P01 CRC or the Toyota checksum), a repeated alive counter, a time stamp
that does not advance, or a value outside its plausible range is counted in
`DecodeStats`, logged once per kind, and skipped; the next frame is decoded
as if nothing happened. A value the sender flags "not available" (a
``SignalNotAvailable`` choice) becomes NaN and is counted too.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Literal, cast

import can
import e2e.p01
from cantools.database.can import Database
from cantools.database.can import Message as MessageDef
from cantools.database.namedsignalvalue import NamedSignalValue

from roadpreview.canbus.dbc import E2E_COUNTER_MODULUS, E2ELayout, e2e_layout
from roadpreview.canbus.logio import CanLogReader, channel_number
from roadpreview.canbus.mapping import BoundMapping, BoundQuantity, InputMapping, bind_mapping
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.types import ImuSample, InputSample, SpeedSample

log = logging.getLogger(__name__)

#: choice names that mean "no value" (compared in lower case without "_")
NOT_AVAILABLE_NAMES = frozenset({"signalnotavailable", "sna", "notavailable", "invalid"})

_RATES = ("roll_rate", "pitch_rate", "yaw_rate")
_ACCEL = ("accel_x", "accel_y", "accel_z")


class FrameProblem(str, Enum):
    """Why a frame was skipped."""

    UNKNOWN_ID = "unknown_id"  #: the DBC has no message with this ID
    WRONG_LENGTH = "wrong_length"  #: payload length differs from the DBC's
    INTEGRITY = "integrity"  #: E2E CRC, checksum or counter value wrong
    COUNTER_REPEATED = "counter_repeated"  #: E2E alive counter did not advance
    TIME_NOT_INCREASING = "time_not_increasing"  #: not later than the previous frame of its ID
    OUT_OF_RANGE = "out_of_range"  #: a value outside its plausible range
    DECODE_ERROR = "decode_error"  #: cantools could not decode the payload
    NOT_DATA_FRAME = "not_data_frame"  #: error or remote frame


@dataclass
class DecodeStats:
    """Counts of what happened to the frames given to a decoder."""

    frames: int = 0  #: frames seen
    used: int = 0  #: frames that gave samples
    ignored: int = 0  #: frames not for us: other channel, unmapped message, ignored unknown ID
    #: frames missing between used frames according to their E2E counters (frames that never
    #: arrived, and frames skipped here for a problem)
    lost: int = 0
    not_available: int = 0  #: values flagged not available by their sender (NaN in the samples)
    problems: Counter[FrameProblem] = field(default_factory=Counter)  #: skipped frames by reason

    @property
    def skipped(self) -> int:
        """Frames skipped because of a problem."""
        return sum(self.problems.values())

    def summary(self) -> str:
        """One line for logs and reports."""
        probs = ", ".join(f"{k.value} {v}" for k, v in sorted(self.problems.items()))
        return (
            f"{self.frames} frames: {self.used} used, {self.ignored} ignored, {self.skipped}"
            f" skipped ({probs or 'none'}), {self.lost} lost (E2E counter),"
            f" {self.not_available} values not available"
        )


def toyota_checksum_ok(frame_id: int, data: bytes | bytearray) -> bool:
    """Toyota's checksum: last byte = (ID bytes + length + the other bytes) mod 256."""
    if not data:
        return False
    total = (frame_id & 0xFF) + ((frame_id >> 8) & 0xFF) + len(data) + sum(data[:-1])
    return (total & 0xFF) == data[-1]


@dataclass
class _Plan:
    """How to decode one mapped frame ID."""

    quantities: list[BoundQuantity]
    integrity: str
    e2e: E2ELayout | None
    last_counter: int | None = None
    last_t: float = -math.inf


def signal_values(
    message: MessageDef, data: bytes, *, decode_choices: bool = True
) -> Mapping[str, Any]:
    """cantools' decode of a plain (not container) message: signal name -> physical value."""
    return cast(
        "Mapping[str, Any]",
        message.decode(data, decode_choices=decode_choices, scaling=True),
    )


def _not_available(value: NamedSignalValue) -> bool:
    return str(value.name).lower().replace("_", "") in NOT_AVAILABLE_NAMES


class CanInputDecoder:
    """Frames in, `ImuSample` / `SpeedSample` out; bad frames counted and skipped (module doc)."""

    def __init__(self, db: Database, mapping: InputMapping, *, db_name: str = "the DBC") -> None:
        self.db = db
        self.db_name = db_name  #: the DBC's name, for messages
        self.mapping = mapping
        self.bound: BoundMapping = bind_mapping(mapping, db, db_name=db_name)
        self.stats = DecodeStats()
        self._logged: set[FrameProblem] = set()
        self._known_ids = {m.frame_id for m in db.messages}
        self._plans: dict[int, _Plan] = {}
        for fid, quantities in self.bound.by_frame_id.items():
            message = quantities[0].message
            integrity = mapping.integrity_of(message.name)
            layout = None
            if integrity == "e2e_p01":
                try:
                    layout = e2e_layout(message)
                except InputDataError as exc:
                    raise ConfigError(f"{mapping.source}: integrity e2e_p01: {exc}") from None
            self._plans[fid] = _Plan(quantities, integrity, layout)

    @property
    def missing(self) -> dict[str, str]:
        """Quantities this car does not provide, with the mapping's reason."""
        return self.mapping.missing

    def _problem(self, kind: FrameProblem, msg: can.Message, detail: str) -> list[InputSample]:
        self.stats.problems[kind] += 1
        if kind not in self._logged:
            self._logged.add(kind)
            log.warning(
                "CAN frame 0x%X at %.6f s skipped: %s (%s); further frames of this kind are"
                " only counted",
                msg.arbitration_id,
                msg.timestamp,
                kind.value,
                detail,
            )
        return []

    def _check_integrity(self, plan: _Plan, msg: can.Message, data: bytes) -> str:
        """'' if fine, else the reason; updates the E2E counter state."""
        if plan.integrity == "toyota_checksum":
            return "" if toyota_checksum_ok(msg.arbitration_id, data) else "Toyota checksum"
        if plan.e2e is None:
            return ""
        if not e2e.p01.e2e_p01_check(bytearray(data), plan.e2e.data_id):
            return f"E2E P01 CRC (data ID 0x{plan.e2e.data_id:04X})"
        counter = data[1] & 0x0F
        if counter >= E2E_COUNTER_MODULUS:
            return f"E2E counter {counter} (0..14 only)"
        return ""

    def decode(self, msg: can.Message) -> list[InputSample]:
        """The samples of one frame (often none); never raises for a bad frame."""
        st = self.stats
        st.frames += 1
        if msg.is_error_frame or msg.is_remote_frame:
            return self._problem(FrameProblem.NOT_DATA_FRAME, msg, "error or remote frame")
        want = self.mapping.header.channel
        if want is not None and msg.channel is not None and channel_number(msg.channel) != want:
            st.ignored += 1
            return []
        fid = msg.arbitration_id
        plan = self._plans.get(fid)
        if plan is None:
            if fid in self._known_ids or self.mapping.header.ignore_unknown_ids:
                st.ignored += 1
                return []
            return self._problem(FrameProblem.UNKNOWN_ID, msg, "not in the DBC")
        message = plan.quantities[0].message
        data = bytes(msg.data)
        if len(data) != message.length:
            return self._problem(
                FrameProblem.WRONG_LENGTH,
                msg,
                f"{message.name}: {len(data)} bytes, the DBC says {message.length}",
            )
        t = float(msg.timestamp)
        if not t > plan.last_t:
            return self._problem(
                FrameProblem.TIME_NOT_INCREASING,
                msg,
                f"{message.name}: {t:.6f} s, previous {plan.last_t:.6f} s",
            )
        reason = self._check_integrity(plan, msg, data)
        if reason:
            return self._problem(FrameProblem.INTEGRITY, msg, f"{message.name}: {reason}")
        counter = None
        gap = 0
        if plan.e2e is not None:
            counter = data[1] & 0x0F
            if plan.last_counter is not None:
                delta = (counter - plan.last_counter) % E2E_COUNTER_MODULUS
                if delta == 0:
                    return self._problem(
                        FrameProblem.COUNTER_REPEATED, msg, f"{message.name}: counter {counter}"
                    )
                gap = delta - 1
        try:
            decoded = signal_values(message, data)
        except Exception as exc:  # cantools raises several types for a payload it cannot take
            return self._problem(FrameProblem.DECODE_ERROR, msg, f"{message.name}: {exc}")
        values: dict[str, float] = {}
        not_available = 0
        for bq in plan.quantities:
            raw = decoded[bq.signal.name]
            if isinstance(raw, NamedSignalValue):
                if _not_available(raw):
                    values[bq.quantity] = math.nan
                    not_available += 1
                    continue
                scaled: Any = bq.signal.conversion.raw_to_scaled(raw.value, False)
                physical = float(scaled)
            else:
                physical = float(raw)
            value, ok = bq.convert(physical)
            if not ok:
                rng = bq.spec.range if bq.spec.range is not None else bq.dbc_range
                return self._problem(
                    FrameProblem.OUT_OF_RANGE,
                    msg,
                    f"{message.name}.{bq.signal.name} = {physical:g} {bq.signal.unit or ''}"
                    f" (mapped {bq.spec.sign * (bq.spec.scale * physical + bq.spec.offset):g}"
                    f" {bq.spec.unit}; range {list(rng) if rng else '?'})",
                )
            values[bq.quantity] = value
        plan.last_t = t
        if counter is not None:
            plan.last_counter = counter
        st.lost += gap
        st.used += 1
        st.not_available += not_available
        out: list[InputSample] = []
        if any(q in values for q in _RATES + _ACCEL):
            rates = tuple(values.get(q, math.nan) for q in _RATES)
            accel = tuple(values.get(q, math.nan) for q in _ACCEL)
            sample = ImuSample(t, rates, accel, message.name)  # type: ignore[arg-type]
            mount = self.mapping.mount  # a calibrated IMU: into the body axes, camera clock
            out.append(sample if mount is None else mount.apply_sample(sample))
        if "speed" in values:
            out.append(SpeedSample(t, values["speed"], message.name))
        return out

    def decode_all(self, messages: Iterable[can.Message]) -> Iterator[InputSample]:
        """Decode a stream of frames, yielding samples in frame order."""
        for msg in messages:
            yield from self.decode(msg)


def decode_log(
    path: str | Path,
    decoder: CanInputDecoder,
    *,
    errors: Literal["log", "raise"] = "log",
) -> Iterator[InputSample]:
    """Samples of a CAN log file (any format `CanLogReader` reads) through ``decoder``."""
    yield from decoder.decode_all(CanLogReader(path, errors=errors))


def split_samples(
    samples: Iterable[InputSample],
) -> tuple[list[ImuSample], list[SpeedSample]]:
    """Separate a decoded stream into IMU and speed samples (order kept)."""
    imu: list[ImuSample] = []
    speed: list[SpeedSample] = []
    for s in samples:
        (imu if isinstance(s, ImuSample) else speed).append(s)  # type: ignore[arg-type]
    return imu, speed


__all__ = [
    "CanInputDecoder",
    "DecodeStats",
    "FrameProblem",
    "decode_log",
    "split_samples",
    "toyota_checksum_ok",
]
