"""E6 'Alert timing': when the first ``RP_ALERT`` goes out, and what provisional alerts cost.

Per hit (a lead crossing with an expected signal f|δ|/d >= `RECALL_MIN_SIGNAL_PX` that a
confirmed alert matched, `roadpreview.pipeline.truthmatch`):

* the **latency** of the first ``RP_ALERT`` (the provisional one, if the alert had one)
  and of the confirmation, after the lead's front axle crossed the anomaly's apex;
* the **lead time** left for the ego (its front axle at the anomaly minus the first
  ``RP_ALERT``) and the **time headway** (the ego's arrival minus the lead's).

Provisional alerts: their false alarms per minute, the share of those CANCELLED before the
ego would have reached the spot they named, and the confirmed alerts' recall and false
alarms beside them (the provisional stage must not change those).

The provisional threshold (``[anomaly.two_axle] provisional_threshold_z``) is chosen as
the main one is: per fold of the wild set, the lowest of `PROVISIONAL_GRID` keeping the
training folds at or below `PROVISIONAL_FA_PER_MIN` provisional false alarms per minute;
the held-out folds' figures are pooled. The generalization suite (never tuned on) is
reported at the shipped threshold, per drive. The provisional confidence's logistic fit
(``provisional_confidence_logit``) is made on the wild drives' provisional alerts at the
shipped threshold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from roadpreview.eval.experiments.base import jf as _f
from roadpreview.eval.product import RECALL_MIN_SIGNAL_PX, _folds, fit_logistic, signal_px
from roadpreview.pipeline.truthmatch import FIRST_ALERT_LATENCY_S, match_alerts

if TYPE_CHECKING:
    from roadpreview.anomaly.config import AnomalyConfig
    from roadpreview.eval.detectors import DetectorTrace
    from roadpreview.eval.experiments import EvalData
    from roadpreview.eval.runner import RecordingJob

#: provisional thresholds the operating point is chosen from (background stds)
PROVISIONAL_GRID: tuple[float, ...] = (3.0, 3.5, 4.0, 4.5, 5.0, 5.5, 6.0, 7.0, 8.0)
#: the provisional false alarms per minute the threshold is chosen for (the issue's target)
PROVISIONAL_FA_PER_MIN = 1.0
#: the lead-time target applies at this time headway and above, s
HEADWAY_MIN_S = 1.5
#: ... and asks for this much lead time, s
LEAD_TIME_MIN_S = 1.0


@dataclass
class Timing:
    """Timing and provisional tallies over some recordings."""

    expected: int = 0
    hits: int = 0
    false_alarms: int = 0  #: confirmed false alarms
    minutes: float = 0.0
    latency: list[float] = field(default_factory=list)  #: first RP_ALERT, per hit, s
    latency_confirmed: list[float] = field(default_factory=list)
    lead_time: list[float] = field(default_factory=list)  #: per hit with an arrival, s
    headway: list[float] = field(default_factory=list)  #: ... its time headway, s
    provisional: int = 0
    provisional_hits: int = 0
    provisional_confirmed: int = 0
    provisional_false: int = 0
    cancelled_in_time: int = 0
    late: int = 0  #: hits whose first RP_ALERT came after the ego arrived

    def add(self, o: Timing) -> None:
        for k, v in vars(o).items():
            if isinstance(v, list):
                getattr(self, k).extend(v)
            else:
                setattr(self, k, getattr(self, k) + v)

    @property
    def provisional_fa_per_min(self) -> float:
        return self.provisional_false / self.minutes if self.minutes else math.nan

    def as_dict(self) -> dict[str, Any]:
        lat = np.asarray(self.latency)
        latc = np.asarray(self.latency_confirmed)
        lead = np.asarray(self.lead_time)
        hw = np.asarray(self.headway)
        far = hw >= HEADWAY_MIN_S
        return {
            "expected": self.expected,
            "hits": self.hits,
            "recall": _f(self.hits / self.expected if self.expected else math.nan),
            "false_alarms": self.false_alarms,
            "fa_per_min": _f(self.false_alarms / self.minutes if self.minutes else math.nan),
            "minutes": _f(self.minutes),
            "latency_le_target": int(np.count_nonzero(lat <= FIRST_ALERT_LATENCY_S)),
            "latency_share": _f(
                float(np.mean(lat <= FIRST_ALERT_LATENCY_S)) if lat.size else math.nan
            ),
            "latency_median_s": _f(float(np.median(lat)) if lat.size else math.nan),
            "latency_p90_s": _f(float(np.percentile(lat, 90)) if lat.size else math.nan),
            "latency_confirmed_median_s": _f(float(np.median(latc)) if latc.size else math.nan),
            "lead_time_median_s": _f(float(np.median(lead)) if lead.size else math.nan),
            "headway_far": int(np.count_nonzero(far)),
            "lead_time_far_min_s": _f(float(lead[far].min()) if far.any() else math.nan),
            "lead_time_far_short": int(np.count_nonzero(far & (lead < LEAD_TIME_MIN_S))),
            "late": self.late,
            "provisional": self.provisional,
            "provisional_hits": self.provisional_hits,
            "provisional_confirmed": self.provisional_confirmed,
            "provisional_false": self.provisional_false,
            "provisional_fa_per_min": _f(self.provisional_fa_per_min),
            "cancelled_in_time": self.cancelled_in_time,
            "cancelled_share": _f(
                self.cancelled_in_time / self.provisional_false
                if self.provisional_false
                else math.nan
            ),
        }


def timing(run: DetectorTrace, info: dict[str, Any], f_px: float) -> Timing:
    """One recording's `Timing` from a detector run."""
    rep = match_alerts(
        run.alerts,
        info["events"],
        t0=0.0,
        duration_s=float(info["duration_s"]),
        max_distance_m=math.inf,
        provisional=run.provisional,
        cancelled=run.cancelled,
    )
    events = {int(e["index"]): e for e in info["events"]}
    out = Timing(false_alarms=len(rep.false_alarms), minutes=float(info["duration_s"]) / 60.0)
    for r in rep.rows:
        if not (r.expected and signal_px(events[r.event_index], f_px) >= RECALL_MIN_SIGNAL_PX):
            continue
        out.expected += 1
        if r.alert is None:
            continue
        out.hits += 1
        out.latency.append(r.latency_s)
        out.latency_confirmed.append(r.latency_confirmed_s)
        if math.isfinite(r.lead_time_s):
            out.lead_time.append(r.lead_time_s)
            out.headway.append(r.headway_s)
            out.late += r.lead_time_s < 0
    p = rep.provisional
    if p is not None:
        out.provisional = p.alerts
        out.provisional_hits = p.hits
        out.provisional_confirmed = p.confirmed
        out.provisional_false = p.false_alarms
        out.cancelled_in_time = p.cancelled_in_time
    return out


