"""E3 (paper Fig. 6): the false-positive rate of the wild set's background windows vs
the ego's rotation intensity."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from roadpreview.eval.clips import background_windows, clip_scores, mean_abs_rate
from roadpreview.eval.experiments.base import Array, BoolArray, crossings, jf, jfs
from roadpreview.eval.experiments.data import EvalData


@dataclass(frozen=True)
class FprRow:
    """One method's FPR per bin of rotation (NaN: empty bin) and over all windows."""

    threshold_px: float  #: the method's F-max threshold on the wild clips
    fpr: tuple[float, ...]
    fpr_all: float
    fpr_at_default: tuple[float, ...]  #: at the common (configured) threshold
    fpr_all_at_default: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "threshold_px": jf(self.threshold_px),
            "fpr": jfs(self.fpr),
            "fpr_all": jf(self.fpr_all),
            "fpr_at_default": jfs(self.fpr_at_default),
            "fpr_all_at_default": jf(self.fpr_all_at_default),
        }


@dataclass(frozen=True)
class FprVsRotation:
    """E3's result: bins of equal count of the ego's mean |pitch rate| (deg/s)."""

    n_windows: int
    step_s: float
    bin_edges_deg_s: tuple[float, ...]
    bin_centers_deg_s: tuple[float, ...]  #: median rotation of each bin (NaN: empty)
    bin_counts: tuple[int, ...]
    default_threshold_px: float
    methods: dict[str, FprRow]

    def as_dict(self) -> dict[str, Any]:
        return {
            "n_windows": self.n_windows,
            "step_s": self.step_s,
            "bin_edges_deg_s": jfs(self.bin_edges_deg_s),
            "bin_centers_deg_s": jfs(self.bin_centers_deg_s),
            "bin_counts": list(self.bin_counts),
            "default_threshold_px": self.default_threshold_px,
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
        }


def _mean(x: BoolArray) -> float:
    return float(x.mean()) if x.size else float("nan")


def fpr_vs_rotation(
    data: EvalData, thresholds: Mapping[str, float], default_threshold_px: float = 1.0
) -> FprVsRotation:
    """FPR of background windows of the wild set at each method's F-maximising threshold
    (and at ``default_threshold_px``), binned by the ego's rotation intensity: the mean
    absolute true camera pitch rate over the frames the window's score depends on
    ([t + a - T, t + b])."""
    plan = data.plan
    a, b = plan.score_window_s
    big_t = data.detector_window_s
    intensity: list[Array] = []
    scores: dict[str, list[Array]] = {m: [] for m in data.method_names}
    for job in data.jobs["wild"]:
        info, truth = data.info(job), data.truth(job)
        centers = background_windows(
            float(info["duration_s"]),
            crossings(info, "lead", hits_only=plan.clear_of_hits_only),
            step_s=plan.e3_step_s,
            window=plan.score_window_s,
            detector_window_s=big_t,
        )
        if not centers.size:
            continue
        rate = np.degrees(truth["cam_pitch_rate_rad_s"])
        intensity.append(mean_abs_rate(truth["frame_t_s"], rate, centers + a - big_t, centers + b))
        for m, sc in data.scores(job).items():
            scores[m].append(clip_scores(sc, centers, plan.score_window_s)[0])
    x = np.concatenate(intensity) if intensity else np.empty(0)
    edges: Array = (
        np.unique(np.nanquantile(x, np.linspace(0, 1, plan.e3_bins + 1))) if x.size else np.empty(0)
    )
    nbins = max(len(edges) - 1, 0)
    bins = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(nbins - 1, 0))
    members = [bins == k for k in range(nbins)]

    def per_bin(pos: BoolArray) -> tuple[float, ...]:
        return tuple(_mean(pos[sel]) for sel in members)

    res: dict[str, FprRow] = {}
    for m in data.method_names:
        s = np.concatenate(scores[m]) if scores[m] else np.empty(0)
        thr = float(thresholds[m])
        res[m] = FprRow(
            threshold_px=thr,
            fpr=per_bin(s >= thr),
            fpr_all=_mean(s >= thr),
            fpr_at_default=per_bin(s >= default_threshold_px),
            fpr_all_at_default=_mean(s >= default_threshold_px),
        )
    return FprVsRotation(
        n_windows=int(x.size),
        step_s=plan.e3_step_s,
        bin_edges_deg_s=tuple(float(v) for v in edges),
        bin_centers_deg_s=tuple(
            float(np.median(x[sel])) if sel.any() else float("nan") for sel in members
        ),
        bin_counts=tuple(int(sel.sum()) for sel in members),
        default_threshold_px=default_threshold_px,
        methods=res,
    )
