"""E2 (paper Fig. 5): each method's pitch against the truth, and its y_c, while the ego
crosses a bump of the ``controlled`` drive; and over every ego-only crossing of the wild
set and the generalization suite (`ego_only_crossings`): the ego's own anomalies must be
invisible in y_c.

The s of the ego's crossing is the detector's 1 s std of y_c, detrended
(`ceiling.windowed_std`), at the frames whose window holds no crossing of the lead (the
lead crossing the same bump 10 m ahead falls inside the controlled drive's window: that s
is the lead's bump, which the product must see)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roadpreview.eval.experiments.base import Array, crossings, hp_error, jf, rms
from roadpreview.eval.experiments.ceiling import true_compensated_y, windowed_std
from roadpreview.eval.experiments.data import EvalData
from roadpreview.eval.plan import gap_name


@dataclass(frozen=True)
class EgoBumpRow:
    """One method's pitch error around the crossing and its s there."""

    rms_error_window_deg: float
    max_abs_error_window_deg: float
    rms_error_hp_drive_deg: float  #: high-passed by the detector window, whole drive
    #: the largest detrended 1 s std of y_c in the window, frames whose window holds a
    #: lead crossing left out (module docstring)
    s_max_window_px: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "rms_error_window_deg": jf(self.rms_error_window_deg),
            "max_abs_error_window_deg": jf(self.max_abs_error_window_deg),
            "rms_error_hp_drive_deg": jf(self.rms_error_hp_drive_deg),
            "s_max_window_px": jf(self.s_max_window_px),
        }


@dataclass(frozen=True)
class Curve:
    """One method's aligned curves over the plotted window."""

    t: Array  #: recording time, s
    phi_rad: Array  #: pitch less its offset to the truth
    y_c_px: Array  #: y_c less its mean over the first second


@dataclass(frozen=True)
class EgoBump:
    """E2's result: the numbers and the curves of the figure."""

    recording: str
    gap_m: float
    ego_crossing_s: float
    window_s: tuple[float, float]
    methods: dict[str, EgoBumpRow]
    truth_t: Array  #: the truth's frame times inside the window, s
    truth_phi_rad: Array
    curves: dict[str, Curve]
    #: the ego-only crossings of the wild set and the suite (None: the run has neither)
    ego_only: EgoOnly | None = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "recording": self.recording,
            "ego_crossing_s": self.ego_crossing_s,
            "window_s": list(self.window_s),
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
            "ego_only": None if self.ego_only is None else self.ego_only.as_dict(),
        }


def _finite_max(x: Array) -> float:
    return float(np.nanmax(x)) if np.isfinite(x).any() else math.nan


def ego_bump(data: EvalData) -> EgoBump:
    """Pitch of each method vs the truth, and y_c, around the ego's first bump crossing
    on the ``controlled`` drive at ``e2_gap_m``.

    Alignment: the pipeline's pitch is relative to its first frame; each method's
    curve is shifted by its mean difference to the truth over the first second of
    the plotted window (2 s before the ego's crossing). y_c is shown relative to its
    mean over the same second."""
    plan = data.plan
    job = next(j for j in data.jobs["controlled"] if j.name == gap_name(plan.e2_gap_m))
    info, truth, traces = data.info(job), data.truth(job), data.traces(job)
    ego = sorted(crossings(info, "ego"))
    te = next((t for t in ego if t >= 2.5), ego[0] if ego else 5.0)
    lo, hi = te - 2.0, te + 3.0
    tt = truth["frame_t_s"]
    phi_true = truth["cam_pitch_rad"]
    rows: dict[str, EgoBumpRow] = {}
    curves: dict[str, Curve] = {}
    lead = crossings(info, "lead", hits_only=False)
    for m, tr in traces.items():
        t = tr.t
        s_m = np.where(
            _clear_of(t, lead, data.detector_window_s), windowed_std(t, tr["y_c"]), np.nan
        )
        sel = (t >= lo) & (t <= hi)
        ref = (t >= lo) & (t < lo + 1.0)
        err = tr["phi"] - np.interp(t, tt, phi_true)
        offset = float(np.nanmean(err[ref])) if np.isfinite(err[ref]).any() else 0.0
        e_win = err[sel] - offset
        yc = tr["y_c"]
        yc0 = float(np.nanmean(yc[ref])) if np.isfinite(yc[ref]).any() else 0.0
        rows[m] = EgoBumpRow(
            rms_error_window_deg=float(np.degrees(rms(e_win))),
            max_abs_error_window_deg=float(np.degrees(_finite_max(np.abs(e_win)))),
            rms_error_hp_drive_deg=float(np.degrees(rms(hp_error(t, err, data.detector_window_s)))),
            s_max_window_px=_finite_max(s_m[sel]),
        )
        curves[m] = Curve(t[sel], tr["phi"][sel] - offset, yc[sel] - yc0)
    sel_t = (tt >= lo) & (tt <= hi)
    return EgoBump(
        recording=job.key,
        gap_m=float(plan.e2_gap_m),
        ego_crossing_s=te,
        window_s=(lo, hi),
        methods=rows,
        truth_t=tt[sel_t],
        truth_phi_rad=phi_true[sel_t],
        curves=curves,
        ego_only=ego_only_crossings(data) if {"wild", "generalization"} & set(data.jobs) else None,
    )


