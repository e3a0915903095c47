"""Typed configuration from TOML: nested dataclasses, unknown keys rejected, ranges checked.

Every configuration class in roadpreview is a dataclass whose fields carry
their unit, the reason for the default and an allowed range in the field
metadata::

    speed_kmh: float = param(20.0, unit="km/h", gt=0, le=200,
                             help="about the paper's controlled-experiment speed")

`from_mapping` builds such a class from a (TOML) mapping, recursing into nested
dataclasses, and raises `ConfigError` naming the file and the dotted field path
of the first problem: an unknown key, a wrong type or a value out of range.
`to_mapping` is the inverse, so a configuration written out can be read back
unchanged.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from roadpreview._tomlio import dump_toml, load_toml
from roadpreview.errors import ConfigError

T = TypeVar("T")


def param(
    default: Any = dataclasses.MISSING,
    *,
    unit: str = "",
    help: str = "",
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    choices: tuple[Any, ...] | None = None,
    default_factory: Any = dataclasses.MISSING,
) -> Any:
    """A dataclass field with its unit, the reason for its default and its allowed range."""
    meta = {"unit": unit, "help": help, "gt": gt, "ge": ge, "lt": lt, "le": le, "choices": choices}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def _type_hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _check_range(value: Any, f: dataclasses.Field[Any], where: str) -> None:
    m = f.metadata
    if m.get("choices") is not None and value not in m["choices"]:
        raise ConfigError(f"{where} = {value!r}: must be one of {list(m['choices'])}")
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return
    unit = f" {m['unit']}" if m.get("unit") else ""
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{where} = {value!r}: must be a finite number")
    if m.get("gt") is not None and not value > m["gt"]:
        raise ConfigError(f"{where} = {value}{unit}: must be > {m['gt']}{unit}")
    if m.get("ge") is not None and not value >= m["ge"]:
        raise ConfigError(f"{where} = {value}{unit}: must be >= {m['ge']}{unit}")
    if m.get("lt") is not None and not value < m["lt"]:
        raise ConfigError(f"{where} = {value}{unit}: must be < {m['lt']}{unit}")
    if m.get("le") is not None and not value <= m["le"]:
        raise ConfigError(f"{where} = {value}{unit}: must be <= {m['le']}{unit}")


def _convert(value: Any, tp: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _convert(value, a, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: unexpected value {value!r}")
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: must be a table, got {type(value).__name__}")
        return _build(tp, value, where)
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: must be an array, got {type(value).__name__}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{where}: must have {len(args)} elements, got {len(value)}")
            return tuple(
                _convert(v, a, f"{where}[{i}]")
                for i, (v, a) in enumerate(zip(value, args, strict=True))
            )
        inner = args[0] if args else Any
        items = [_convert(v, inner, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: must be a table, got {type(value).__name__}")
        return dict(value)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: must be true or false, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: must be a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: must be an integer, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: must be a string, got {value!r}")
        return value
    return value


def _build(cls: type[T], data: Mapping[str, Any], where: str) -> T:
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        prefix = f"{where}." if where else ""
        raise ConfigError(
            f"unknown key {prefix}{unknown[0]!s} (known keys: {', '.join(sorted(fields))})"
        )
    hints = _type_hints(cls)
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        path = f"{where}.{name}" if where else name
        converted = _convert(value, hints[name], path)
        _check_range(converted, fields[name], path)
        kwargs[name] = converted
    try:
        obj = cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(f"{where or cls.__name__}: {exc}") from None
    validate = getattr(obj, "validate", None)
    if callable(validate):
        validate(where or cls.__name__)
    return obj


def from_mapping(cls: type[T], data: Mapping[str, Any], *, source: str = "", where: str = "") -> T:
    """Build dataclass ``cls`` from ``data``; errors name ``source`` and the dotted field path."""
    try:
        return _build(cls, data, where)
    except ConfigError as exc:
        if source:
            raise ConfigError(f"{source}: {exc}") from None
        raise


def load(cls: type[T], path: str | Path, *, table: str | None = None) -> T:
    """Load dataclass ``cls`` from a TOML file (optionally from one ``[table]`` of it)."""
    data: Any = load_toml(path)
    if table is not None:
        if table not in data:
            raise ConfigError(f"{path}: missing table [{table}]")
        data = data[table]
    return from_mapping(cls, data, source=str(path), where=table or "")


def to_mapping(obj: Any) -> Any:
    """A dataclass (recursively) as TOML-ready plain values; ``None`` fields are left out."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out: dict[str, Any] = {}
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if v is None:
                continue
            out[f.name] = to_mapping(v)
        return out
    if isinstance(obj, (list, tuple)):
        return [to_mapping(v) for v in obj]
    if isinstance(obj, Mapping):
        return {k: to_mapping(v) for k, v in obj.items()}
    return obj


