"""E7: the compensation's error budget. Where does the product's y_c part from the truth,
and what does each part cost the detector?

The residual r(t) = y_c(t) - y_c,true(t) per frame, y_c,true the *true* compensated row
(`ceiling.true_compensated_y`: the rendered row of the lead's rear centre less the true
pitch and heave terms). The product's y_c = y - f tan φ - H (`roadpreview.compensation`)
has four inputs, each replaced by the simulator's truth, one at a time and cumulatively
in `TERMS` order:

* ``pitch``: φ -> the camera's true pitch;
* ``heave``: the heave term's Δz -> the camera's true heave (its height less its centred
  3 s mean, as the ceiling's), over the product's lead distance;
* ``distance``: the heave term's d -> the true lead distance;
* ``tracking``: y (the tracked grid's mean row) -> the rendered row of the lead's rear
  centre.

With all four substituted r is 0 wherever the product had a lead; frames without one stay
without (a lost lead is not a compensation error: `BudgetRow.lead_frames` counts them).
Each variant is the product's trace with y_c, its halves (moved by the same amount) and
the compensation term replaced (`substitute`), run through the same detectors as the
methods. Per variant:

* the 1 s-window std of r (detrended as the detector's s: `ceiling.windowed_std`), median
  and 95th percentile over the frames, px at the drive's resolution and mrad (px / f);
* each detector's AUC on the data set's clips, entire and hard (wild set);
* the product detector's recall (f|δ|/d >= 1 px) at <= 0.5 false alarms per minute on the
  held-out folds (`product.held_out_at_rate`, wild set), and at the shipped threshold.

A term's cost is the AUC it takes away: the variant with only that term true less the
product (`Budget.costs`). The truth substitutions use `roadpreview.compensation.compensate`,
the same function the pipeline's stage computes y_c with.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from roadpreview.anomaly import DETECTORS
from roadpreview.anomaly.config import AnomalyConfig
from roadpreview.compensation import compensate, heave_term_px
from roadpreview.eval.clips import window_max
from roadpreview.eval.detectors import (
    THRESHOLD_FIELDS,
    DetectorTrace,
    at_threshold,
    run_detector,
)
from roadpreview.eval.experiments.base import Array, jf
from roadpreview.eval.experiments.ceiling import (
    CEILING_HEAVE_SPAN_S,
    true_compensated_y,
    windowed_std,
)
from roadpreview.eval.experiments.data import EvalData
from roadpreview.eval.metrics import auc
from roadpreview.eval.runner import RecordingJob, Trace
from roadpreview.types import Alert

#: the substituted terms, in the cumulative order
TERMS = ("pitch", "heave", "distance", "tracking")
#: the budget's method: the product (its Kalman back end), and the factor graph beside it
BUDGET_METHODS = ("fused-kalman", "fused-fg")
#: the false-alarm rate of the budget's recall, per minute
BUDGET_FA_PER_MIN = 0.5


@dataclass(frozen=True)
class FrameTruth:
    """The truth at a trace's frames (NaN where no rendered frame matches)."""

    y: Array  #: the lead's rear centre row, px
    pitch_px: Array  #: f tan(true pitch), px
    dz_m: Array  #: the camera's true heave (height less its centred 3 s mean), m
    distance_m: Array  #: the true lead distance, m
    y_c: Array  #: the true compensated row, px


