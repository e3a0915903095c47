"""The experiments: the paper's Fig. 4-7 and Table I, then ours (texture loss, range,
lead time). Each function takes the processed data, returns plain data (JSON-ready)
and writes its figure.

* `e1_signal_vs_distance` (Fig. 4): s at the bump crossings of the ``controlled``
  drives vs the lead distance, the fit s(d) = α f δ / d + β, the separation distance.
* `e2_ego_bump` (Fig. 5): pitch of each method vs the truth and y_c while the ego
  crosses a bump.
* `e3_fpr_vs_rotation` (Fig. 6): false-positive rate of background windows vs the
  ego's rotation intensity.
* `e4_table1` (Table I, Fig. 7): cross-validated balanced accuracy and F-score, AUC,
  entire / hard / easy, and ROC curves.
* `e5_beyond` : texture loss, detection range per resolution, alert lead time.
"""

from __future__ import annotations

import itertools
import json
import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roadpreview.anomaly import DETECTORS, TrajectorySample, make_detector
from roadpreview.eval.clips import (
    DETECTOR_WINDOW_S,
    ClipTable,
    Scores,
    background_windows,
    clip_scores,
    draw_clips,
    mean_abs_rate,
    score_table,
    window_max,
)
from roadpreview.eval.cv import ENTIRE, cross_validate
from roadpreview.eval.detectors import DetectorTrace, run_detector
from roadpreview.eval.methods import METHODS, MethodSpec
from roadpreview.eval.metrics import auc, best_f_threshold, confusion, roc_curve
from roadpreview.eval.plan import EvalPlan, gap_name
from roadpreview.eval.runner import MethodSet, RecordingJob, Trace, load_traces

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: truth arrays the experiments read
_TRUTH_KEYS = (
    "frame_t_s",
    "cam_pitch_rad",
    "cam_pitch_rate_rad_s",
    "lead_distance_m",
    "lead_box_px",
    "lead_rear_px",
    "cam_z_m",
    "ego_speed_m_s",
)

#: the ceiling's camera heave: its height less its centred running mean over this span (the
#: road's hills and the ride height are not heave); the detrended s removes what is left
CEILING_HEAVE_SPAN_S = 3.0
#: bins of the expected signal f |δ| / d (px) for the AUC by signal strength
SIGNAL_BINS_PX = (0.0, 1.0, 2.0, 4.0, math.inf)
#: E5 range: each method's threshold keeps the false-positive rate on the resolution's
#: background clips at or below this (a recall at the F-max threshold alone says nothing
#: when that threshold flags nearly every clip)
RANGE_MAX_FPR = 0.1


# -- data access --------------------------------------------------------------------------------
@dataclass
class EvalData:
    """Processed recordings: traces, truth and clips, loaded once."""

    plan: EvalPlan
    methods: MethodSet
    jobs: dict[str, list[RecordingJob]]
    _traces: dict[str, dict[str, Trace]] = field(default_factory=dict)
    _truth: dict[str, dict[str, Array]] = field(default_factory=dict)
    _info: dict[str, dict[str, Any]] = field(default_factory=dict)
    _tables: dict[str, ClipTable] = field(default_factory=dict)
    _runs: dict[tuple[str, str, str], DetectorTrace] = field(default_factory=dict)

    @property
    def method_names(self) -> list[str]:
        return list(self.methods.configs)

    def spec(self, method: str) -> MethodSpec:
        return METHODS[method]

    def traces(self, job: RecordingJob) -> dict[str, Trace]:
        if job.key not in self._traces:
            self._traces[job.key] = load_traces(job, self.methods)
        return self._traces[job.key]

    def truth(self, job: RecordingJob) -> dict[str, Array]:
        if job.key not in self._truth:
            with np.load(job.folder / "truth.npz") as npz:
                self._truth[job.key] = {k: np.asarray(npz[k]) for k in _TRUTH_KEYS}
        return self._truth[job.key]

    @property
    def detectors(self) -> list[str]:
        """Every detector of the registry, the paper's first."""
        return ["std", *(d for d in DETECTORS if d != "std")]

    @property
    def product_detector(self) -> str:
        """The detector the product runs (the reference method's configuration)."""
        return self.methods.configs[self.methods.reference].anomaly.detector

    def detection(
        self, job: RecordingJob, method: str, detector: str | None = None
    ) -> DetectorTrace:
        """``detector`` (default: the product's) over ``method``'s trace of ``job``."""
        name = detector or self.product_detector
        key = (job.key, method, name)
        if key not in self._runs:
            anomaly = self.methods.configs[method].anomaly
            self._runs[key] = run_detector(self.traces(job)[method], anomaly, name)
        return self._runs[key]

    def detection_at(
        self, job: RecordingJob, method: str, detector: str, threshold: float
    ) -> DetectorTrace:
        """``detector`` on ``method``'s trace of ``job`` with its threshold set to
        ``threshold`` (its `THRESHOLD_FIELDS` entry): an operating point."""
        from roadpreview.eval.product import THRESHOLD_FIELDS

        key = (job.key, method, f"{detector}@{threshold:g}")
        if key not in self._runs:
            anomaly = self.methods.configs[method].anomaly
            field_name = DETECTORS[detector][2]
            table = replace(getattr(anomaly, field_name), **{THRESHOLD_FIELDS[detector]: threshold})
            anomaly = replace(anomaly, **{field_name: table})
            self._runs[key] = run_detector(self.traces(job)[method], anomaly, detector)
        return self._runs[key]

    def scores(self, job: RecordingJob, detector: str = "std") -> dict[str, Scores]:
        """Every method's per-frame score of ``detector`` on ``job`` (the paper's
        experiments use the windowed std, its s at the frame's time)."""
        out = {}
        for m in self.method_names:
            run = self.detection(job, m, detector)
            out[m] = Scores(run.t_score, run.score)
        return out

    def score_window(self, detector: str) -> tuple[float, float]:
        """The clip window of ``detector``'s scores (relative to the clip centre)."""
        return self.plan.score_windows.get(detector, self.plan.score_window_s)

    def info(self, job: RecordingJob) -> dict[str, Any]:
        if job.key not in self._info:
            self._info[job.key] = json.loads((job.folder / "truth.json").read_text())
        return self._info[job.key]

    def focal_px(self, job: RecordingJob) -> float:
        return float(job.scenario.camera_model().fy)

    def clip_table(
        self,
        dataset: str,
        jobs: Sequence[RecordingJob] | None = None,
        detector: str = "std",
    ) -> ClipTable:
        """Clips of a data set (or of the given jobs) with every method's score of
        ``detector`` (the paper's windowed std by default)."""
        jobs = list(jobs if jobs is not None else self.jobs[dataset])
        key = dataset + "|" + detector + "|" + ",".join(j.key for j in jobs)
        if key not in self._tables:
            plan = self.plan
            clips = {
                j.key: draw_clips(
                    j.folder,
                    j.key,
                    (plan.seed, i, zlib.crc32(dataset.encode())),
                    window=plan.score_window_s,
                    clip_half_s=plan.clip_half_s,
                    clearance_s=plan.clearance_s,
                    ego_crossing_share=plan.ego_crossing_share,
                    clear_of_hits_only=plan.clear_of_hits_only,
                    background_spacing_s=plan.background_spacing_s,
                )
                for i, j in enumerate(jobs)
            }
            self._tables[key] = score_table(
                clips,
                {j.key: self.scores(j, detector) for j in jobs},
                {j.key: self.truth(j) for j in jobs},
                self.score_window(detector),
                boxes_by_recording={j.key: self.traces(j)[self.methods.reference] for j in jobs},
                tracked_window=plan.score_window_s,
            )
        return self._tables[key]