def _at(anomaly: AnomalyConfig, threshold: float) -> AnomalyConfig:
    return replace(anomaly, two_axle=replace(anomaly.two_axle, provisional_threshold_z=threshold))


def _run(data: EvalData, job: RecordingJob, method: str, threshold: float) -> DetectorTrace:
    anomaly = data.methods.configs[method].anomaly
    if threshold == anomaly.two_axle.provisional_threshold_z:
        return data.detection(job, method)
    return data.detection_with(job, method, f"provisional@{threshold:g}", _at(anomaly, threshold))


def provisional_points(data: EvalData) -> dict[str, Any]:
    """The module docstring's figures, JSON-ready (two-axle product detector only)."""
    m = data.methods.reference
    anomaly = data.methods.configs[m].anomaly
    shipped = anomaly.two_axle.provisional_threshold_z
    wild = {j.key: j for j in data.jobs["wild"]}
    grid = PROVISIONAL_GRID[:: data.plan.threshold_stride]
    tallies = {
        (key, thr): timing(_run(data, job, m, thr), data.info(job), data.focal_px(job))
        for key, job in wild.items()
        for thr in grid
    }
    keys = list(wild)
    folds = _folds(sorted(keys), data.plan.cv_k, data.plan.cv_seed)
    held = Timing()
    chosen = []
    for test in folds:
        train = [k for k in keys if k not in test]
        thr = math.inf
        for cand in grid:
            total = Timing()
            for k in train:
                total.add(tallies[(k, cand)])
            if total.provisional_fa_per_min <= PROVISIONAL_FA_PER_MIN:
                thr = cand
                break
        chosen.append(thr)
        for k in test:
            held.add(tallies[(k, thr if math.isfinite(thr) else grid[-1])])
    curve = []
    for thr in grid:
        total = Timing()
        for k in keys:
            total.add(tallies[(k, thr)])
        curve.append({"threshold": thr, **total.as_dict()})
    out: dict[str, Any] = {
        "method": m,
        "shipped_threshold": shipped,
        "fa_target_per_min": PROVISIONAL_FA_PER_MIN,
        "latency_target_s": FIRST_ALERT_LATENCY_S,
        "headway_min_s": HEADWAY_MIN_S,
        "lead_time_min_s": LEAD_TIME_MIN_S,
        "curve": curve,
        "held_out": {**held.as_dict(), "thresholds": [_f(t) for t in chosen]},
        "wild_shipped": _shipped(data, "wild", m).as_dict(),
        "calibration": _calibration(data, m),
    }
    without = replace(anomaly, two_axle=replace(anomaly.two_axle, provisional=False))
    base = Timing()
    for job in wild.values():
        run = data.detection_with(job, m, "no-provisional", without)
        base.add(timing(run, data.info(job), data.focal_px(job)))
    out["wild_without"] = base.as_dict()
    if data.jobs.get("generalization"):
        per_drive = {}
        pooled = Timing()
        for job in data.jobs["generalization"]:
            t = timing(data.detection(job, m), data.info(job), data.focal_px(job))
            per_drive[job.name] = t.as_dict()
            pooled.add(t)
        out["generalization"] = {"pooled": pooled.as_dict(), "drives": per_drive}
    return out


def _shipped(data: EvalData, dataset: str, method: str) -> Timing:
    total = Timing()
    for job in data.jobs[dataset]:
        total.add(timing(data.detection(job, method), data.info(job), data.focal_px(job)))
    return total


def _calibration(data: EvalData, method: str) -> dict[str, Any]:
    """The logistic fit of a provisional alert's being real on ln(z / threshold), over
    the wild drives' provisional alerts at the shipped threshold."""
    x: list[float] = []
    y: list[bool] = []
    for job in data.jobs["wild"]:
        run = data.detection(job, method)
        info = data.info(job)
        rep = match_alerts(
            run.provisional,
            info["events"],
            t0=0.0,
            duration_s=float(info["duration_s"]),
            max_distance_m=math.inf,
        )
        real = {id(r.alert) for r in rep.rows if r.alert is not None}
        thr = data.methods.configs[method].anomaly.two_axle.provisional_threshold_z
        for a in run.provisional:
            x.append(math.log(max(a.severity_px, 1e-9) / thr))
            y.append(id(a) in real)
    if len(set(y)) < 2:
        return {"n": len(y), "real": int(sum(y)), "logit": None}
    fa, fb = fit_logistic(np.asarray(x), np.asarray(y, dtype=bool))
    return {"n": len(y), "real": int(sum(y)), "logit": [_f(fa), _f(fb)]}


__all__ = ["PROVISIONAL_GRID", "Timing", "provisional_points", "timing"]
