"""Input mappings: which CAN message and signal gives each IMU quantity and the vehicle speed.

A mapping is a TOML file (``docs/can-interface.md``, "Input mappings"), so
that any car's DBC can feed roadpreview. Shipped mappings are
``roadpreview/data/mapping_<name>.toml`` (`load_mapping` takes the name)::

    [mapping]
    name = "toyota_rav4"
    frame = "iso8855"        # axes the `axis` / `sign` of the signals refer to
    channel = 0              # only frames of this bus (optional)
    integrity = "none"       # default check: none | e2e_p01 | toyota_checksum

    [messages.SPEED]
    integrity = "toyota_checksum"

    [quantities.yaw_rate]
    message = "KINEMATICS"
    signal = "YAW_RATE"
    unit = "deg/s"           # unit of the DBC's physical value
    axis = "z"               # the body axis the signal is about / along
    sign = 1                 # +1: positive like a right-handed rotation about / along +axis
    scale = 1.0              # value = sign * (scale * physical + offset), in `unit`
    offset = 0.0
    range = [-100.0, 100.0]  # optional plausibility range of value, in `unit`

    [quantities.pitch_rate]
    missing = "no pitch rate on this car's powertrain bus"

An optional ``[mount]`` table (``roadpreview calibrate`` writes it,
`roadpreview.canbus.samples.ImuMount`) says how the IMU lies in the car: the
quantities above are then the IMU's own axes, turned into the body's by
``rotation`` (body <- IMU), and ``time_offset_s`` is taken off their stamps.

Every quantity of `QUANTITIES` must be listed, mapped or declared
``missing`` with the reason, so a missing signal is a statement, not an
oversight. The value is converted to SI and to roadpreview's conventions
(``roadpreview.canbus.samples``) from the declared ``frame``: ``iso8855``
(x forward, y left, z up) or ``sae_j670`` (x forward, y right, z down).
`bind_mapping` checks a mapping against a DBC and raises `ConfigError`
naming the file, the quantity and the message or signal that is not there.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib.resources
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cantools.database.can import Database, Signal
from cantools.database.can import Message as MessageDef

from roadpreview._tomlio import load_toml
from roadpreview.canbus.samples import ImuMount
from roadpreview.configtools import from_mapping, param
from roadpreview.errors import ConfigError

#: quantity -> (kind, body axis); rates and accelerations per axis, speed along x
QUANTITIES: dict[str, tuple[str, str]] = {
    "roll_rate": ("rate", "x"),
    "pitch_rate": ("rate", "y"),
    "yaw_rate": ("rate", "z"),
    "accel_x": ("accel", "x"),
    "accel_y": ("accel", "y"),
    "accel_z": ("accel", "z"),
    "speed": ("speed", "x"),
}

#: SI factor of each unit a mapping may name, by kind
UNITS: dict[str, dict[str, float]] = {
    "rate": {"rad/s": 1.0, "deg/s": math.pi / 180.0},
    "accel": {"m/s^2": 1.0, "g": 9.80665},
    "speed": {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704},
}
_UNIT_ALIASES = {
    "m/s2": "m/s^2",
    "m/s²": "m/s^2",
    "m/s/s": "m/s^2",
    "mps2": "m/s^2",
    "kph": "km/h",
    "kmh": "km/h",
    "kmph": "km/h",
    "mps": "m/s",
    "deg/sec": "deg/s",
    "°/s": "deg/s",
    "dps": "deg/s",
    "rad/sec": "rad/s",
}

#: sign that takes a right-handed value about / along the frame's axis to roadpreview's quantity
FRAME_SIGNS: dict[str, dict[str, float]] = {
    # ISO 8855 is roadpreview's body frame; only pitch differs (nose up = -omega_y)
    "iso8855": {
        "roll_rate": 1.0,
        "pitch_rate": -1.0,
        "yaw_rate": 1.0,
        "accel_x": 1.0,
        "accel_y": 1.0,
        "accel_z": 1.0,
        "speed": 1.0,
    },
    # SAE J670: y right, z down. +omega_y raises the nose, +omega_z turns right
    "sae_j670": {
        "roll_rate": 1.0,
        "pitch_rate": 1.0,
        "yaw_rate": -1.0,
        "accel_x": 1.0,
        "accel_y": -1.0,
        "accel_z": -1.0,
        "speed": 1.0,
    },
}

#: integrity checks a message may declare (roadpreview.canbus.decode implements them)
INTEGRITY_CHECKS = ("none", "e2e_p01", "toyota_checksum")

_PACKAGE_DATA = "data"


def normalise_unit(unit: str) -> str:
    """Canonical spelling of a unit (``m/s2`` -> ``m/s^2``, ``kph`` -> ``km/h``)."""
    u = unit.strip()
    return _UNIT_ALIASES.get(u.lower(), _UNIT_ALIASES.get(u, u))


@dataclass(frozen=True)
class MappingHeader:
    """The ``[mapping]`` table."""

    name: str = param("", help="short name of the car / DBC this mapping is for")
    description: str = param("", help="free text: car, DBC file, how the signs were checked")
    dbc: str = param("", help="file name of the DBC the mapping was written for (informational)")
    frame: str = param(
        "iso8855",
        choices=tuple(FRAME_SIGNS),
        help="axes of `axis`/`sign`: iso8855 (x fwd, y left, z up), sae_j670 (y right, z down)",
    )
    channel: int | None = param(None, ge=0, help="only frames of this channel; None: any")
    integrity: str = param(
        "none",
        choices=INTEGRITY_CHECKS,
        help="check of messages without their own [messages]",
    )
    dbc_ranges: bool = param(
        False,
        help="also reject values outside the DBC signal ranges (only if those are real;"
        " opendbc's are often placeholders)",
    )
    ignore_unknown_ids: bool = param(
        False,
        help="frames whose ID the DBC lacks are ignored instead of counted as problems"
        " (a DBC that describes only part of a car's bus)",
    )


@dataclass(frozen=True)
class MessageOptions:
    """A ``[messages.<NAME>]`` table."""

    integrity: str = param("none", choices=INTEGRITY_CHECKS, help="integrity check of the frames")


@dataclass(frozen=True)
class QuantitySpec:
    """A ``[quantities.<quantity>]`` table: where the quantity comes from, or why it is missing."""

    message: str = param("", help="DBC message name")
    signal: str = param("", help="DBC signal name")
    unit: str = param("", help="unit of the signal's physical value (UNITS)")
    axis: str = param("", choices=("", "x", "y", "z"), help="body axis of the signal")
    sign: int = param(1, choices=(1, -1), help="+1: positive about / along +axis of `frame`")
    scale: float = param(1.0, help="extra factor on the DBC's physical value")
    offset: float = param(0.0, help="added after scale, in `unit`")
    range: tuple[float, float] | None = param(None, help="plausible values, in `unit`")
    missing: str = param("", help="non-empty: not available on this car, and why")


@dataclass(frozen=True)
class InputMapping:
    """A parsed mapping file (not yet checked against a DBC: `bind_mapping`)."""

    header: MappingHeader
    quantities: dict[str, QuantitySpec]
    messages: dict[str, MessageOptions] = field(default_factory=dict)
    source: str = "<mapping>"
    #: ``[mount]``: the IMU's rotation into the body axes and its clock offset (calibrated)
    mount: ImuMount | None = None

    def integrity_of(self, message: str) -> str:
        """The integrity check of ``message``."""
        opts = self.messages.get(message)
        return opts.integrity if opts is not None else self.header.integrity

    @property
    def missing(self) -> dict[str, str]:
        """Quantities this car does not provide, with the reason."""
        return {q: s.missing for q, s in self.quantities.items() if s.missing}


def _check_quantity(name: str, spec: QuantitySpec, where: str) -> None:
    kind, axis = QUANTITIES[name]
    if spec.missing:
        if spec.message or spec.signal:
            raise ConfigError(f"{where}: either message/signal or missing, not both")
        return
    for key in ("message", "signal", "unit"):
        if not getattr(spec, key):
            raise ConfigError(
                f"{where}.{key} is not set (map the quantity, or declare it missing with the"
                ' reason: missing = "...")'
            )
    unit = normalise_unit(spec.unit)
    if unit not in UNITS[kind]:
        raise ConfigError(
            f"{where}.unit = {spec.unit!r}: a {kind} needs one of {', '.join(UNITS[kind])}"
        )
    if spec.axis and spec.axis != axis:
        raise ConfigError(
            f"{where}.axis = {spec.axis!r}: {name} is about / along the {axis} axis"
            f" (a signal about {spec.axis} belongs to another quantity)"
        )
    if kind != "speed" and not spec.axis:
        raise ConfigError(f"{where}.axis is not set (must be {axis!r})")
    if spec.range is not None and not spec.range[0] < spec.range[1]:
        raise ConfigError(f"{where}.range = {list(spec.range)}: need low < high")
    if spec.scale == 0:
        raise ConfigError(f"{where}.scale = 0")


def parse_mapping(data: Mapping[str, Any], source: str = "<mapping>") -> InputMapping:
    """Build an `InputMapping` from parsed TOML; `ConfigError` names ``source`` and the key."""
    unknown = sorted(set(data) - {"mapping", "messages", "quantities", "mount"})
    if unknown:
        raise ConfigError(
            f"{source}: unknown table [{unknown[0]}] (known: mapping, messages, quantities, mount)"
        )
    header = from_mapping(MappingHeader, data.get("mapping", {}), source=source, where="mapping")
    messages: dict[str, MessageOptions] = {}
    for name, table in dict(data.get("messages", {})).items():
        messages[name] = from_mapping(
            MessageOptions, table, source=source, where=f"messages.{name}"
        )
    raw_q = dict(data.get("quantities", {}))
    quantities: dict[str, QuantitySpec] = {}
    for name, table in raw_q.items():
        where = f"quantities.{name}"
        if name not in QUANTITIES:
            raise ConfigError(
                f"{source}: unknown quantity [{where}] (known: {', '.join(QUANTITIES)})"
            )
        spec = from_mapping(QuantitySpec, table, source=source, where=where)
        try:
            _check_quantity(name, spec, where)
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}") from None
        quantities[name] = spec
    absent = [q for q in QUANTITIES if q not in quantities]
    if absent:
        raise ConfigError(
            f"{source}: quantity {absent[0]} is not in the mapping; add [quantities.{absent[0]}]"
            ' with its message and signal, or with missing = "why this car has none"'
        )
    mount = ImuMount.from_dict(data["mount"], source=source) if "mount" in data else None
    return InputMapping(
        header=header, quantities=quantities, messages=messages, source=source, mount=mount
    )


def packaged_mapping_path(name: str) -> Path:
    """Path of the shipped mapping ``data/mapping_<name>.toml``."""
    resource = importlib.resources.files("roadpreview").joinpath(
        _PACKAGE_DATA, f"mapping_{name}.toml"
    )
    return Path(str(resource))


def available_mappings() -> list[str]:
    """Names of the shipped mappings."""
    folder = importlib.resources.files("roadpreview").joinpath(_PACKAGE_DATA)
    return sorted(
        p.name[len("mapping_") : -len(".toml")]
        for p in folder.iterdir()
        if p.name.startswith("mapping_") and p.name.endswith(".toml")
    )


def load_mapping(path_or_name: str | Path) -> InputMapping:
    """Load a mapping file, or a shipped one by name (``"roadpreview"``, ``"toyota_rav4"``)."""
    path = Path(path_or_name)
    if isinstance(path_or_name, str) and path.suffix == "" and len(path.parts) == 1:
        path = packaged_mapping_path(path_or_name)
        if not path.is_file():
            shipped = ", ".join(available_mappings())
            raise ConfigError(f"no shipped mapping {path_or_name!r} (available: {shipped})")
    return parse_mapping(load_toml(path), source=str(path))


# --- binding to a DBC ---------------------------------------------------------------------------


@dataclass(frozen=True)
class BoundQuantity:
    """One mapped quantity resolved against a DBC: signal object and conversion to SI."""

    quantity: str
    message: MessageDef
    signal: Signal
    spec: QuantitySpec
    si_factor: float  #: SI per `unit`, times the frame's sign
    dbc_range: tuple[float, float] | None  #: checked on the DBC's physical value, or None

    def convert(self, physical: float) -> tuple[float, bool]:
        """(value in SI and roadpreview's convention, inside the plausible range)."""
        spec = self.spec
        value = spec.sign * (spec.scale * physical + spec.offset)
        ok = True
        if spec.range is not None:
            ok = spec.range[0] <= value <= spec.range[1]
        if self.dbc_range is not None:
            ok = ok and self.dbc_range[0] <= physical <= self.dbc_range[1]
        return value * self.si_factor, ok


@dataclass(frozen=True)
class BoundMapping:
    """A mapping checked against a DBC: per frame ID, the quantities it carries."""

    mapping: InputMapping
    by_frame_id: dict[int, list[BoundQuantity]]

    @property
    def messages(self) -> dict[int, MessageDef]:
        """The mapped messages by frame ID."""
        return {fid: qs[0].message for fid, qs in self.by_frame_id.items()}


def _suggest(name: str, options: list[str]) -> str:
    close = difflib.get_close_matches(name, options, n=3)
    return f" (close: {', '.join(close)})" if close else ""


def bind_mapping(mapping: InputMapping, db: Database, *, db_name: str = "the DBC") -> BoundMapping:
    """Resolve every mapped quantity in ``db``; `ConfigError` names what is missing.

    Also checks that the signal's DBC unit, if it has one, is the mapping's unit.
    """
    src = mapping.source
    names = [m.name for m in db.messages]
    for msg_name in mapping.messages:
        if msg_name not in names:
            raise ConfigError(
                f"{src}: [messages.{msg_name}]: message {msg_name!r} is not in {db_name}"
                f"{_suggest(msg_name, names)}"
            )
    by_id: dict[int, list[BoundQuantity]] = {}
    frame_signs = FRAME_SIGNS[mapping.header.frame]
    for q, spec in mapping.quantities.items():
        if spec.missing:
            continue
        where = f"{src}: quantities.{q}"
        try:
            message = db.get_message_by_name(spec.message)
        except KeyError:
            raise ConfigError(
                f"{where}: message {spec.message!r} is not in {db_name}"
                f"{_suggest(spec.message, names)}"
            ) from None
        signals = [s.name for s in message.signals]
        if spec.signal not in signals:
            raise ConfigError(
                f"{where}: signal {spec.signal!r} is not in message {message.name} of {db_name}"
                f"{_suggest(spec.signal, signals)} (signals: {', '.join(signals)})"
            )
        signal = message.get_signal_by_name(spec.signal)
        unit = normalise_unit(spec.unit)
        if signal.unit and normalise_unit(signal.unit) != unit:
            raise ConfigError(
                f"{where}.unit = {spec.unit!r}, but {message.name}.{signal.name} is in"
                f" {signal.unit!r} in {db_name}"
            )
        kind = QUANTITIES[q][0]
        dbc_range = None
        lo, hi = signal.minimum, signal.maximum
        if mapping.header.dbc_ranges and lo is not None and hi is not None and lo < hi:
            dbc_range = (float(lo), float(hi))
        by_id.setdefault(message.frame_id, []).append(
            BoundQuantity(
                quantity=q,
                message=message,
                signal=signal,
                spec=spec,
                si_factor=UNITS[kind][unit] * frame_signs[q],
                dbc_range=dbc_range,
            )
        )
    return BoundMapping(mapping=mapping, by_frame_id=by_id)


def replace_quantity(mapping: InputMapping, quantity: str, **changes: Any) -> InputMapping:
    """A copy of ``mapping`` with one quantity's fields changed (checked again)."""
    spec = dataclasses.replace(mapping.quantities[quantity], **changes)
    _check_quantity(quantity, spec, f"quantities.{quantity}")
    return dataclasses.replace(mapping, quantities={**mapping.quantities, quantity: spec})