def _f(x: Any) -> float | None:
    """A JSON-ready float (None for NaN / inf)."""
    v = float(x)
    return v if math.isfinite(v) else None


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> str:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    _plt().close(fig)
    return path.name


def _crossings(info: Mapping[str, Any], who: str, hits_only: bool = True) -> list[float]:
    """Front-axle crossing times of ``who`` ("lead" or "ego")."""
    out = []
    for e in info["events"]:
        t = e.get(f"{who}_front_t_s")
        if t is not None and (e.get(f"{who}_hits") or not hits_only):
            out.append(float(t))
    return out


def _hp_error(t: Array, err: Array, window_s: float = DETECTOR_WINDOW_S) -> Array:
    """err minus its trailing mean over ``window_s``: the part of a pitch error that the
    1 s detector window sees (a constant offset cancels in s)."""
    n = max(2, round(window_s / float(np.median(np.diff(t)))))
    ok = np.isfinite(err)
    e = np.where(ok, err, 0.0)
    c = np.concatenate([[0.0], np.cumsum(e)])
    k = np.concatenate([[0], np.cumsum(ok)])
    idx = np.arange(err.size)
    lo = np.maximum(idx + 1 - n, 0)
    cnt = k[idx + 1] - k[lo]
    mean = (c[idx + 1] - c[lo]) / np.maximum(cnt, 1)
    out = err - mean
    out[(idx < n - 1) | ~ok] = math.nan
    return np.asarray(out, dtype=np.float64)


def _rms(x: Array) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


