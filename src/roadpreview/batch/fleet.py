"""Replay a fleet of drives (``roadpreview batch``): the run loop per drive, fanned out as
Dask tasks (`roadpreview.batch.engine`), one sub-folder of outputs per drive, then the
fleet's tables and report.

Output folder::

    <drive>/            replay's outputs (alerts.blf, alerts.jsonl, frames.csv, plots.png,
                        summary.json), replay.log, batch.json (fingerprint + outcome)
    alerts.parquet      every alert of every drive, with the drive id (+ alerts.csv)
    drives.parquet      one row per drive: status, message, frames, fps, modes, alerts
                        per km and per hour, road class, errors (+ drives.csv)
    report.md, report.png   the fleet report
    fleet.json          what this batch was: drives, engine, settings, timings

A drive's errors stay in its row (`roadpreview.batch.drive`); `BatchResult.failed` lists
them and the command exits 1 when there is one.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from roadpreview.batch.drive import BatchSettings, run_drive
from roadpreview.batch.engine import Engine, TaskFailure
from roadpreview.batch.manifest import DriveSpec
from roadpreview.batch.outcome import DriveOutcome

log = logging.getLogger(__name__)

#: the batch's own record in its output folder (a drive's is ``<drive>/batch.json``)
FLEET_JSON = "fleet.json"


@dataclass
class BatchResult:
    """What a batch did: one outcome per drive, in the order the drives were given."""

    outcomes: list[DriveOutcome]
    out: Path
    seconds: float  #: wall time of the drives (engine running), s
    engine: str = ""  #: `Engine.describe`
    files: dict[str, Path] = field(default_factory=dict)  #: tables and report written

    def with_status(self, status: str) -> list[DriveOutcome]:
        return [o for o in self.outcomes if o.status == status]

    @property
    def failed(self) -> list[DriveOutcome]:
        return self.with_status("failed")

    @property
    def done(self) -> list[DriveOutcome]:
        return self.with_status("done")

    @property
    def skipped(self) -> list[DriveOutcome]:
        return self.with_status("skipped")


def _cost(spec: DriveSpec) -> int:
    """Bytes of the drive's camera input: the longest drives go first, so that the last
    task to finish is a short one."""
    path = spec.input
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        return path.stat().st_size
    except OSError:
        return 0


def run_batch(
    specs: Sequence[DriveSpec],
    settings: BatchSettings,
    engine: Engine,
    *,
    progress: bool = True,
    tty: bool | None = None,
    notes: Sequence[str] = (),
) -> BatchResult:
    """Every drive through `run_drive` on ``engine``, longest first; then the fleet tables
    and report in ``settings.out`` (module docstring)."""
    from roadpreview.batch.report import write_report
    from roadpreview.batch.tables import write_tables

    out = settings.out
    out.mkdir(parents=True, exist_ok=True)
    order = sorted(specs, key=_cost, reverse=True)
    t0 = time.perf_counter()
    by_drive: dict[str, DriveOutcome] = {}
    for spec, result in engine.map(
        run_drive,
        order,
        keys=[s.drive for s in order],
        label="batch",
        progress=progress,
        tty=tty,
        settings=settings,
    ):
        if isinstance(result, TaskFailure):
            result = DriveOutcome(spec.drive, "failed", result.message, str(out / spec.drive))
        by_drive[spec.drive] = result
        if result.status == "failed":
            log.error("drive %s failed: %s", spec.drive, result.message)
        else:
            log.info(
                "drive %s %s: %d frames, %d alert(s)",
                spec.drive,
                result.status,
                result.frames,
                result.alerts,
            )
    seconds = time.perf_counter() - t0
    outcomes = [by_drive[s.drive] for s in specs]
    files = write_tables(outcomes, out)
    md, png = write_report(outcomes, out, notes=[engine.describe(), *notes])
    files.update({"report.md": md, "report.png": png})
    batch = BatchResult(outcomes, out, seconds, engine.describe(), files)
    _write_fleet_json(batch, settings)
    return batch


def _write_fleet_json(result: BatchResult, settings: BatchSettings) -> None:
    from roadpreview.apps.summary import versions
    from roadpreview.configtools import to_mapping

    data: dict[str, Any] = {
        "engine": result.engine,
        "seconds": round(result.seconds, 3),
        "drives": len(result.outcomes),
        "done": len(result.done),
        "skipped": len(result.skipped),
        "failed": [{"drive": o.drive, "message": o.message} for o in result.failed],
        "settings": {
            "force": settings.force,
            "truth": settings.truth,
            "allow_missing": settings.allow_missing,
            "package_digest": settings.package,
        },
        "config": to_mapping(settings.config),
        "versions": versions(),
        "files": {k: str(v) for k, v in result.files.items()},
    }
    path = result.out / FLEET_JSON
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1) + "\n")
    os.replace(tmp, path)


__all__ = ["FLEET_JSON", "BatchResult", "run_batch"]
