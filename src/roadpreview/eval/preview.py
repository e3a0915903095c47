"""E6 'Road preview': the ``RP_PREVIEW`` profile against the simulator's road.

The product method's stored trajectory goes through `roadpreview.preview.ProfileEstimator`
exactly as inside the pipeline (restarted where the tracker changed target); every preview
is compared with the true road of its drive (`roadpreview.eval.road_truth.compare`: the bins
whose spot the lead's wheels passed within the last `RECENT_S`, each side's least-squares
line removed as the preview's). Per drive: the RMS height error, the true road's RMS at
the same bins (the error's scale), the bins compared and the correlation of the ego's
vertical acceleration predicted from the preview with the one it then had. Pooled by road
class: A-C (the issue's target) and D-E, on the wild set and, apart, the generalization
suite (never tuned on: the preview has no tuned parameter; its roughness prior is ISO
8608 class B's level).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from roadpreview.eval.experiments.base import jf as _f
from roadpreview.eval.road_truth import compare, drive_for_scenario
from roadpreview.preview import ProfileEstimator
from roadpreview.types import Alert, RoadPreview

if TYPE_CHECKING:
    from roadpreview.eval.detectors import DetectorTrace
    from roadpreview.eval.experiments import EvalData
    from roadpreview.eval.runner import RecordingJob, Trace

#: bins the lead's wheels passed within this long before the preview are compared, s
RECENT_S = 2.0
#: the road classes of the target
TARGET_CLASSES = ("A", "B", "C")


def previews_of(
    trace: Trace, estimator: ProfileEstimator, run: DetectorTrace | None = None
) -> list[RoadPreview]:
    """Every preview of ``trace``'s trajectory (as `roadpreview.pipeline.Pipeline`), with
    the confirmed alerts of the detector's ``run`` over it, each from the frame it was
    confirmed at."""
    changed = trace["target_changed"]
    alerts: list[Alert] = sorted(run.alerts, key=lambda a: a.t_emit_s) if run else []
    k = 0
    out = []
    for i, sample in enumerate(trace.samples()):
        if changed[i]:
            estimator.restart()
        while k < len(alerts) and alerts[k].t_emit_s <= sample.t + 1e-9:
            estimator.add_alert(alerts[k])
            k += 1
        p = estimator.push(sample)
        if p is not None:
            out.append(p)
    return out


def drive_errors(data: EvalData, job: RecordingJob, method: str) -> dict[str, Any]:
    """One drive's preview errors (module docstring): the product's (the profile with the
    alerts' bins), the profile alone, and the profile alone on the true compensated
    trajectory (every term of the compensation and the tracked row from the truth: the
    ceiling the trajectory sets)."""
    from roadpreview.eval.experiments.budget import frame_truth, substitute, variants

    cfg = data.methods.configs[method]

    cy = job.scenario.camera_model().cy

    def fresh() -> ProfileEstimator:
        return ProfileEstimator(cfg.preview, cfg.anomaly.two_axle.vehicle, principal_row_px=cy)

    trace = data.traces(job)[method]
    drive = drive_for_scenario(job.scenario)
    previews = previews_of(trace, fresh(), data.detection(job, method))
    err = compare(previews, drive, recent_s=RECENT_S)
    alone = compare(previews_of(trace, fresh()), drive, recent_s=RECENT_S)
    truth = frame_truth(data.truth(job), trace.t, data.focal_px(job))
    every = list(variants().values())[-1]
    ceiling = compare(previews_of(substitute(trace, truth, every), fresh()), drive)
    valid = [float(p.valid.mean()) for p in previews if p.valid.size]
    return {
        "road_class": job.scenario.motion.road.iso_class,
        "rms_mm": _f(err.rms_mm),
        "rms_alone_mm": _f(alone.rms_mm),
        "rms_true_trajectory_mm": _f(ceiling.rms_mm),
        "max_abs_mm": _f(err.max_abs_mm),
        "true_rms_mm": _f(err.true_rms_mm),
        "bins": err.n_bins,
        "accel_correlation": _f(err.accel_correlation),
        "previews": len(previews),
        "valid_share": _f(float(np.mean(valid)) if valid else math.nan),
    }


def _pool(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """RMS over every bin of ``rows`` (each drive weighted by its bins)."""
    n = sum(r["bins"] for r in rows)
    if not n:
        return {"drives": len(rows), "bins": 0, "rms_mm": None, "true_rms_mm": None}

    def rms(k: str) -> float:
        ok = [r for r in rows if r["bins"] and r[k] is not None]
        m = sum(r["bins"] for r in ok)
        return math.sqrt(sum(r["bins"] * r[k] ** 2 for r in ok) / m) if m else math.nan

    corr = [r["accel_correlation"] for r in rows if r["accel_correlation"] is not None]
    return {
        "drives": len(rows),
        "bins": n,
        "rms_mm": _f(rms("rms_mm")),
        "rms_alone_mm": _f(rms("rms_alone_mm")),
        "rms_true_trajectory_mm": _f(rms("rms_true_trajectory_mm")),
        "true_rms_mm": _f(rms("true_rms_mm")),
        "accel_correlation_median": _f(float(np.median(corr)) if corr else math.nan),
    }


def preview_errors(data: EvalData) -> dict[str, Any]:
    """The module docstring's figures for the product method, JSON-ready."""
    m = data.methods.reference
    out: dict[str, Any] = {"method": m, "recent_s": RECENT_S, "target_classes": TARGET_CLASSES}
    for dataset in ("wild", "generalization"):
        jobs = data.jobs.get(dataset) or []
        if not jobs:
            continue
        drives = {job.name: drive_errors(data, job, m) for job in jobs}
        rows = list(drives.values())
        out[dataset] = {
            "drives": drives,
            "target": _pool([r for r in rows if r["road_class"] in TARGET_CLASSES]),
            "rough": _pool([r for r in rows if r["road_class"] not in TARGET_CLASSES]),
        }
    return out


__all__ = ["RECENT_S", "drive_errors", "preview_errors", "previews_of"]