# -- E1: signal vs distance (Fig. 4) ------------------------------------------------------------
def e1_signal_vs_distance(data: EvalData, fig_dir: Path) -> dict[str, Any]:
    """s at the lead's bump crossings vs distance; fit s(d) = α f δ / d + β; the largest
    distance where the crossings still stand out of the background's 99th percentile."""
    plan = data.plan
    jobs = data.jobs["controlled"]
    per_method: dict[str, dict[str, Any]] = {}
    for m in data.method_names:
        pos_d, pos_s, pos_x, pos_gap = [], [], [], []
        bg_by_gap: dict[float, Array] = {}
        for job in jobs:
            gap = float(job.scenario.motion.gap_m)
            info, tr = data.info(job), data.scores(job)[m]
            f = data.focal_px(job)
            lead = [
                e
                for e in info["events"]
                if e.get("lead_hits") and e.get("lead_front_t_s") is not None
            ]
            for e in lead:
                tc = float(e["lead_front_t_s"])
                if tc + plan.score_window_s[0] - DETECTOR_WINDOW_S < plan.e1_start_s:
                    continue  # the detector window would reach into the start-up
                s_c, _ = window_max(tr.t, tr.s, tc, plan.score_window_s)
                d = float(e["lead_distance_m"])
                pos_d.append(d)
                pos_s.append(s_c)
                pos_x.append(f * float(e["height_m"]) / d)
                pos_gap.append(gap)
            cross = np.asarray(_crossings(info, "lead") + _crossings(info, "ego"))
            t = tr.t
            keep = (t >= plan.e1_start_s) & np.isfinite(tr.s)
            if cross.size:
                near = (t[:, None] >= cross[None, :] + plan.e1_exclude_s[0]) & (
                    t[:, None] <= cross[None, :] + plan.e1_exclude_s[1]
                )
                keep &= ~near.any(axis=1)
            bg_by_gap[gap] = tr.s[keep]
        x = np.asarray(pos_x)
        s = np.asarray(pos_s)
        alpha = beta = r2 = math.nan
        if x.size >= 2:
            A = np.column_stack([x, np.ones_like(x)])
            (alpha, beta), *_ = np.linalg.lstsq(A, s, rcond=None)
            ss_res = float(np.sum((s - (alpha * x + beta)) ** 2))
            ss_tot = float(np.sum((s - s.mean()) ** 2))
            r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else math.nan
        bg_all = np.concatenate(list(bg_by_gap.values())) if bg_by_gap else np.empty(0)
        p99_all = float(np.percentile(bg_all, 99)) if bg_all.size else math.nan
        gaps = sorted(bg_by_gap)
        rows = []
        separated_to = math.nan
        broken = False
        for g in gaps:
            sel = np.asarray(pos_gap) == g
            bg = bg_by_gap[g]
            p99 = float(np.percentile(bg, 99)) if bg.size >= 30 else p99_all
            s_g = s[sel]
            d_g = np.asarray(pos_d)[sel]
            sep = bool(s_g.size and np.median(s_g) > p99)
            if sep and not broken:
                separated_to = float(np.median(d_g))
            elif s_g.size:
                broken = True
            rows.append(
                {
                    "gap_m": g,
                    "distance_m": _f(np.median(d_g)) if d_g.size else None,
                    "positive_s": [_f(v) for v in s_g],
                    "background_p99": _f(p99),
                    "background_median": _f(np.median(bg)) if bg.size else None,
                    "background_frames": int(bg.size),
                    "separated": sep,
                }
            )
        per_method[m] = {
            "alpha": _f(alpha),
            "beta": _f(beta),
            "r2": _f(r2),
            "n_points": int(x.size),
            "background_p99_pooled": _f(p99_all),
            "separation_distance_m": _f(separated_to),
            "per_gap": rows,
            "points": {"d": [_f(v) for v in pos_d], "s": [_f(v) for v in s]},
        }
    fig_name = _plot_e1(data, per_method, fig_dir / "e1_signal_vs_distance.png")
    f0 = data.focal_px(jobs[0]) if jobs else math.nan
    return {
        "focal_px": _f(f0),
        "size": list(plan.e1_size),
        "delta_m": 0.06,
        "methods": per_method,
        "figure": fig_name,
    }


def _plot_e1(data: EvalData, res: Mapping[str, Any], path: Path) -> str:
    plt = _plt()
    methods = list(res)
    cols = 3
    rows = math.ceil(len(methods) / cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False, layout="constrained"
    )
    f = data.focal_px(data.jobs["controlled"][0])
    for ax, m in zip(axes.ravel(), methods, strict=False):
        r = res[m]
        d = np.asarray([v for v in r["points"]["d"]], dtype=float)
        s = np.asarray([v if v is not None else np.nan for v in r["points"]["s"]], dtype=float)
        ax.plot(d, s, "o", color=data.spec(m).color, label="crossings")
        g = [row["distance_m"] for row in r["per_gap"] if row["distance_m"] is not None]
        p99 = [row["background_p99"] for row in r["per_gap"] if row["distance_m"] is not None]
        ax.plot(g, p99, "k--", lw=1, label="background p99")
        if r["alpha"] is not None and d.size:
            dd = np.linspace(max(d.min() * 0.8, 1.0), d.max() * 1.1, 100)
            ax.plot(
                dd,
                r["alpha"] * f * 0.06 / dd + r["beta"],
                "-",
                color="0.3",
                lw=1,
                label=f"α={r['alpha']:.2f} β={r['beta']:.2f} R²={r['r2'] or 0:.2f}",
            )
        ax.set_title(data.spec(m).label, fontsize=9)
        ax.set_xlabel("lead distance (m)")
        ax.set_ylabel("s (px)")
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(methods) :]:
        ax.axis("off")
    fig.suptitle("E1: s at the lead's bump crossings vs distance (controlled)")
    return _save(fig, path)


