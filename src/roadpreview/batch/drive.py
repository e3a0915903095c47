"""One drive of a batch, as a Dask task: `run_drive` replays it into its own sub-folder
(``roadpreview replay``'s outputs, plus ``replay.log`` and ``batch.json``), or skips it
when nothing changed since it was last done.

**Skipping.** ``batch.json`` records the drive's fingerprint: the drive's spec, the
digest of its pipeline configuration, the digest of the package's replay code
(`replay_source_digest`, taken once by the client so that every worker agrees), whether
truth was matched, and every input file's size, modification time and SHA-256. A drive
is skipped when its last run ended ``done``, every output file is there, and the
fingerprint is the same: an input whose size changed is changed; one whose size and
modification time are the recorded ones is not; one whose time changed is hashed again
and compared (a copy or a ``touch`` does not re-run a drive). ``force`` re-runs it.

**Failing.** Every error of the drive (an unreadable video, a CAN log that gives nothing,
a source that keeps failing, a bad configuration, a full disk) ends *this* drive with
status ``failed`` and a one-line message; the batch goes on. A drive that kills its
worker outright (out of memory, a crash in a native library) is retried by Dask on a
fresh worker (`roadpreview.batch.engine`).
"""

from __future__ import annotations

import contextlib
import csv
import json
import logging
import math
import os
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from roadpreview.apps.summary import sha256_file
from roadpreview.batch.manifest import DriveSpec
from roadpreview.batch.outcome import MODES, DriveOutcome
from roadpreview.digests import digest
from roadpreview.errors import RoadPreviewError
from roadpreview.pipeline.config import PipelineConfig

log = logging.getLogger(__name__)

#: bump when batch.json's layout or what a drive's run writes changes
BATCH_FORMAT = 1
BATCH_JSON = "batch.json"
REPLAY_LOG = "replay.log"
#: the outputs a finished drive has (besides batch.json)
REQUIRED_OUTPUTS = ("alerts.blf", "alerts.jsonl", "frames.csv", "plots.png", "summary.json")


@dataclass(frozen=True)
class BatchSettings:
    """What every drive of a batch shares (pickled once per task: small)."""

    out: Path  #: the batch's output folder; each drive in ``out/<drive>``
    config: PipelineConfig  #: the batch's pipeline configuration
    package: str  #: `replay_source_digest`, taken by the client
    force: bool = False  #: re-run drives that could be skipped
    truth: bool = False  #: match alerts to a recording folder's true events
    allow_missing: bool = False  #: an input that gives nothing does not fail the drive


def fingerprint(spec: DriveSpec, config: PipelineConfig, settings: BatchSettings) -> dict[str, Any]:
    """What decides whether a drive must run again, but its input files' content."""
    from roadpreview.configtools import to_mapping

    return {
        "format": BATCH_FORMAT,
        "spec": spec.to_json(),
        "config": digest(to_mapping(config)),
        "package": settings.package,
        "truth": settings.truth,
        "allow_missing": settings.allow_missing,
    }


def _stat(path: Path) -> dict[str, Any]:
    st = path.stat()
    return {"path": str(path.resolve()), "size_bytes": st.st_size, "mtime_ns": st.st_mtime_ns}


def _inputs_unchanged(recorded: list[dict[str, Any]]) -> bool:
    """Every recorded input file is there with the same content (module docstring)."""
    for rec in recorded:
        path = Path(rec["path"])
        try:
            now = _stat(path)
        except OSError:
            return False
        if now["size_bytes"] != rec.get("size_bytes"):
            return False
        if now["mtime_ns"] != rec.get("mtime_ns") and sha256_file(path) != rec.get("sha256"):
            return False
    return True


def previous_outcome(folder: Path, fp: dict[str, Any]) -> DriveOutcome | None:
    """The recorded outcome when the drive in ``folder`` can be skipped, else None."""
    try:
        meta = json.loads((folder / BATCH_JSON).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(meta, dict) or meta.get("fingerprint") != fp:
        return None
    outcome = meta.get("outcome") or {}
    if outcome.get("status") not in ("done", "skipped"):
        return None
    if not all((folder / name).is_file() for name in REQUIRED_OUTPUTS):
        return None
    if not _inputs_unchanged(meta.get("inputs", [])):
        return None
    return DriveOutcome.from_json(outcome)


def _write_batch_json(
    folder: Path, fp: dict[str, Any], outcome: DriveOutcome, inputs: list[dict[str, Any]]
) -> None:
    meta = {"fingerprint": fp, "inputs": inputs, "outcome": outcome.to_json()}
    tmp = folder / (BATCH_JSON + ".tmp")
    tmp.write_text(json.dumps(meta, indent=1) + "\n")
    os.replace(tmp, folder / BATCH_JSON)


def _recorded_inputs(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """summary.json's inputs (path, size, SHA-256) with their modification times."""
    out = []
    for rec in summary.get("inputs", []):
        path = Path(rec["path"])
        try:
            out.append({**rec, "mtime_ns": path.stat().st_mtime_ns})
        except OSError:
            continue
    return out


def distance_km(frames_csv: Path) -> float:
    """The distance driven, from ``frames.csv`` (``t_unix_s``, ``ego_speed_mps``; the
    trapezoid rule over the frames with a speed); NaN without any speed."""
    import numpy as np

    try:
        with frames_csv.open(newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader)
            it, iv = header.index("t_unix_s"), header.index("ego_speed_mps")
            rows = [(r[it], r[iv]) for r in reader if len(r) > max(it, iv)]
    except (OSError, StopIteration, ValueError):
        return math.nan
    if not rows:
        return math.nan
    data = np.asarray(rows, dtype=np.float64)
    ok = np.isfinite(data).all(axis=1)
    if ok.sum() < 2:
        return math.nan
    t, v = data[ok, 0], data[ok, 1]
    return float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(t)) / 1000.0)


