"""E2 (paper Fig. 5): each method's pitch against the truth, and its y_c, while the ego
crosses a bump of the ``controlled`` drive."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from roadpreview.eval.experiments.base import Array, crossings, hp_error, jf, rms
from roadpreview.eval.experiments.data import EvalData
from roadpreview.eval.plan import gap_name


@dataclass(frozen=True)
class EgoBumpRow:
    """One method's pitch error around the crossing and its s there."""

    rms_error_window_deg: float
    max_abs_error_window_deg: float
    rms_error_hp_drive_deg: float  #: high-passed by the detector window, whole drive
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

    def as_dict(self) -> dict[str, Any]:
        return {
            "recording": self.recording,
            "ego_crossing_s": self.ego_crossing_s,
            "window_s": list(self.window_s),
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
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
    std_scores = data.scores(job)
    for m, tr in traces.items():
        s_m = std_scores[m].s
        t = tr.t
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
    )