# -- E2: the ego over a bump (Fig. 5) -----------------------------------------------------------
def e2_ego_bump(data: EvalData, fig_dir: Path) -> dict[str, Any]:
    """Pitch of each method vs the truth, and y_c, around the ego's first bump crossing
    on the ``controlled`` drive at ``e2_gap_m``.

    Alignment: the pipeline's pitch is relative to its first frame; each method's
    curve is shifted by its mean difference to the truth over the first second of
    the plotted window (2 s before the ego's crossing). y_c is shown relative to its
    mean over the same second."""
    plan = data.plan
    job = next(j for j in data.jobs["controlled"] if j.name == gap_name(plan.e2_gap_m))
    info, truth, traces = data.info(job), data.truth(job), data.traces(job)
    ego = sorted(_crossings(info, "ego"))
    te = next((t for t in ego if t >= 2.5), ego[0] if ego else 5.0)
    lo, hi = te - 2.0, te + 3.0
    tt = truth["frame_t_s"]
    phi_true = truth["cam_pitch_rad"]
    out: dict[str, Any] = {"recording": job.key, "ego_crossing_s": te, "window_s": [lo, hi]}
    rows = {}
    curves = {}
    std_scores = data.scores(job)
    for m, tr in traces.items():
        s_m = std_scores[m].s
        t = tr.t
        sel = (t >= lo) & (t <= hi)
        ref = (t >= lo) & (t < lo + 1.0)
        true_i = np.interp(t, tt, phi_true)
        err = tr["phi"] - true_i
        offset = float(np.nanmean(err[ref])) if np.isfinite(err[ref]).any() else 0.0
        e_win = err[sel] - offset
        hp = _hp_error(t, err)
        yc = tr["y_c"]
        yc0 = float(np.nanmean(yc[ref])) if np.isfinite(yc[ref]).any() else 0.0
        rows[m] = {
            "rms_error_window_deg": _f(np.degrees(_rms(e_win))),
            "max_abs_error_window_deg": _f(np.degrees(np.nanmax(np.abs(e_win))))
            if np.isfinite(e_win).any()
            else None,
            "rms_error_hp_drive_deg": _f(np.degrees(_rms(hp))),
            "s_max_window_px": _f(np.nanmax(s_m[sel])) if np.isfinite(s_m[sel]).any() else None,
        }
        curves[m] = (t[sel], tr["phi"][sel] - offset, yc[sel] - yc0)
    out["methods"] = rows
    plt = _plt()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    sel_t = (tt >= lo) & (tt <= hi)
    a1.plot(tt[sel_t] - te, np.degrees(phi_true[sel_t]), "k-", lw=2.2, label="truth")
    for m, (t, phi, yc) in curves.items():
        spec = data.spec(m)
        if spec.compensated:
            a1.plot(t - te, np.degrees(phi), color=spec.color, lw=1.2, label=spec.label)
        a2.plot(t - te, yc, color=spec.color, lw=1.2, label=spec.label)
    a1.axvline(0, color="0.6", lw=0.8)
    a2.axvline(0, color="0.6", lw=0.8)
    a1.set_ylabel("camera pitch (deg)")
    a1.legend(fontsize=7, ncol=2)
    a2.set_ylabel("y_c - mean of first s (px)")
    a2.set_xlabel("time from the ego's front axle over the bump (s)")
    a2.legend(fontsize=7, ncol=2)
    fig.suptitle(f"E2: the ego crosses a 6 cm bump (controlled, gap {plan.e2_gap_m:g} m)")
    out["figure"] = _save(fig, fig_dir / "e2_ego_bump.png")
    return out


# -- E4: Table I and ROC (Fig. 7) ---------------------------------------------------------------
def windowed_std(t: Array, y: Array, window_s: float, detrend: bool) -> Array:
    """s(t): the std of ``y`` over the frames in the last ``window_s`` (NaN until the first
    full window), about its least-squares line when ``detrend`` (the detector's
    `anomaly.std.detrend`), vectorised over frames with a sliding window of the
    frame count that spans ``window_s`` at the median frame rate."""
    n = len(t)
    out = np.full(n, np.nan)
    if n < 3:
        return out
    w = max(3, round(window_s / float(np.median(np.diff(t)))))
    if n < w:
        return out
    Y = np.lib.stride_tricks.sliding_window_view(y, w)
    ym = Y - Y.mean(axis=1, keepdims=True)
    if detrend:
        T = np.lib.stride_tricks.sliding_window_view(t - t[0], w)
        tm = T - T.mean(axis=1, keepdims=True)
        slope = (tm * ym).sum(axis=1) / (tm * tm).sum(axis=1)
        ym = ym - slope[:, None] * tm
    out[w - 1 :] = np.sqrt((ym * ym).mean(axis=1))
    return out