def save(obj: Any, path: str | Path) -> None:
    """Write a configuration dataclass as TOML."""
    dump_toml(to_mapping(obj), path)


def check_ranges(obj: Any, where: str = "") -> None:
    """Re-check every field's declared range (for objects built in code, not from TOML)."""
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        path = f"{where}.{f.name}" if where else f.name
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            check_ranges(v, path)
        else:
            _check_range(v, f, path)


def _range_text(m: Mapping[str, Any]) -> str:
    bounds = [
        f"{op} {m[key]}"
        for key, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
        if m.get(key) is not None
    ]
    if m.get("choices") is not None:
        return "one of: " + ", ".join(str(c) for c in m["choices"])
    return "range: " + " and ".join(bounds) if bounds else ""


def _field_comment(f: dataclasses.Field[Any], value: Any) -> list[str]:
    """The comment lines above one field: its help, unit and allowed range."""
    import textwrap

    m = f.metadata
    text = m.get("help") or (
        "a table of options passed on to the chosen component (empty: its defaults)"
        if isinstance(value, Mapping)
        else f"{f.name.replace('_', ' ')}"
    )
    extras = [f"unit: {m['unit']}"] if m.get("unit") else []
    if rng := _range_text(m):
        extras.append(rng)
    if extras:
        text = f"{text} [{'; '.join(extras)}]"
    return textwrap.wrap(
        text, width=88, initial_indent="# ", subsequent_indent="# ", break_on_hyphens=False
    )


def commented_toml(obj: Any, *, header: str = "") -> str:
    """A configuration dataclass as TOML with every field commented (its help, unit and
    range from `param`), tables in field order; a field that is None is written
    commented out. ``header``: comment lines at the top. Reading the text back gives
    ``obj`` (`to_mapping` values)."""
    import tomli_w

    lines = [f"# {h}" if h else "#" for h in header.splitlines()]

    def table(o: Any, where: str, doc: str) -> None:
        scalars: list[str] = []
        nested: list[tuple[str, Any, str]] = []
        for f in dataclasses.fields(o):
            v = getattr(o, f.name)
            path = f"{where}.{f.name}" if where else f.name
            if dataclasses.is_dataclass(v) and not isinstance(v, type):
                nested.append((path, v, (type(v).__doc__ or "").strip().split("\n")[0]))
                continue
            if isinstance(v, Mapping):
                nested.append((path, v, "\n".join(_field_comment(f, v))[2:]))
                continue
            scalars += _field_comment(f, v)
            if v is None:
                scalars.append(f"# {f.name} = (not set)")
            else:
                scalars.append(tomli_w.dumps({f.name: to_mapping(v)}).rstrip("\n"))
        if where:
            lines.append("")
            lines.extend(f"# {d}" for d in doc.splitlines() if d)
            lines.append(f"[{where}]")
        lines.extend(scalars)
        for path, v, d in nested:
            if isinstance(v, Mapping):
                lines.append("")
                lines.append(f"# {d}")
                lines.append(f"[{path}]")
                lines.extend(tomli_w.dumps(to_mapping(dict(v))).splitlines())
            else:
                table(v, path, d)

    table(obj, "", "")
    return "\n".join(lines).strip("\n") + "\n"