#: an ego-only crossing: no crossing of the lead within this much before its window's start
#: or after its end, s (the lead's own bump, seen by the detector, is not the ego's)
EGO_ONLY_CLEARANCE_S = 1.0
#: the frames of one ego crossing: from its front axle's crossing to this much after (the
#: rear axle follows 0.1-0.3 s later; the 1 s window then spans the whole pitching)
EGO_CROSSING_SPAN_S = 1.5


def _clear_of(t: Array, events: list[float], window_s: float) -> NDArray[np.bool_]:
    """Frames whose std window [t - window_s, t] holds none of ``events``."""
    ok = np.ones(t.shape, dtype=np.bool_)
    for te in events:
        ok &= ~((t >= te) & (t - window_s <= te))
    return ok


@dataclass(frozen=True)
class EgoOnly:
    """The 1 s std of y_c over the ego-only crossings (per crossing its largest value)."""

    n: int
    per_method: dict[str, tuple[float, float, float]]  #: median, 90th percentile, max (px)
    truth: tuple[float, float, float]  #: the same of the true compensated row
    worst: dict[str, tuple[str, float, float]]  #: method -> (recording, time, s)

    def as_dict(self) -> dict[str, Any]:
        return {
            "n_crossings": self.n,
            "methods": {m: [jf(v) for v in x] for m, x in self.per_method.items()},
            "truth": [jf(v) for v in self.truth],
            "worst": {m: [w[0], jf(w[1]), jf(w[2])] for m, w in self.worst.items()},
        }


def _stats(x: list[float]) -> tuple[float, float, float]:
    a = np.asarray([v for v in x if math.isfinite(v)])
    if a.size == 0:
        return math.nan, math.nan, math.nan
    return float(np.median(a)), float(np.percentile(a, 90)), float(a.max())


def ego_only_crossings(
    data: EvalData, datasets: tuple[str, ...] = ("wild", "generalization")
) -> EgoOnly:
    """Every crossing of an anomaly by the ego with no crossing of the lead (either side,
    hit or passed) from `EGO_ONLY_CLEARANCE_S` before to `EGO_CROSSING_SPAN_S` +
    `EGO_ONLY_CLEARANCE_S` + the window after it: the largest detrended 1 s std of y_c
    over [t_ego, t_ego + `EGO_CROSSING_SPAN_S`] per method (and of the truth's y_c), with
    frames without a lead left out. What the ego's own bumps leave in y_c."""
    win = data.detector_window_s
    vals: dict[str, list[float]] = {}
    truth_vals: list[float] = []
    worst: dict[str, tuple[str, float, float]] = {}
    n = 0
    for ds in datasets:
        for job in data.jobs.get(ds, []):
            info = data.info(job)
            lead = crossings(info, "lead", hits_only=False)
            ego = crossings(info, "ego")
            traces = data.traces(job)
            tt, yc_true, _ = true_compensated_y(data.truth(job), data.focal_px(job))
            s_true = windowed_std(tt, yc_true)
            s_m = {m: windowed_std(tr.t, tr["y_c"]) for m, tr in traces.items()}
            for te in ego:
                lo, hi = te - EGO_ONLY_CLEARANCE_S, te + EGO_CROSSING_SPAN_S + win
                if any(lo <= tl <= hi + EGO_ONLY_CLEARANCE_S for tl in lead):
                    continue
                n += 1
                sel_t = (tt >= te) & (tt <= te + EGO_CROSSING_SPAN_S)
                truth_vals.append(_finite_max(s_true[sel_t]))
                for m, tr in traces.items():
                    sel = (tr.t >= te) & (tr.t <= te + EGO_CROSSING_SPAN_S)
                    v = _finite_max(s_m[m][sel])
                    vals.setdefault(m, []).append(v)
                    if math.isfinite(v) and v > worst.get(m, ("", 0.0, -1.0))[2]:
                        worst[m] = (job.key, te, v)
    return EgoOnly(
        n=n,
        per_method={m: _stats(v) for m, v in vals.items()},
        truth=_stats(truth_vals),
        worst=worst,
    )