def true_compensated_y(truth: Mapping[str, Array], f_px: float) -> tuple[Array, Array, Array]:
    """Frame times, the *true* compensated row y_c (px) and the true lead distance (m): the
    rendered row of the lead's rear centre (``lead_rear_px``) less the camera's true pitch,
    f tan(phi), and heave, f dz / d (dz: the camera height less its centred
    `CEILING_HEAVE_SPAN_S` mean)."""
    t = np.asarray(truth["frame_t_s"], dtype=np.float64)
    y = np.asarray(truth["lead_rear_px"], dtype=np.float64)[:, 1]
    z = np.asarray(truth["cam_z_m"], dtype=np.float64)
    d = np.asarray(truth["lead_distance_m"], dtype=np.float64)
    k = max(1, round(CEILING_HEAVE_SPAN_S / float(np.median(np.diff(t)))) | 1)
    mean = np.convolve(np.pad(z, (k // 2, k // 2), mode="edge"), np.ones(k) / k, mode="valid")
    with np.errstate(invalid="ignore", divide="ignore"):
        yc = y - f_px * np.tan(np.asarray(truth["cam_pitch_rad"])) - f_px * (z - mean) / d
    return t, yc, d


def ceiling_s(truth: Mapping[str, Array], f_px: float, window_s: float, detrend: bool) -> Array:
    """s(t) of the *true* compensated trajectory (`true_compensated_y`): what a method with
    perfect tracking, pitch and heave would see; the data set's ceiling, not a method."""
    t, yc, _ = true_compensated_y(truth, f_px)
    return windowed_std(t, yc, window_s, detrend)


def true_trajectory(truth: Mapping[str, Array], f_px: float) -> list[TrajectorySample]:
    """The *true* compensated trajectory as detector input: the rendered row of the lead's
    rear centre less the camera's true pitch and heave (`true_compensated_y`), with the true
    distance and ego speed; no halves (the truth has none)."""
    t, yc, d = true_compensated_y(truth, f_px)
    v = np.asarray(truth["ego_speed_m_s"], dtype=np.float64)
    return [
        TrajectorySample(
            t=float(t[i]),
            y_c=float(yc[i]),
            lead_distance_m=float(d[i]),
            ego_speed_mps=float(v[i]),
            valid=bool(np.isfinite(yc[i])),
            focal_px=f_px,
        )
        for i in range(t.size)
    ]


def _ceiling_scores(data: EvalData, table: ClipTable, detector: str = "std") -> Array:
    """The detector on each clip's recording's true compensated trajectory, scored like a
    method (`window_max`): the windowed std by `ceiling_s`, any other through
    `true_trajectory`."""
    ref = data.methods.configs[data.methods.reference].anomaly
    by_key = {j.key: j for j in data.jobs["wild"]}
    cache: dict[str, tuple[Array, Array]] = {}
    window = data.score_window(detector)
    out = np.zeros(len(table))
    for i, c in enumerate(table.clips):  # clips, not frames
        if c.recording not in cache:
            job = by_key[c.recording]
            tr = data.truth(job)
            f = data.focal_px(job)
            if detector == "std":
                s = ceiling_s(tr, f, ref.std.window_s, ref.std.detrend)
                cache[c.recording] = (np.asarray(tr["frame_t_s"], dtype=np.float64), s)
            else:
                det = make_detector(replace(ref, detector=detector), f)
                ts, ss = [], []
                for sample in true_trajectory(tr, f):
                    det.push(sample)
                    fr = det.frame
                    ts.append(fr.t_score if fr else math.nan)
                    ss.append(fr.score if fr else math.nan)
                cache[c.recording] = (np.asarray(ts), np.asarray(ss))
        t, s = cache[c.recording]
        out[i] = window_max(t, s, c.t_center_s, window)[0]
    return out


def _auc_by_signal(data: EvalData, table: ClipTable, scores: Mapping[str, Array]) -> dict[str, Any]:
    """AUC of the positives in bins of their expected signal f |δ| / d (px) against all
    backgrounds, per method (and the ceiling)."""
    f = data.focal_px(data.jobs["wild"][0])
    labels = table.labels
    dist = np.asarray(
        [
            c.lead_distance_m if math.isfinite(c.lead_distance_m) else table.true_distance_m[i]
            for i, c in enumerate(table.clips)
        ]
    )
    height = np.asarray([abs(c.height_m) for c in table.clips])
    with np.errstate(invalid="ignore", divide="ignore"):
        signal = f * height / dist
    bins = []
    for lo, hi in itertools.pairwise(SIGNAL_BINS_PX):
        pos = labels & (signal >= lo) & (signal < hi)
        keep = pos | ~labels
        bins.append(
            {
                "lo_px": lo,
                "hi_px": None if math.isinf(hi) else hi,
                "n_pos": int(pos.sum()),
                "auc": {m: _f(auc(v[keep], labels[keep])) for m, v in scores.items()},
            }
        )
    return {"focal_px": f, "n_neg": int((~labels).sum()), "bins": bins}


def _subset_results(cv: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """`cross_validate`'s per-subset results as plain data."""
    return {
        name: {
            "n_pos": r.n_pos,
            "n_neg": r.n_neg,
            "ba_mean": _f(r.balanced_accuracy_mean),
            "ba_std": _f(r.balanced_accuracy_std),
            "f_mean": _f(r.f_score_mean),
            "f_std": _f(r.f_score_std),
            "auc": _f(r.auc),
            "auc_mean": _f(r.auc_mean),
            "auc_std": _f(r.auc_std),
        }
        for name, r in cv.items()
    }


def _table1(
    data: EvalData, table: ClipTable, scores: Mapping[str, Array], subsets: Mapping[str, BoolArray]
) -> tuple[dict[str, Any], dict[str, dict[str, tuple[Array, Array]]]]:
    """Table I cells (cross-validated BA and F, AUC) of every scored method, and ROCs."""
    plan = data.plan
    labels, hard = table.labels, table.hard
    res: dict[str, Any] = {}
    rocs: dict[str, dict[str, tuple[Array, Array]]] = {}
    for m, sc in scores.items():
        cv = cross_validate(
            sc, labels, subsets=subsets, groups=table.groups, k=plan.cv_k, seed=plan.cv_seed
        )
        fold_thr = [fr.threshold for fr in cv[ENTIRE].folds]
        thr_all = best_f_threshold(sc, labels)
        c_default = confusion(sc, labels, 1.0)
        c_best = confusion(sc, labels, thr_all)
        res[m] = {
            "subsets": _subset_results(cv),
            "fold_thresholds_px": [_f(v) for v in fold_thr],
            "threshold_f_max_px": _f(thr_all),
            "at_f_max": {"tpr": _f(c_best.tpr), "fpr": _f(c_best.fpr), "f": _f(c_best.f_score)},
            "at_1px": {
                "tpr": _f(c_default.tpr),
                "fpr": _f(c_default.fpr),
                "f": _f(c_default.f_score),
            },
            "no_lead_clips": int((~table.has_lead[m]).sum()) if m in table.has_lead else 0,
        }
        rocs[m] = {}
        for name, mask in (("entire", np.ones_like(labels)), ("hard", hard)):
            if labels[mask].any() and (~labels[mask]).any():
                fpr, tpr, _ = roc_curve(sc[mask], labels[mask])
                rocs[m][name] = (fpr, tpr)
    return res, rocs


def e4_table1(data: EvalData, fig_dir: Path) -> dict[str, Any]:
    """5-fold cross-validated BA and F-score at the F-maximising threshold (chosen on the
    training folds), AUC; entire / hard / easy subsets of the wild set; ROC curves. The
    paper's detector (windowed std) first, then every other detector of the registry on
    the same clips and methods, each with the data set's ceiling (the detector on the true
    compensated trajectory)."""
    plan = data.plan
    table = data.clip_table("wild")
    labels, hard = table.labels, table.hard
    tracked = table.masks["tracked"]
    subsets = {
        "hard": hard,
        "easy": ~hard,
        "tracked": tracked,
        "tracked-hard": tracked & hard,
        "tracked-easy": tracked & ~hard,
    }
    res, rocs = _table1(data, table, {m: table.scores[m] for m in data.method_names}, subsets)
    detectors: dict[str, Any] = {}
    for det in data.detectors:
        if det == "std":
            continue
        t_det = data.clip_table("wild", detector=det)
        d_res, _ = _table1(data, t_det, {m: t_det.scores[m] for m in data.method_names}, subsets)
        ceil = _ceiling_scores(data, t_det, det)
        c_res, _ = _table1(data, t_det, {"ceiling": ceil}, subsets)
        detectors[det] = {
            "methods": d_res,
            "ceiling": c_res["ceiling"],
            "by_signal": _auc_by_signal(
                data, t_det, {"ceiling": ceil, **{m: t_det.scores[m] for m in data.method_names}}
            ),
        }
    # the data set's ceiling: the true compensated trajectory, cross-validated the same way
    ceiling = _ceiling_scores(data, table)
    cv_ceiling = cross_validate(
        ceiling, labels, subsets=subsets, groups=table.groups, k=plan.cv_k, seed=plan.cv_seed
    )
    res_ceiling = {
        "subsets": _subset_results(cv_ceiling),
        "threshold_f_max_px": _f(best_f_threshold(ceiling, labels)),
    }
    by_signal = _auc_by_signal(
        data, table, {"ceiling": ceiling, **{m: table.scores[m] for m in data.method_names}}
    )
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    for ax, name in zip(axes, ("entire", "hard"), strict=True):
        for m, curves in rocs.items():
            if name in curves:
                spec = data.spec(m)
                a = res[m]["subsets"][name]["auc"]
                ax.plot(*curves[name], color=spec.color, label=f"{spec.label} ({a:.2f})")
        ax.plot([0, 1], [0, 1], ":", color="0.6")
        ax.set_title(f"{name} subset")
        ax.set_xlabel("false-positive rate")
        ax.set_ylabel("true-positive rate")
        ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("E4: ROC of the clip score max s(t) (wild set)")
    # positives whose ego crosses the same anomaly inside the score window: there the
    # ego's own pitching adds to the uncompensated score of a true event
    events = {
        (j.key, int(e["index"])): e for j in data.jobs["wild"] for e in data.info(j)["events"]
    }
    same = 0
    for c in table.clips:
        if c.label and c.event_index is not None:
            e = events[(c.recording, c.event_index)]
            te = e.get("ego_front_t_s")
            if e.get("ego_hits") and te is not None:
                same += int(float(te) - c.t_center_s <= plan.score_window_s[1])
    return {
        "counts": {**table.counts(), "ego_same_anomaly_in_window": same},
        "size": list(plan.wild_size),
        "methods": res,
        "ceiling": res_ceiling,
        "by_signal": by_signal,
        "detectors": detectors,
        "figure": _save(fig, fig_dir / "e4_roc.png"),
    }


def thresholds_of(data: EvalData) -> dict[str, float]:
    """Each method's F-maximising threshold on the whole wild clip set."""
    table = data.clip_table("wild")
    return {m: best_f_threshold(table.scores[m], table.labels) for m in data.method_names}


# -- E3: FPR vs ego rotation (Fig. 6) -----------------------------------------------------------
def e3_fpr_vs_rotation(
    data: EvalData,
    fig_dir: Path,
    thresholds: Mapping[str, float],
    default_threshold_px: float = 1.0,
) -> dict[str, Any]:
    """FPR of background windows of the wild set at each method's F-maximising threshold,
    binned by the ego's rotation intensity: the mean absolute true camera pitch rate over
    the frames the window's score depends on ([t + a - T, t + b])."""
    plan = data.plan
    a, b = plan.score_window_s
    intensity: list[Array] = []
    scores: dict[str, list[Array]] = {m: [] for m in data.method_names}
    for job in data.jobs["wild"]:
        info, truth = data.info(job), data.truth(job)
        centers = background_windows(
            float(info["duration_s"]),
            _crossings(info, "lead", hits_only=plan.clear_of_hits_only),
            step_s=plan.e3_step_s,
            window=plan.score_window_s,
        )
        if not centers.size:
            continue
        rate = np.degrees(truth["cam_pitch_rate_rad_s"])
        intensity.append(
            mean_abs_rate(truth["frame_t_s"], rate, centers + a - DETECTOR_WINDOW_S, centers + b)
        )
        for m, sc in data.scores(job).items():
            scores[m].append(clip_scores(sc, centers, plan.score_window_s)[0])
    x = np.concatenate(intensity) if intensity else np.empty(0)
    edges: Array = (
        np.unique(np.nanquantile(x, np.linspace(0, 1, plan.e3_bins + 1))) if x.size else np.empty(0)
    )
    bins = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(len(edges) - 2, 0))
    res: dict[str, Any] = {}
    centers_deg = [
        _f(np.median(x[bins == k])) if (bins == k).any() else None
        for k in range(max(len(edges) - 1, 0))
    ]
    for m in data.method_names:
        s = np.concatenate(scores[m]) if scores[m] else np.empty(0)
        thr = float(thresholds[m])
        nbins = max(len(edges) - 1, 0)

        def per_bin(pos: BoolArray, nbins: int = nbins) -> list[float | None]:
            return [_f(pos[bins == k].mean()) if (bins == k).any() else None for k in range(nbins)]

        res[m] = {
            "threshold_px": _f(thr),
            "fpr": per_bin(s >= thr),
            "fpr_all": _f((s >= thr).mean()) if s.size else None,
            "fpr_at_default": per_bin(s >= default_threshold_px),
            "fpr_all_at_default": _f((s >= default_threshold_px).mean()) if s.size else None,
        }
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True, layout="constrained")
    panels = (
        ("fpr", "each method's F-max threshold"),
        ("fpr_at_default", f"common threshold {default_threshold_px:g} px"),
    )
    for ax, (key, title) in zip(axes, panels, strict=True):
        for m in data.method_names:
            spec = data.spec(m)
            pts = [
                (c, v)
                for c, v in zip(centers_deg, res[m][key], strict=True)
                if c is not None and v is not None
            ]
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                marker="o",
                color=spec.color,
                label=spec.label,
                ls="--" if not spec.compensated else "-",
            )
        ax.set_xlabel("ego rotation: mean |true pitch rate| in the window (deg/s)")
        ax.set_title(title, fontsize=9)
        ax.set_ylim(-0.02, 1.02)
    axes[0].set_ylabel("false-positive rate")
    axes[0].legend(fontsize=7)
    fig.suptitle("E3: FPR of background windows vs ego rotation (wild set)")
    return {
        "n_windows": int(x.size),
        "step_s": plan.e3_step_s,
        "bin_edges_deg_s": [_f(v) for v in edges],
        "bin_centers_deg_s": centers_deg,
        "bin_counts": [int((bins == k).sum()) for k in range(max(len(edges) - 1, 0))],
        "default_threshold_px": default_threshold_px,
        "methods": res,
        "figure": _save(fig, fig_dir / "e3_fpr_vs_rotation.png"),
    }


# -- E5: texture loss, range, lead time ---------------------------------------------------------
def _segments(info: Mapping[str, Any]) -> list[tuple[str, float, float]]:
    return [(c["kind"], float(c["start_s"]), float(c["end_s"])) for c in info.get("conditions", [])]


def _in_segments(t: Array, segs: Sequence[tuple[str, float, float]]) -> BoolArray:
    m = np.zeros(t.shape, dtype=np.bool_)
    for _, s0, s1 in segs:
        m |= (t >= s0) & (t <= s1)
    return m


def e5_texture_loss(
    data: EvalData, fig_dir: Path, thresholds: Mapping[str, float]
) -> dict[str, Any]:
    """Per method on the texture-loss set: AUC and BA (at the method's wild F-max
    threshold) for clips centred inside the fog / tunnel / night segments vs outside,
    and the pitch error inside them (1 s high-pass RMS, and RMS after aligning on the
    second before each segment)."""
    jobs = data.jobs["texture-loss"]
    table = data.clip_table("texture-loss")
    inside = np.zeros(len(table), dtype=np.bool_)
    i0 = 0
    for job in jobs:
        n = sum(1 for c in table.clips if c.recording == job.key)
        centers = np.asarray([c.t_center_s for c in table.clips[i0 : i0 + n]])
        inside[i0 : i0 + n] = _in_segments(centers, _segments(data.info(job)))
        i0 += n
    labels = table.labels
    res: dict[str, Any] = {}
    for m in data.method_names:
        row: dict[str, Any] = {}
        for name, mask in (("inside", inside), ("outside", ~inside)):
            lab, sc = labels[mask], table.scores[m][mask]
            both = bool(lab.any() and (~lab).any())
            c = confusion(sc, lab, thresholds[m]) if mask.any() else None
            row[name] = {
                "n_pos": int(lab.sum()),
                "n_neg": int((~lab).sum()),
                "auc": _f(auc(sc, lab)) if both else None,
                "ba": _f(c.balanced_accuracy) if c is not None and both else None,
            }
        hp_err, al_err = [], []
        for job in jobs:
            tr = data.traces(job)[m]
            truth = data.truth(job)
            err = tr["phi"] - np.interp(tr.t, truth["frame_t_s"], truth["cam_pitch_rad"])
            hp = _hp_error(tr.t, err)
            for _, s0, s1 in _segments(data.info(job)):
                seg = (tr.t >= s0) & (tr.t <= s1)
                before = (tr.t >= s0 - 1.0) & (tr.t < s0)
                hp_err.append(hp[seg])
                if np.isfinite(err[before]).any():
                    al_err.append(err[seg] - np.nanmean(err[before]))
        row["pitch_rms_hp_inside_deg"] = (
            _f(np.degrees(_rms(np.concatenate(hp_err)))) if hp_err else None
        )
        row["pitch_rms_aligned_inside_deg"] = (
            _f(np.degrees(_rms(np.concatenate(al_err)))) if al_err else None
        )
        res[m] = row
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    names = [m for m in data.method_names if data.spec(m).compensated]
    vals = [res[m]["pitch_rms_hp_inside_deg"] or 0.0 for m in names]
    ax.bar(range(len(names)), vals, color=[data.spec(m).color for m in names])
    ax.set_xticks(range(len(names)), [data.spec(m).label for m in names], rotation=20, fontsize=7)
    ax.set_ylabel("pitch error, 1 s high-pass RMS (deg)")
    ax.set_title("E5: pitch error inside fog / tunnel / night (texture-loss set)")
    return {
        "counts": table.counts(),
        "clips_inside": int(inside.sum()),
        "size": list(data.plan.texture_size),
        "methods": res,
        "figure": _save(fig, fig_dir / "e5_texture_loss.png"),
    }


def e5_range(data: EvalData, fig_dir: Path) -> dict[str, Any]:
    """Recall vs the lead's distance per resolution at each method's threshold for a
    false-positive rate of at most `RANGE_MAX_FPR` on that resolution's background clips;
    the range is the lower edge of the first distance bin whose recall is below 50 %.
    Tracked clips only (`clips.tracked_clips`)."""
    plan = data.plan
    edges = np.asarray(plan.distance_bins_m, dtype=np.float64)
    out: dict[str, Any] = {"bins_m": [float(v) for v in edges], "sizes": {}}
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    styles = ["-", "--", ":", "-."]
    for k, size in enumerate(plan.range_sizes):
        jobs = plan.range_jobs(data.jobs, size)
        full = data.clip_table(f"range-{size[0]}x{size[1]}", jobs)
        # the clips where the tracker followed the true lead: the range is a question of
        # resolution, not of the tracker's failures (Table I's "tracked" subsets)
        table = full.subset(full.masks["tracked"])
        labels = table.labels
        d = table.true_distance_m
        per_m: dict[str, Any] = {}
        for m in data.method_names:
            sc = table.scores[m]
            bg = np.sort(sc[~labels])
            # the smallest threshold that flags (score > threshold) at most RANGE_MAX_FPR of
            # the backgrounds: the background score of rank ceil((1 - fpr) n)
            thr = float(bg[max(0, math.ceil((1.0 - RANGE_MAX_FPR) * bg.size) - 1)])
            hit = sc > thr
            fpr = float((bg > thr).mean())
            recall, counts = [], []
            rng_m: float | None = None
            for i in range(edges.size - 1):
                sel = labels & (d >= edges[i]) & (d < edges[i + 1])
                counts.append(int(sel.sum()))
                r = float(hit[sel].mean()) if sel.any() else math.nan
                recall.append(_f(r))
                if rng_m is None and sel.any() and r < 0.5:
                    rng_m = float(edges[i])
            per_m[m] = {
                "threshold_px": _f(thr),
                "fpr": _f(fpr),
                "recall": recall,
                "positives": counts,
                "range_m": rng_m if rng_m is not None else _f(edges[-1]),
                "range_open": rng_m is None,  # recall never fell below 50 %: range >= last edge
            }
        out["sizes"][f"{size[0]}x{size[1]}"] = {
            "recordings": len(jobs),
            "positives": int(labels.sum()),
            "backgrounds": int((~labels).sum()),
            "untracked_clips": len(full) - len(table),
            "methods": per_m,
        }
        mid = 0.5 * (edges[:-1] + edges[1:])
        for m, ls_m in (("fused-kalman", styles[k % 4]), ("uncompensated", styles[k % 4])):
            if m not in per_m:
                continue
            spec = data.spec(m)
            rec_m = [v if v is not None else np.nan for v in per_m[m]["recall"]]
            ax.plot(
                mid,
                rec_m,
                linestyle=ls_m,
                marker="o" if m == "fused-kalman" else "x",
                color=spec.color,
                label=f"{spec.label}, {size[0]}x{size[1]}",
            )
    ax.axhline(0.5, color="0.6", lw=0.8)
    ax.set_xlabel("lead distance at the crossing (m)")
    ax.set_ylabel(f"recall at FPR <= {RANGE_MAX_FPR:.0%}")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=7)
    ax.set_title("E5: detection range per resolution (wild drives)")
    out["figure"] = _save(fig, fig_dir / "e5_range.png")
    return out