def _outcome_from(
    spec: DriveSpec, folder: Path, result: Any, summary: dict[str, Any]
) -> DriveOutcome:
    modes = {m: float(summary.get("modes", {}).get(m, {}).get("share", 0.0)) for m in MODES}
    clock = summary.get("clock", {})
    first, last = clock.get("first_frame_rel_s"), clock.get("last_frame_rel_s")
    duration = (last - first) if first is not None and last is not None else math.nan
    truth = summary.get("truth")
    unusable = summary.get("unusable_inputs", [])
    return DriveOutcome(
        drive=spec.drive,
        status="done",
        message="; ".join(u["reason"] for u in unusable),
        folder=str(folder),
        frames=int(summary.get("frames", 0)),
        duration_s=float(duration),
        distance_km=distance_km(folder / "frames.csv"),
        replay_s=float(result.seconds),
        fps=float(result.fps),
        alerts=len(result.alerts),
        modes=modes,
        road_class=summary.get("road_class"),
        decode_failures=int(summary.get("video_decode_failures", 0)),
        input_errors=int(summary.get("can_input_errors", 0)),
        unusable_inputs=len(unusable),
        truth=None
        if truth is None
        else {
            "expected": float(truth["expected"]),
            "hits": float(truth["hits"]),
            "false_alarms": float(truth["false_alarms"]),
            "minutes": duration / 60.0,
        },
        alert_rows=_alert_rows(folder / "alerts.jsonl"),
    )


def _alert_rows(path: Path) -> list[dict[str, Any]]:
    try:
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    except (OSError, ValueError):
        return []


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "local"


class _DriveLog:
    """While a drive runs: the package's log records go to its ``replay.log`` (and not to
    the worker's console, where N drives would interleave)."""

    def __init__(self, path: Path) -> None:
        self.handler = logging.FileHandler(path, mode="w", encoding="utf-8")
        self.handler.setFormatter(
            logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
        )
        self.logger = logging.getLogger("roadpreview")

    def __enter__(self) -> _DriveLog:
        self.level, self.propagate = self.logger.level, self.logger.propagate
        self.logger.addHandler(self.handler)
        self.logger.setLevel(logging.INFO)
        self.logger.propagate = False
        return self

    def __exit__(self, *exc: object) -> None:
        self.logger.removeHandler(self.handler)
        self.logger.setLevel(self.level)
        self.logger.propagate = self.propagate
        self.handler.close()


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    first = text[0] if text else ""
    return (
        first if isinstance(exc, RoadPreviewError | OSError) else f"{type(exc).__name__}: {first}"
    )


def run_drive(spec: DriveSpec, settings: BatchSettings) -> DriveOutcome:
    """Replay one drive into ``settings.out/<drive>``, or skip it (module docstring).
    Never raises for a bad drive: the outcome says ``failed`` and why."""
    from roadpreview.apps.replay import OUTPUT_FILES, replay

    t_task = time.perf_counter()
    folder = settings.out / spec.drive
    worker = _worker_address()
    try:
        config = spec.pipeline_config(settings.config)
        fp = fingerprint(spec, config, settings)
    except (RoadPreviewError, OSError) as exc:
        return DriveOutcome(spec.drive, "failed", _one_line(exc), str(folder), worker=worker)
    if not settings.force:
        earlier = previous_outcome(folder, fp)
        if earlier is not None:
            earlier.status = "skipped"
            earlier.worker = worker
            earlier.task_s = time.perf_counter() - t_task
            return earlier
    t0 = time.perf_counter()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name in (*OUTPUT_FILES, BATCH_JSON):  # no output of an earlier run survives
            (folder / name).unlink(missing_ok=True)
        with _DriveLog(folder / REPLAY_LOG):
            # --truth: the simulator's drives are matched, the others replay without it
            inputs = spec.replay_inputs(truth=settings.truth and spec.is_recording)
            result = replay(
                inputs,
                config,
                folder,
                start_s=spec.start_s,
                end_s=spec.end_s,
                more_inputs=spec.files(),
            )
        summary = json.loads((folder / "summary.json").read_text())
        outcome = _outcome_from(spec, folder, result, summary)
        if outcome.unusable_inputs and not settings.allow_missing:
            outcome.status = "failed"
            outcome.message = f"unusable input: {outcome.message}"
        outcome.worker = worker
        outcome.task_s = time.perf_counter() - t_task
        _write_batch_json(folder, fp, outcome, _recorded_inputs(summary))
        return outcome
    except Exception as exc:  # this drive only: the batch goes on
        message = _one_line(exc)
        try:  # the traceback for whoever looks into it; the tables carry the one line
            with (folder / REPLAY_LOG).open("a", encoding="utf-8") as fh:
                fh.write(f"drive {spec.drive} failed: {message}\n")
                traceback.print_exception(exc, file=fh)
        except OSError:
            pass
        outcome = DriveOutcome(
            spec.drive,
            "failed",
            message,
            str(folder),
            replay_s=time.perf_counter() - t0,
            task_s=time.perf_counter() - t_task,
            worker=worker,
        )
        with contextlib.suppress(OSError):
            _write_batch_json(folder, fp, outcome, [])
        return outcome


__all__ = [
    "BATCH_FORMAT",
    "BATCH_JSON",
    "REQUIRED_OUTPUTS",
    "BatchSettings",
    "distance_km",
    "fingerprint",
    "previous_outcome",
    "run_drive",
]
