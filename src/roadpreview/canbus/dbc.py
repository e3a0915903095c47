"""The project's CAN database (``roadpreview.dbc``) and the E2E protection of its messages.

The DBC ships inside the package (``roadpreview/data/roadpreview.dbc``; the
repository's ``data/roadpreview.dbc`` is a symlink to it) and is loaded with
cantools in strict mode. Every input message carries an AUTOSAR E2E profile 1
header: byte 0 is a CRC-8 SAE J1850 over the message's E2E data ID (DBC
attribute ``E2E_DataID``) and bytes 1..7, bits 8..11 an alive counter that
runs 0..14; so do the outputs ``RP_ALERT``, ``RP_ALERT_DETAIL``, ``RP_ALERT_END``,
``RP_CONFIRM``, ``RP_STATUS``, ``RP_ROAD_STATUS``, ``RP_INPUT_STATUS`` and the multiplexed
``RP_PREVIEW`` (`roadpreview.canbus.output`). The CRC comes from the ``autosar-e2e`` package.
Messages and signals are documented in ``docs/can-interface.md``. The DBC's ``VERSION`` is
`DBC_VERSION`; version 2 only added signals in free bits and a message, so a receiver built
on version 1 keeps working.

Other cars' DBCs (opendbc) load with ``load_database(path, strict=False)``:
they often have overlapping or placeholder signals that strict mode refuses.
"""

from __future__ import annotations

import functools
import importlib.resources
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cantools
import e2e.p01
from cantools.database.can import Database
from cantools.database.can import Message as MessageDef

from roadpreview.errors import InputDataError

#: resource name of the shipped DBC inside the ``roadpreview`` package
DBC_RESOURCE = ("data", "roadpreview.dbc")

# Message names (the DBC is the single source of IDs, layouts and periods).
IMU_RATES = "IMU_RATES"
IMU_ACCEL = "IMU_ACCEL"
VEHICLE_SPEED = "VEHICLE_SPEED"
WHEEL_SPEEDS = "WHEEL_SPEEDS"
RP_ALERT = "RP_ALERT"
RP_STATUS = "RP_STATUS"
RP_ROAD_STATUS = "RP_ROAD_STATUS"
RP_INPUT_STATUS = "RP_INPUT_STATUS"
RP_ALERT_DETAIL = "RP_ALERT_DETAIL"
RP_CONFIRM = "RP_CONFIRM"
RP_ALERT_END = "RP_ALERT_END"
RP_PREVIEW = "RP_PREVIEW"

#: ``VERSION`` of the shipped DBC (2: issue 27, ``AlertState``, ``EndCauseEx``, ``RP_PREVIEW``)
DBC_VERSION = "roadpreview 2"

#: 11-bit identifiers reserved for roadpreview's own output messages (alerts, confirmations,
#: status, road preview)
RESERVED_OUTPUT_IDS = range(0x200, 0x210)

#: DBC message attribute holding the AUTOSAR E2E data ID
E2E_DATA_ID_ATTRIBUTE = "E2E_DataID"
#: E2E profile 1 counters run 0..14; 15 is never sent
E2E_COUNTER_MODULUS = 15


def dbc_text() -> str:
    """The text of the shipped ``roadpreview.dbc``."""
    resource = importlib.resources.files("roadpreview").joinpath(*DBC_RESOURCE)
    try:
        return resource.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputDataError(
            f"roadpreview/{'/'.join(DBC_RESOURCE)}: cannot read the packaged DBC ({exc})"
        ) from None


@functools.lru_cache(maxsize=1)
def _packaged_database() -> Database:
    name = f"roadpreview/{'/'.join(DBC_RESOURCE)}"
    try:
        db = cantools.database.load_string(dbc_text(), database_format="dbc", strict=True)
    except (cantools.database.errors.UnsupportedDatabaseFormatError, ValueError) as exc:
        raise _dbc_error(name, exc) from None
    assert isinstance(db, Database)
    return db