def e5_lead_time(data: EvalData, fig_dir: Path) -> dict[str, Any]:
    """The product's alerts (default detector settings) matched to the wild set's lead
    crossings: recall, false alarms per minute and the lead time (ego arrival minus
    alert emission) of the detected ones."""
    from roadpreview.pipeline.truthmatch import match_alerts

    res: dict[str, Any] = {}
    times: dict[str, list[float]] = {}
    for m in data.method_names:
        hits = expected = fa = 0
        minutes = 0.0
        lead_times: list[float] = []
        for job in data.jobs["wild"]:
            info = data.info(job)
            dur = float(info["duration_s"])
            rep = match_alerts(
                data.detection(job, m).alerts,
                info["events"],
                t0=0.0,
                duration_s=dur,
                max_distance_m=math.inf,
            )
            hits += rep.hits
            expected += rep.expected
            fa += len(rep.false_alarms)
            minutes += dur / 60.0
            lead_times += [
                r.lead_time_s
                for r in rep.rows
                if r.alert is not None and r.expected and math.isfinite(r.lead_time_s)
            ]
        arr = np.asarray(lead_times)
        times[m] = lead_times
        res[m] = {
            "alerts_hits": hits,
            "lead_crossings": expected,
            "recall": _f(hits / expected) if expected else None,
            "false_alarms_per_min": _f(fa / minutes) if minutes else None,
            "lead_time_median_s": _f(np.median(arr)) if arr.size else None,
            "lead_time_p10_s": _f(np.percentile(arr, 10)) if arr.size else None,
            "lead_time_p90_s": _f(np.percentile(arr, 90)) if arr.size else None,
            "lead_time_min_s": _f(arr.min()) if arr.size else None,
            "late_alerts": int((arr <= 0).sum()),
        }
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    shown = [m for m in data.method_names if times[m]]
    if shown:
        ax.hist(
            [times[m] for m in shown],
            bins=12,
            color=[data.spec(m).color for m in shown],
            label=[data.spec(m).label for m in shown],
        )
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel("lead time: ego reaches the anomaly minus alert emitted (s)")
    ax.set_ylabel("alerts")
    ax.legend(fontsize=7)
    ax.set_title("E5: alert lead time (wild set, default detector)")
    return {"methods": res, "figure": _save(fig, fig_dir / "e5_lead_time.png")}
