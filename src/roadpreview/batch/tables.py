"""The fleet tables of a batch: every drive's alerts in one table, and one row of figures
per drive, each as Parquet (pyarrow) with a CSV twin.

* `alerts_table`: one row per alert of every drive, ``drive`` first, then the fields of
  ``alerts.jsonl`` (`roadpreview.sinks.files.alert_record`). Every alert of every drive
  given is there, a failed drive's too (a drive failed for an unusable input was still
  replayed); join with the drives table on ``drive`` to filter by status.
* `drives_table`: one row per drive (`DRIVE_COLUMNS`), units in the column names.
* `write_tables`: both, as ``alerts.parquet`` / ``alerts.csv`` / ``drives.parquet`` /
  ``drives.csv`` (`TABLE_FILES`), each written to a temporary name and renamed.

Drives come out sorted by id (the outcomes arrive in completion order, which changes from
run to run); a drive's alerts keep their order. The column types do not depend on the data:
a column that is null in every row keeps its type, and an empty fleet gives every known
column with no rows.
"""

from __future__ import annotations

import json
import math
import os
import re
import types
import typing
from collections.abc import Callable, Iterable, Sequence
from dataclasses import fields
from enum import Enum
from functools import cache, partial
from pathlib import Path
from typing import Any

import pyarrow as pa

from roadpreview.batch.outcome import MODES, DriveOutcome

#: the files `write_tables` writes, in this order
TABLE_FILES = ("alerts.parquet", "alerts.csv", "drives.parquet", "drives.csv")

#: a column named like a physical quantity (the project's unit suffixes) holds numbers
_UNIT_SUFFIX = re.compile(
    r"_(s|ms|h|min|m|mm|km|px|rad|deg|mps|mps2|hz|m3|rad_s|per_km|per_hour|per_min)$"
)


def _mode_column(mode: str) -> str:
    return f"mode_{mode}_share"


#: the drives table's columns and their types, in order
DRIVE_COLUMNS: dict[str, pa.DataType] = {
    "drive": pa.string(),
    "status": pa.string(),
    "message": pa.string(),
    "frames": pa.int64(),
    "duration_s": pa.float64(),
    "distance_km": pa.float64(),
    "replay_s": pa.float64(),
    "task_s": pa.float64(),
    "fps": pa.float64(),
    "alerts": pa.int64(),
    "alerts_per_km": pa.float64(),
    "alerts_per_hour": pa.float64(),
    **{_mode_column(m): pa.float64() for m in MODES},
    "road_class": pa.string(),
    "decode_failures": pa.int64(),
    "input_errors": pa.int64(),
    "unusable_inputs": pa.int64(),
    "truth_expected": pa.float64(),
    "truth_hits": pa.float64(),
    "truth_false_alarms": pa.float64(),
    "worker": pa.string(),
    "folder": pa.string(),
}


# -- the alert columns ----------------------------------------------------------------------
def _sample_value(hint: Any) -> Any:
    """A value of the type ``hint`` names (the first non-None member of a union): the
    type's zero, an enum's first member; None when the type is none of those."""
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        members = [a for a in typing.get_args(hint) if a is not type(None)]
        return _sample_value(members[0]) if members else None
    if isinstance(hint, type) and issubclass(hint, Enum):
        return next(iter(hint))
    if hint in (bool, int, float, str):
        return hint()
    return None


def _sample(cls: type[Any]) -> Any:
    """An instance of the dataclass ``cls`` with every field set (`_sample_value`), so
    that whatever serialises it shows the fields' types."""
    hints = typing.get_type_hints(cls)
    return cls(**{f.name: _sample_value(hints[f.name]) for f in fields(cls)})


def _arrow_type_of(value: Any) -> pa.DataType | None:
    if isinstance(value, bool):
        return pa.bool_()
    if isinstance(value, int):
        return pa.int64()
    if isinstance(value, float):
        return pa.float64()
    if isinstance(value, str):
        return pa.string()
    return None


@cache
def alert_columns() -> dict[str, pa.DataType]:
    """The columns of ``alerts.jsonl`` and their types, in the file's key order: what
    `roadpreview.sinks.files.alert_record` makes of an `Alert` with every field set and a
    confirmation, so that a field added there shows up here. (Imported on use: the sinks
    bring in the whole pipeline.)"""
    from roadpreview.sinks.files import alert_record
    from roadpreview.types import Alert, ConfirmationResult

    record = alert_record(_sample(Alert), _sample(ConfirmationResult))
    return {
        key: _arrow_type_of(value) or _guess_type(key, [value]) for key, value in record.items()
    }


def _fits(value: Any, kind: pa.DataType) -> bool:
    """Whether ``value`` (not None) goes into a column of type ``kind`` as it is."""
    if pa.types.is_boolean(kind):
        return isinstance(value, bool)
    if pa.types.is_integer(kind):
        return isinstance(value, int) and not isinstance(value, bool)
    if pa.types.is_floating(kind):
        return isinstance(value, int | float) and not isinstance(value, bool)
    return bool(pa.types.is_string(kind))  # anything has a text form


def _guess_type(name: str, values: Sequence[Any]) -> pa.DataType:
    """The type of a column no `alert_columns` entry covers (or whose values do not fit
    it): from the values present; with none, float64 for a name with a unit, else text."""
    present = [v for v in values if v is not None]
    if not present:
        return pa.float64() if _UNIT_SUFFIX.search(name) else pa.string()
    for kind in (pa.bool_(), pa.int64(), pa.float64()):
        if all(_fits(v, kind) for v in present):
            return kind
    return pa.string()