def _dbc_error(path: object, exc: Exception) -> InputDataError:
    """An error naming the file, and the line and column of a syntax error."""
    cause = exc.__cause__ or exc.__context__
    line = getattr(cause, "line", None)
    column = getattr(cause, "column", None)
    if isinstance(line, int):
        where = f"{path}:{line}" + (f":{column}" if isinstance(column, int) else "")
        return InputDataError(f"{where}: DBC syntax error ({exc})")
    return InputDataError(f"{path}: not a valid DBC ({exc})")


def load_database(path: str | Path | None = None, *, strict: bool = True) -> Database:
    """Load a DBC, by default strictly (overlapping signals, bad lengths are errors).

    ``path=None`` gives the packaged ``roadpreview.dbc`` (loaded once and
    cached; treat it as read-only; always strict). ``strict=False`` is for
    foreign DBCs such as opendbc's. Raises `InputDataError` naming the file,
    and for a syntax error the line and column.
    """
    if path is None:
        return _packaged_database()
    try:
        db = cantools.database.load_file(path, database_format="dbc", strict=strict)
    except FileNotFoundError:
        raise InputDataError(f"{path}: DBC file not found") from None
    except (cantools.database.errors.UnsupportedDatabaseFormatError, ValueError, OSError) as exc:
        raise _dbc_error(path, exc) from None
    if not isinstance(db, Database):
        raise InputDataError(f"{path}: not a CAN database")
    return db


@dataclass(frozen=True)
class E2ELayout:
    """Where a message keeps its E2E profile 1 fields, read from the DBC."""

    data_id: int
    crc_signal: str
    counter_signal: str


def e2e_layout(message: MessageDef) -> E2ELayout:
    """The E2E data ID and the CRC / counter signal names of ``message``.

    The CRC signal must be byte 0 and the counter bits 8..11 (the layout the
    autosar-e2e profile 1 functions use); raises `InputDataError` otherwise.
    """
    attrs: Mapping[str, Any] = message.dbc.attributes if message.dbc is not None else {}
    if E2E_DATA_ID_ATTRIBUTE not in attrs:
        raise InputDataError(
            f"DBC message {message.name}: no {E2E_DATA_ID_ATTRIBUTE} attribute (not E2E protected)"
        )
    crc = [s for s in message.signals if s.start == 0 and s.length == 8 and s.name.endswith("_CRC")]
    cnt = [
        s for s in message.signals if s.start == 8 and s.length == 4 and s.name.endswith("_Counter")
    ]
    if len(crc) != 1 or len(cnt) != 1 or message.length < 2:
        raise InputDataError(
            f"DBC message {message.name}: E2E P01 needs a *_CRC signal at bits 0..7 and a"
            " *_Counter signal at bits 8..11"
        )
    return E2ELayout(int(attrs[E2E_DATA_ID_ATTRIBUTE].value), crc[0].name, cnt[0].name)


def encode_protected(
    message: MessageDef,
    signals: Mapping[str, float | int | str],
    counter: int,
    *,
    layout: E2ELayout | None = None,
) -> bytes:
    """Encode physical ``signals`` (all but CRC and counter) and add the E2E header.

    Values must lie within the signals' DBC ranges (cantools raises
    ``EncodeError`` otherwise); ``counter`` is taken modulo 15. Pass
    ``layout=e2e_layout(message)`` when encoding many frames of one message.
    """
    layout = layout or e2e_layout(message)
    values = dict(signals)
    values[layout.crc_signal] = 0
    values[layout.counter_signal] = counter % E2E_COUNTER_MODULUS
    data = bytearray(message.encode(values, strict=True))
    e2e.p01.e2e_p01_protect(data, layout.data_id, increment_counter=False)
    return bytes(data)


def check_protected(message: MessageDef, data: bytes | bytearray) -> bool:
    """True if the E2E CRC of a received payload is correct (counter not judged here)."""
    if len(data) != message.length:
        return False
    layout = e2e_layout(message)
    return bool(e2e.p01.e2e_p01_check(bytearray(data), layout.data_id))
