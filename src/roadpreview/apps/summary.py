"""``summary.json``: what a replay read, how it was set up and what it found, in one file
that explains itself.

* ``clock``: the Unix time of the video's frame 0; every ``*_rel_s`` time in the file
  (and on the console) is seconds from it.
* ``inputs``: each file read, with its size and SHA-256 (read in 1 MiB chunks).
* ``config``: the whole pipeline configuration; ``versions``: roadpreview, Python and
  the libraries that shape the numbers.
* counts, the fusion modes (their changes with a reason, and each mode's share of
  the drive), the road class, the confirmations, and with ``--truth`` one row per true
  event (hit or miss, the alert that matched it and its timing errors).
* what went wrong with the inputs: ``source_errors`` (samples lost, per source),
  ``inputs_problems`` (per source: reason -> count, e.g. ``skipped_bad_line``,
  ``rejected_range``, ``resynced``, ``missing_frames``, ``thread_died``, ``restarted``),
  ``unusable_inputs`` (inputs that gave nothing, with the reason; the replay ran without
  them) and ``thread_deaths``.

The file is replaced atomically, so a reader never sees half of it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
from collections.abc import Iterable, Sequence
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roadpreview import __version__, configtools
from roadpreview.pipeline.truthmatch import MatchReport
from roadpreview.types import Confirmation, FusionMode

if TYPE_CHECKING:
    from roadpreview.apps.result import ReplayResult
    from roadpreview.pipeline.config import PipelineConfig

#: distributions whose versions the summary records (alternatives: the first installed)
DEPENDENCIES: dict[str, tuple[str, ...]] = {
    "numpy": ("numpy",),
    "scipy": ("scipy",),
    "opencv": ("opencv-python-headless", "opencv-python", "opencv-contrib-python"),
    "filterpy": ("filterpy",),
    "gtsam": ("gtsam",),
    "onnxruntime": ("onnxruntime", "onnxruntime-gpu"),
    "python-can": ("python-can",),
    "cantools": ("cantools",),
}

_CHUNK = 1 << 20


def sha256_file(path: Path) -> str:
    """The SHA-256 of a file, read in chunks (a video of several GB fits in no memory)."""
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        while chunk := fh.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def describe_inputs(paths: Iterable[Path]) -> list[dict[str, Any]]:
    """Path (absolute), size and SHA-256 of each input file (each once)."""
    unique = dict.fromkeys(Path(p).resolve() for p in paths)
    return [
        {"path": str(p), "size_bytes": p.stat().st_size, "sha256": sha256_file(p)} for p in unique
    ]


def versions() -> dict[str, str | None]:
    """roadpreview, Python and the `DEPENDENCIES` (None: not installed)."""
    out: dict[str, str | None] = {
        "roadpreview": __version__,
        "python": platform.python_version(),
    }
    for name, dists in DEPENDENCIES.items():
        out[name] = None
        for dist in dists:
            try:
                out[name] = metadata.version(dist)
                break
            except metadata.PackageNotFoundError:
                continue
    return out


def mode_shares(
    changes: Sequence[tuple[float, FusionMode, str]], last_t: float
) -> dict[str, dict[str, float]]:
    """Seconds spent in each mode from the first frame to ``last_t``, and its share."""
    seconds = {m.name: 0.0 for m in FusionMode}
    for (t, mode, _), nxt in zip(changes, [*changes[1:], None], strict=True):
        end = last_t if nxt is None else nxt[0]
        seconds[mode.name] += max(0.0, end - t)
    total = sum(seconds.values())
    return {
        name: {"seconds": round(s, 3), "share": round(s / total, 4) if total > 0 else 0.0}
        for name, s in seconds.items()
    }


def _num(x: float | None, digits: int = 3) -> float | None:
    """A finite number rounded; None for NaN, inf or None (JSON has no NaN)."""
    return None if x is None or not math.isfinite(x) else round(x, digits)


def truth_rows(match: MatchReport) -> list[dict[str, Any]]:
    """One row per true event: when and where the lead crossed it, hit or miss, and the
    alert that matched (its id, crossing-time error, predicted and true time to arrival)."""
    rows = []
    for r in match.rows:
        a = r.alert
        rows.append(
            {
                "event": r.event_index,
                "kind": r.kind,
                "lead_side": r.lead_side,
                "height_mm": _num(r.height_mm, 1),
                "t_lead_rel_s": _num(r.t_lead_s),
                "lead_distance_m": _num(r.distance_m, 2),
                "expected": r.expected,
                "outcome": r.outcome,
                "alert_id": None if a is None else a.alert_id,
                "alert_height_mm": None if a is None else _num(a.height_mm, 1),
                "alert_distance_m": None if a is None else _num(a.distance_m, 2),
                "crossing_error_s": _num(r.crossing_error_s),
                "tta_true_s": _num(r.tta_true_s),
                "tta_error_s": _num(r.tta_error_s),
                "lead_time_s": _num(r.lead_time_s),
                "latency_first_s": _num(r.latency_s),
                "latency_confirmed_s": _num(r.latency_confirmed_s),
                "headway_s": _num(r.headway_s),
            }
        )
    return rows


def summary_dict(
    result: ReplayResult, config: PipelineConfig, files: Sequence[Path] = ()
) -> dict[str, Any]:
    """The content of ``summary.json`` (module docstring)."""
    s = result.run
    start = result.video_start_s
    summary: dict[str, Any] = {
        "interrupted": s.interrupted,
        "error": s.error,
        "clock": {
            "frame0_unix_s": round(start, 6),
            "first_frame_rel_s": _num(s.first_t - start),
            "last_frame_rel_s": _num(s.last_t - start),
            "note": "*_rel_s: seconds from the video's frame 0 (frame0_unix_s)",
            "rules": result.clock_notes,  # how each input was put on this clock
        },
        "frames": s.frames,
        "seconds": round(s.seconds, 3),
        "fps": _num(s.fps, 2),
        "alerts": len(s.alerts),
        "provisional_alerts": len(s.provisional),
        "provisional_cancelled": len(s.cancelled),
        "video_decode_failures": result.decode_failures,
        "can_input_errors": result.input_errors,
        "frames_out_of_order": s.frames_out_of_order,
        "sink_errors": s.sink_errors,
        "source_errors": dict(s.source_errors),
        "inputs_problems": {name: dict(p) for name, p in s.source_problems.items()},
        "unusable_inputs": list(result.unusable_inputs),
        "thread_deaths": dict(s.thread_deaths),
        "mode_changes": [
            {"t_rel_s": round(t - start, 3), "mode": m.name, "reason": why}
            for t, m, why in s.mode_changes
        ],
        "modes": mode_shares(s.mode_changes, s.last_t),
        "detector": config.anomaly.detector,
        "road_class": result.road.iso_class,
        "road_class_ego": result.road.ego_class,
        "road_class_lead": result.road.lead_class,
        "confirmations": {
            c.name: sum(x.outcome is c for x in s.confirmations) for c in Confirmation
        },
        "pending_confirmations": len(s.alerts) - len(s.confirmations),
        "inputs": describe_inputs(files),
        "config": configtools.to_mapping(config),
        "versions": versions(),
    }
    match = result.match
    if match is not None:
        summary["truth"] = {
            "expected": match.expected,
            "hits": match.hits,
            "false_alarms": len(match.false_alarms),
            "false_alarms_per_min": _num(match.false_alarms_per_min),
            "events": truth_rows(match),
            "false_alarm_alert_ids": [a.alert_id for a in match.false_alarms],
        }
        p = match.provisional
        if p is not None:
            summary["truth"]["provisional"] = {
                "alerts": p.alerts,
                "confirmed": p.confirmed,
                "hits": p.hits,
                "false_alarms": p.false_alarms,
                "false_alarms_per_min": _num(p.false_alarms_per_min),
                "cancelled_in_time": p.cancelled_in_time,
            }
    return summary


def write_summary(
    path: Path, result: ReplayResult, config: PipelineConfig, *, files: Sequence[Path] = ()
) -> None:
    """Write ``summary.json`` (module docstring); ``files``: the inputs read."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(summary_dict(result, config, files), indent=2) + "\n")
    os.replace(tmp, path)
