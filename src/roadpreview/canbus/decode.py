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
from roadpreview.plausibility import (
    REJECTED_SPIKE,
    SPIKE_GATE_RESET,
    PlausibilityConfig,
    SampleGate,
)
from roadpreview.types import ImuSample, InputSample, SpeedSample

log = logging.getLogger(__name__)

#: choice names that mean "no value" (compared in lower case without "_")
NOT_AVAILABLE_NAMES = frozenset({"signalnotavailable", "sna", "notavailable", "invalid"})

_RATES = ("roll_rate", "pitch_rate", "yaw_rate")
_ACCEL = ("accel_x", "accel_y", "accel_z")


class FrameProblem(str, Enum):
    """Why a frame was skipped; the values are the per-source ``problems`` reasons."""

    UNKNOWN_ID = "unknown_id"  #: the DBC has no message with this ID
    ID_FORMAT = "rejected_id_format"  #: a 29-bit frame with an 11-bit message's ID (or reverse)
    WRONG_LENGTH = "rejected_dlc"  #: payload length (DLC) differs from the DBC's
    INTEGRITY = "e2e_crc"  #: E2E CRC, checksum or counter value wrong
    COUNTER_REPEATED = "e2e_counter_stuck"  #: E2E alive counter did not advance
    BAD_STAMP = "rejected_stamp"  #: time stamp not a finite number
    STAMP_JUMP = "stamp_jump"  #: far ahead of its message's previous frame, not yet confirmed
    TIME_NOT_INCREASING = "out_of_order"  #: not later than the previous frame of its ID
    SATURATED = "saturated"  #: a value at its DBC signal's limit (clipped by the sender)
    OUT_OF_RANGE = "rejected_range"  #: a value outside its plausible range
    SPIKE = "rejected_spike"  #: a gyro rate far from its recent history
    DECODE_ERROR = "decode_error"  #: cantools could not decode the payload
    NOT_DATA_FRAME = "not_data_frame"  #: error or remote frame


#: frames taken but noted (not skipped): counter jumps beyond the E2E MaxDeltaCounter, time
#: lines adopted after a backward clock step, spike gates that started their window again
COUNTER_JUMP = "e2e_counter_jump"
RESYNCED = "resynced"


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
    """How to decode one mapped frame ID, and the state of its stream."""

    quantities: list[BoundQuantity]
    integrity: str
    e2e: E2ELayout | None
    #: physical values at the DBC limits of each quantity's signal, and half a step
    saturation: dict[str, tuple[tuple[float, ...], float]]
    max_step_s: float  #: a larger forward step of the stamp waits for confirmation
    last_counter: int | None = None
    last_t: float = -math.inf
    pending_t: float = math.nan  #: stamp of a frame held back after a forward jump
    back_first: float = math.nan  #: first stamp of a run of frames stamped before last_t
    back_last: float = math.nan  #: last stamp of that run