def _as_text(value: Any) -> str | None:
    if value is None:
        return None
    if isinstance(value, str):
        return value
    if isinstance(value, dict | list | tuple):
        return json.dumps(value)
    return str(value)


def _as_float(value: Any) -> float | None:
    """A float, None for None and NaN / inf (null in the tables, as in the JSON)."""
    if value is None:
        return None
    x = float(value)
    return x if math.isfinite(x) else None


def _converter(kind: pa.DataType) -> Callable[[Any], Any]:
    if pa.types.is_floating(kind):
        return _as_float
    if pa.types.is_string(kind):
        return _as_text
    return lambda v: v


def _column(values: Sequence[Any], kind: pa.DataType) -> pa.Array:
    convert = _converter(kind)
    return pa.array([convert(v) for v in values], type=kind)


def _sorted(outcomes: Iterable[DriveOutcome]) -> list[DriveOutcome]:
    return sorted(outcomes, key=lambda o: o.drive)


# -- the tables -----------------------------------------------------------------------------
def alerts_table(outcomes: Iterable[DriveOutcome]) -> pa.Table:
    """One row per alert of every drive: ``drive``, then the alert fields (the first
    alert's key order, then any other keys sorted; with no alert, `alert_columns`).
    Known columns keep their type when null throughout; a value that does not fit its
    column's type turns the column to what fits (text at worst)."""
    drives: list[str] = []
    rows: list[dict[str, Any]] = []
    for o in _sorted(outcomes):
        for row in o.alert_rows:
            drives.append(o.drive)
            rows.append(row)
    known = alert_columns()
    if rows:
        first = [k for k in rows[0] if k != "drive"]
        others = sorted({k for r in rows for k in r if k != "drive"} - set(first))
        names = first + others
    else:
        names = list(known)
    arrays = [_column(drives, pa.string())]
    for name in names:
        values = [r.get(name) for r in rows]
        kind = known.get(name)
        if kind is None or not all(_fits(v, kind) for v in values if v is not None):
            kind = _guess_type(name, values)
        arrays.append(_column(values, kind))
    return pa.Table.from_arrays(arrays, names=["drive", *names])


def _drive_row(o: DriveOutcome) -> dict[str, Any]:
    """One drive's row of the drives table (NaN -> null)."""
    truth = o.truth or {}
    row: dict[str, Any] = {
        "drive": o.drive,
        "status": o.status,
        "message": o.message,
        "frames": o.frames,
        "duration_s": o.duration_s,
        "distance_km": o.distance_km,
        "replay_s": o.replay_s,
        "task_s": o.task_s,
        "fps": o.fps,
        "alerts": o.alerts,
        "alerts_per_km": o.alerts_per_km,
        "alerts_per_hour": o.alerts_per_hour,
        # a drive without modes (failed before it ran) has no shares, not zero shares
        **{_mode_column(m): o.modes.get(m, 0.0) if o.modes else None for m in MODES},
        "road_class": o.road_class,
        "decode_failures": o.decode_failures,
        "input_errors": o.input_errors,
        "unusable_inputs": o.unusable_inputs,
        "truth_expected": truth.get("expected"),
        "truth_hits": truth.get("hits"),
        "truth_false_alarms": truth.get("false_alarms"),
        "worker": o.worker,
        "folder": o.folder,
    }
    return row


def drives_table(outcomes: Iterable[DriveOutcome]) -> pa.Table:
    """One row per drive (`DRIVE_COLUMNS`): the outcome's figures, the alert rates
    (null without a distance / duration), the share of time in each fusion mode, the
    error counts, and the truth counts (null without truth)."""
    rows = [_drive_row(o) for o in _sorted(outcomes)]
    return pa.Table.from_arrays(
        [_column([r[name] for r in rows], kind) for name, kind in DRIVE_COLUMNS.items()],
        names=list(DRIVE_COLUMNS),
    )


# -- files ----------------------------------------------------------------------------------
def write_atomically(path: Path, write: Callable[[Path], None]) -> Path:
    """Call ``write`` with a temporary name next to ``path``, then rename it to ``path``
    (a reader never sees half a file); the temporary file goes if ``write`` fails."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _write_parquet(table: pa.Table, path: Path) -> None:
    import pyarrow.parquet as pq

    pq.write_table(table, path)


def _write_csv(table: pa.Table, path: Path) -> None:
    import pyarrow.csv as pacsv

    pacsv.write_csv(table, path, write_options=pacsv.WriteOptions(quoting_style="needed"))


def write_tables(outcomes: Iterable[DriveOutcome], out: Path) -> dict[str, Path]:
    """Write the fleet tables into ``out`` (created if needed): `TABLE_FILES`. Returns
    each file's name -> its path."""
    outcomes = list(outcomes)
    out.mkdir(parents=True, exist_ok=True)
    tables = {"alerts": alerts_table(outcomes), "drives": drives_table(outcomes)}
    written: dict[str, Path] = {}
    for name in TABLE_FILES:
        stem, ext = name.split(".")
        writer = _write_parquet if ext == "parquet" else _write_csv
        written[name] = write_atomically(out / name, partial(writer, tables[stem]))
    return written


__all__ = [
    "DRIVE_COLUMNS",
    "TABLE_FILES",
    "alert_columns",
    "alerts_table",
    "drives_table",
    "write_atomically",
    "write_tables",
]