def frame_truth(truth: dict[str, Array], t: Array, f_px: float) -> FrameTruth:
    """`FrameTruth` at the frame times ``t`` (recording clock): each frame matched to the
    rendered frame nearest in time, within a quarter frame interval."""
    tt, yc_true, d_true = true_compensated_y(truth, f_px)
    z = np.asarray(truth["cam_z_m"], dtype=np.float64)
    k = max(1, round(CEILING_HEAVE_SPAN_S / float(np.median(np.diff(tt)))) | 1)
    mean = np.convolve(np.pad(z, (k // 2, k // 2), mode="edge"), np.ones(k) / k, mode="valid")
    idx = np.clip(np.searchsorted(tt, t), 1, tt.size - 1)
    idx = np.where(np.abs(tt[idx - 1] - t) < np.abs(tt[idx] - t), idx - 1, idx)
    ok = np.abs(tt[idx] - t) <= 0.25 * float(np.median(np.diff(tt)))

    def at(a: Array) -> Array:
        return np.where(ok, a[idx], np.nan)

    return FrameTruth(
        y=at(np.asarray(truth["lead_rear_px"], dtype=np.float64)[:, 1]),
        pitch_px=at(f_px * np.tan(np.asarray(truth["cam_pitch_rad"], dtype=np.float64))),
        dz_m=at(z - mean),
        distance_m=at(d_true),
        y_c=at(yc_true),
    )


def substitute(trace: Trace, truth: FrameTruth, terms: tuple[str, ...]) -> Trace:
    """``trace`` with the ``terms`` of its compensation replaced by the truth (module
    docstring): y_c recomputed by `compensate`, the halves moved with it, the compensation
    term and the detector input's y_c replaced."""
    f = trace.focal_px
    y = trace["y"]
    heave_px = trace["heave_px"]
    # the pitch term the pipeline subtracted (0 on a frame whose fusion diverged)
    pitch_px = trace["traj_compensation_px"] - heave_px
    phi = np.arctan(pitch_px / f)
    if "pitch" in terms:
        phi = np.arctan(truth.pitch_px / f)
    if "heave" in terms or "distance" in terms:
        d = truth.distance_m if "distance" in terms else trace["lead_distance_m"]
        if "heave" in terms:
            heave_px = heave_term_px(truth.dz_m, d, f)
        else:  # the product's Δz over the true distance
            with np.errstate(invalid="ignore", divide="ignore"):
                heave_px = heave_px * trace["lead_distance_m"] / d
            heave_px = np.where(np.isfinite(heave_px), heave_px, trace["heave_px"])
    if "tracking" in terms:
        y = np.where(np.isfinite(y), truth.y, np.nan)
    y_c = compensate(y, phi, f, heave_px)
    old = trace["traj_y_c"]
    delta = y_c - old
    cols = dict(trace.columns)
    cols["y_c"] = y_c
    cols["traj_y_c"] = y_c
    for half in ("traj_y_c_left", "traj_y_c_right"):
        cols[half] = trace[half] + delta
    cols["traj_compensation_px"] = f * np.tan(phi) + heave_px
    cols["traj_valid"] = (trace["traj_valid"] > 0) & np.isfinite(y_c)
    return replace(trace, columns=cols)


def residual_std(trace: Trace, truth: FrameTruth) -> Array:
    """The 1 s-window std of r = y_c - y_c,true per frame (px; NaN where undefined)."""
    r = trace["traj_y_c"] - truth.y_c
    return windowed_std(trace.t, r)


def variants() -> dict[str, tuple[str, ...]]:
    """Variant name -> the terms it takes from the truth: the product, each term alone,
    then cumulatively (the last is the truth wherever the product had a lead)."""
    out: dict[str, tuple[str, ...]] = {"product": ()}
    out.update({f"{t} only": (t,) for t in TERMS})
    for i in range(1, len(TERMS) + 1):
        out["+ " + " + ".join(TERMS[:i])] = TERMS[:i]
    return out


@dataclass(frozen=True)
class BudgetRow:
    """One variant on one data set."""

    terms: tuple[str, ...]
    r_std_px: tuple[float, float]  #: median, 95th percentile of the 1 s std of r
    r_std_mrad: tuple[float, float]
    auc: dict[str, dict[str, float]]  #: detector -> {"entire", "hard"}
    recall_held_out: dict[str, Any]  #: at <= BUDGET_FA_PER_MIN, held-out folds
    at_shipped: dict[str, Any]  #: recall / false alarms at the shipped threshold
    lead_frames: int  #: frames with a lead (the rest have no y_c in any variant)

    def as_dict(self) -> dict[str, Any]:
        return {
            "terms": list(self.terms),
            "r_std_px": [jf(v) for v in self.r_std_px],
            "r_std_mrad": [jf(v) for v in self.r_std_mrad],
            "auc": {d: {k: jf(v) for k, v in a.items()} for d, a in self.auc.items()},
            "recall_held_out": self.recall_held_out,
            "at_shipped": self.at_shipped,
            "lead_frames": self.lead_frames,
        }


@dataclass(frozen=True)
class Budget:
    """E7 for one method on one data set."""

    dataset: str
    method: str
    rows: dict[str, BudgetRow]

    def costs(self, detector: str = "two-axle", subset: str = "entire") -> dict[str, float]:
        """Per term: the AUC of the variant with only that term true less the product's."""

        def auc_of(name: str) -> float:
            row = self.rows.get(name)
            return math.nan if row is None else row.auc.get(detector, {}).get(subset, math.nan)

        base = auc_of("product")
        return {t: auc_of(f"{t} only") - base for t in TERMS}

    def largest(self, n: int = 3, detector: str = "two-axle") -> list[str]:
        """The ``n`` terms that cost the most AUC (entire), largest first."""
        c = self.costs(detector)
        known = [t for t in TERMS if math.isfinite(c[t])]
        return sorted(known, key=lambda t: -c[t])[:n]

    def as_dict(self) -> dict[str, Any]:
        return {
            "dataset": self.dataset,
            "method": self.method,
            "rows": {k: v.as_dict() for k, v in self.rows.items()},
            "costs": {d: {k: jf(v) for k, v in self.costs(d).items()} for d in ("two-axle", "std")},
            "largest": self.largest(),
        }


def _pcts(x: Array) -> tuple[float, float]:
    x = x[np.isfinite(x)]
    if x.size == 0:
        return math.nan, math.nan
    return float(np.median(x)), float(np.percentile(x, 95))


def budget(
    data: EvalData, dataset: str = "wild", method: str = "fused-kalman", *, detect: bool = True
) -> Budget:
    """E7 (module docstring) of ``method`` on ``dataset``; ``detect`` False: the residual's
    figures only (no detector runs)."""
    from roadpreview.eval.product import held_out_at_rate, tally_at

    jobs = data.jobs[dataset]
    anomaly = data.methods.configs[method].anomaly
    det_p = data.product_detector
    shipped = float(getattr(getattr(anomaly, DETECTORS[det_p][2]), THRESHOLD_FIELDS[det_p]))
    truths = {
        j.key: frame_truth(data.truth(j), data.traces(j)[method].t, data.focal_px(j)) for j in jobs
    }
    rows: dict[str, BudgetRow] = {}
    chosen = data.plan.budget_variants
    for name, terms in variants().items():
        if chosen is not None and name not in chosen:
            continue
        same = next((r for r in rows.values() if r.terms == terms), None)
        if same is not None:  # ("pitch only" is "+ pitch")
            rows[name] = same
            continue
        traces = {j.key: substitute(data.traces(j)[method], truths[j.key], terms) for j in jobs}
        stds = [residual_std(traces[j.key], truths[j.key]) for j in jobs]
        mrad = [1e3 * s / data.focal_px(j) for s, j in zip(stds, jobs, strict=True)]
        n_lead = sum(int(np.isfinite(tr["traj_y_c"]).sum()) for tr in traces.values())
        aucs: dict[str, dict[str, float]] = {}
        held: dict[str, Any] = {}
        at_shipped: dict[str, Any] = {}
        if detect:
            alerts_at = _Alerts(traces, anomaly, det_p)

            if dataset == "wild":
                aucs = _aucs(data, dataset, traces, anomaly, (alerts_at, shipped))
                # the sweep (3 more runs a drive) for the product and the truth's rows
                if name in ("product", "+ pitch", "+ " + " + ".join(TERMS)):
                    held = held_out_at_rate(
                        data, dataset, det_p, alerts_at, BUDGET_FA_PER_MIN, stride=2
                    )
            at_shipped = tally_at(data, dataset, functools.partial(_at, alerts_at, shipped))
        rows[name] = BudgetRow(
            terms=terms,
            r_std_px=_pcts(np.concatenate(stds)),
            r_std_mrad=_pcts(np.concatenate(mrad)),
            auc=aucs,
            recall_held_out=held,
            at_shipped=at_shipped,
            lead_frames=n_lead,
        )
    return Budget(dataset, method, rows)


def _at(alerts: _Alerts, thr: float, job: RecordingJob) -> list[Alert]:
    return alerts(job, thr)


class _Alerts:
    """``(job, threshold) -> alerts`` of one detector over a variant's traces, each run once
    (`run` keeps the whole `DetectorTrace`: the AUC reuses the shipped threshold's)."""

    def __init__(self, traces: dict[str, Trace], anomaly: AnomalyConfig, detector: str) -> None:
        self.traces, self.anomaly, self.detector = traces, anomaly, detector
        self.runs: dict[tuple[str, float], DetectorTrace] = {}

    def run(self, key: str, thr: float) -> DetectorTrace:
        if (key, thr) not in self.runs:
            cfg = at_threshold(self.anomaly, self.detector, thr)
            self.runs[(key, thr)] = run_detector(self.traces[key], cfg, self.detector)
        return self.runs[(key, thr)]

    def __call__(self, job: RecordingJob, thr: float) -> list[Alert]:
        return self.run(job.key, thr).alerts


def _aucs(
    data: EvalData,
    dataset: str,
    traces: dict[str, Trace],
    anomaly: AnomalyConfig,
    product: tuple[_Alerts, float],
) -> dict[str, dict[str, float]]:
    """Each detector's AUC (entire, hard) on the data set's clips, scored on ``traces``
    as a method's (`clips.window_max` of the detector's score around each clip); the
    product detector's runs at its shipped threshold come from ``product``."""
    out: dict[str, dict[str, float]] = {}
    alerts, shipped = product
    for det in data.detectors:
        table = data.clip_table(dataset, detector=det)
        runs = {
            k: alerts.run(k, shipped) if det == alerts.detector else run_detector(tr, anomaly, det)
            for k, tr in traces.items()
        }
        window = data.score_window(det)
        sc = np.asarray(
            [
                window_max(
                    runs[c.recording].t_score, runs[c.recording].score, c.t_center_s, window
                )[0]
                for c in table.clips  # clips, not frames
            ]
        )
        hard = table.hard
        out[det] = {
            "entire": auc(sc, table.labels),
            "hard": auc(sc[hard], table.labels[hard]),
        }
    return out


def pitch_errors(data: EvalData, dataset: str) -> dict[str, list[Any]]:
    """Per method with a pitch: the detrended 1 s std of its pitch error (deg; median and
    95th percentile over the frames of ``dataset``)."""
    out: dict[str, list[Any]] = {}
    for m in data.method_names:
        if not data.spec(m).compensated:
            continue
        vals = []
        for job in data.jobs[dataset]:
            tr = data.traces(job)[m]
            ft = frame_truth(data.truth(job), tr.t, data.focal_px(job))
            err = np.degrees(tr["phi"] - np.arctan(ft.pitch_px / data.focal_px(job)))
            vals.append(windowed_std(tr.t, err))
        out[m] = [jf(v) for v in _pcts(np.concatenate(vals))]
    return out


def e7_budget(data: EvalData) -> dict[str, Any]:
    """E7 on the wild set (the product's budget with the detectors, the factor graph's
    residual beside it) and the generalization suite (the product's), and every method's
    pitch error, when the run has the data sets."""
    budgets: dict[str, Any] = {}
    pitch: dict[str, Any] = {}
    for dataset in ("wild", "generalization"):
        if dataset not in data.jobs:
            continue
        methods = BUDGET_METHODS if dataset == "wild" else BUDGET_METHODS[:1]
        budgets[dataset] = {
            m: budget(data, dataset, m, detect=(m == methods[0])).as_dict()
            for m in methods
            if m in data.method_names
        }
        pitch[dataset] = pitch_errors(data, dataset)
    return {"budgets": budgets, "pitch": pitch}


__all__ = [
    "BUDGET_METHODS",
    "TERMS",
    "Budget",
    "BudgetRow",
    "FrameTruth",
    "budget",
    "e7_budget",
    "frame_truth",
    "pitch_errors",
    "residual_std",
    "substitute",
    "variants",
]