def _saturation_limits(signal: Any) -> tuple[tuple[float, ...], float]:
    """The physical values a signal clips at (its DBC min/max and its raw extremes; zero
    never counts: a sensor rests there), and the tolerance (half a scale step)."""
    scale = float(signal.scale or 1.0)
    offset = float(signal.offset or 0.0)
    n = int(signal.length)
    raw = (-(2 ** (n - 1)), 2 ** (n - 1) - 1) if signal.is_signed else (0, 2**n - 1)
    limits = {r * scale + offset for r in raw}
    lo, hi = signal.minimum, signal.maximum
    if lo is not None and hi is not None and lo < hi:
        limits |= {float(lo), float(hi)}
    return tuple(sorted(v for v in limits if v != 0.0)), abs(scale) / 2.0


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

    def __init__(
        self,
        db: Database,
        mapping: InputMapping,
        *,
        db_name: str = "the DBC",
        plausibility: PlausibilityConfig | None = None,
    ) -> None:
        self.db = db
        self.db_name = db_name  #: the DBC's name, for messages
        self.mapping = mapping
        self.bound: BoundMapping = bind_mapping(mapping, db, db_name=db_name)
        self.stats = DecodeStats()
        #: the physical range and gyro spike gate after the integrity checks
        self.gate = SampleGate(plausibility)
        self.plausibility = self.gate.config
        #: frames taken but noted: e2e_counter_jump, resynced
        self.notes: Counter[str] = Counter()
        self._logged: set[str] = set()
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
            cycle_s = float(message.cycle_time or 0) / 1000.0
            self._plans[fid] = _Plan(
                quantities,
                integrity,
                layout,
                {bq.quantity: _saturation_limits(bq.signal) for bq in quantities},
                max(self.plausibility.stamp_step_max_s, 10.0 * cycle_s),
            )

    @property
    def problems(self) -> Counter[str]:
        """Reason -> count: skipped frames by `FrameProblem` value, plus frames taken but
        noted (``e2e_counter_jump``, ``resynced``, ``spike_gate_reset``)."""
        out: Counter[str] = Counter({k.value: v for k, v in self.stats.problems.items()})
        out.update(self.notes)
        if self.gate.problems[SPIKE_GATE_RESET]:
            out[SPIKE_GATE_RESET] = self.gate.problems[SPIKE_GATE_RESET]
        return out

    @property
    def missing(self) -> dict[str, str]:
        """Quantities this car does not provide, with the mapping's reason."""
        return self.mapping.missing

    def _problem(self, kind: FrameProblem, msg: can.Message, detail: str) -> list[InputSample]:
        self.stats.problems[kind] += 1
        if kind.value not in self._logged:
            self._logged.add(kind.value)
            log.warning(
                "CAN frame 0x%X at %.6f s skipped: %s (%s); further frames of this kind are"
                " only counted",
                msg.arbitration_id,
                msg.timestamp,
                kind.value,
                detail,
            )
        return []

    def _note(self, kind: str, msg: can.Message, detail: str) -> None:
        """A frame taken, but worth counting (and logging once)."""
        self.notes[kind] += 1
        if kind not in self._logged:
            self._logged.add(kind)
            log.warning(
                "CAN frame 0x%X at %.6f s: %s (%s); further ones are only counted",
                msg.arbitration_id,
                msg.timestamp,
                kind,
                detail,
            )

    def _stamp_problem(
        self, plan: _Plan, name: str, msg: can.Message, t: float
    ) -> list[InputSample] | None:
        """None if the stamp may be taken (the plan's time state updated for a resync),
        else the rejection. Integrity is checked before a forward jump is held."""
        if not math.isfinite(t):
            return self._problem(FrameProblem.BAD_STAMP, msg, f"{name}: stamp {t!r}")
        if t > plan.last_t:
            plan.back_first = plan.back_last = math.nan
            return None
        # before the message's newest frame: a late frame, or the sender's clock stepped back
        if not t > plan.back_last:  # (NaN: no run yet) a new run starts here
            plan.back_first = t
        plan.back_last = t
        if t - plan.back_first >= self.plausibility.stamp_resync_s:
            self._note(
                RESYNCED,
                msg,
                f"{name}: stamps {self.plausibility.stamp_resync_s:g} s behind the newest"
                f" {plan.last_t:.6f} s; the new time line is taken",
            )
            plan.last_t = -math.inf
            plan.pending_t = math.nan
            plan.back_first = plan.back_last = math.nan
            return None
        return self._problem(
            FrameProblem.TIME_NOT_INCREASING,
            msg,
            f"{name}: {t:.6f} s, previous {plan.last_t:.6f} s",
        )

    def _jump_problem(
        self, plan: _Plan, name: str, msg: can.Message, t: float
    ) -> list[InputSample] | None:
        """A frame far ahead of its message's previous one waits for the next to confirm
        that the time goes on from there (a single wild stamp costs only its own frame)."""
        if plan.last_t == -math.inf or t - plan.last_t <= plan.max_step_s:
            plan.pending_t = math.nan
            return None
        pending, plan.pending_t = plan.pending_t, t
        if pending < t and t - pending <= plan.max_step_s:
            plan.pending_t = math.nan
            return None  # confirmed: the previous frame jumped the same way
        return self._problem(
            FrameProblem.STAMP_JUMP,
            msg,
            f"{name}: {t:.6f} s is {t - plan.last_t:.3g} s after the previous {plan.last_t:.6f} s;"
            " held until the next frame confirms it",
        )

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
        """The samples of one frame (often none); never raises for a bad frame.

        Order: frame kind, ID (and its 11/29-bit format), length, stamp, integrity
        (CRC, alive counter), then the values: not available, saturated, the mapping's
        range, and the plausibility gate (physical range, gyro spike) on the sample."""
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
        if bool(msg.is_extended_id) != bool(message.is_extended_frame):
            bits = (29, 11) if msg.is_extended_id else (11, 29)
            return self._problem(
                FrameProblem.ID_FORMAT,
                msg,
                f"a {bits[0]}-bit ID; {message.name} has a {bits[1]}-bit ID in {self.db_name}",
            )
        data = bytes(msg.data)
        if len(data) != message.length:
            return self._problem(
                FrameProblem.WRONG_LENGTH,
                msg,
                f"{message.name}: {len(data)} bytes, the DBC says {message.length}",
            )
        t = float(msg.timestamp)
        rejected = self._stamp_problem(plan, message.name, msg, t)
        if rejected is not None:
            return rejected
        reason = self._check_integrity(plan, msg, data)
        if reason:
            return self._problem(FrameProblem.INTEGRITY, msg, f"{message.name}: {reason}")
        rejected = self._jump_problem(plan, message.name, msg, t)
        if rejected is not None:
            return rejected
        plan.last_t = t  # intact (CRC): its stamp is the time line's, also if stuck below
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
                if delta > self.plausibility.e2e_max_delta_counter:
                    self._note(
                        COUNTER_JUMP,
                        msg,
                        f"{message.name}: counter {plan.last_counter} -> {counter}, more than"
                        f" {self.plausibility.e2e_max_delta_counter}; re-synced",
                    )
        # the frame came through intact and in order: its counter is the new reference,
        # whatever the values turn out to be
        if counter is not None:
            plan.last_counter = counter
        st.lost += gap
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
            where = f"{message.name}.{bq.signal.name} = {physical:g} {bq.signal.unit or ''}"
            limits, tol = plan.saturation[bq.quantity]
            if self.plausibility.enabled and any(abs(physical - v) <= tol for v in limits):
                return self._problem(FrameProblem.SATURATED, msg, f"{where}: at the signal's limit")
            value, ok = bq.convert(physical)
            mapped = bq.spec.sign * (bq.spec.scale * physical + bq.spec.offset)
            if not ok or not math.isfinite(value):
                rng = bq.spec.range if bq.spec.range is not None else bq.dbc_range
                return self._problem(
                    FrameProblem.OUT_OF_RANGE,
                    msg,
                    f"{where} (mapped {mapped:g}"
                    f" {bq.spec.unit}; range {list(rng) if rng else '?'})",
                )
            values[bq.quantity] = value
        out: list[InputSample] = []
        if any(q in values for q in _RATES + _ACCEL):
            rates = tuple(values.get(q, math.nan) for q in _RATES)
            accel = tuple(values.get(q, math.nan) for q in _ACCEL)
            sample = ImuSample(t, rates, accel, message.name)  # type: ignore[arg-type]
            mount = self.mapping.mount  # a calibrated IMU: into the body axes, camera clock
            out.append(sample if mount is None else mount.apply_sample(sample))
        if "speed" in values:
            out.append(SpeedSample(t, values["speed"], message.name))
        for taken in out:
            why = self.gate.check(taken)
            if why:
                kind = FrameProblem.SPIKE if why == REJECTED_SPIKE else FrameProblem.OUT_OF_RANGE
                return self._problem(kind, msg, f"{message.name}: {self.gate.describe(taken, why)}")
        st.used += 1
        st.not_available += not_available
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
    "COUNTER_JUMP",
    "RESYNCED",
    "CanInputDecoder",
    "DecodeStats",
    "FrameProblem",
    "decode_log",
    "split_samples",
    "toyota_checksum_ok",
]
