"""E1 (paper Fig. 4): s at the lead's bump crossings of the ``controlled`` drives vs the
lead's distance, the fit s(d) = α f δ / d + β, and the largest distance at which the
crossings still stand out of the background."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from roadpreview.eval.clips import window_max
from roadpreview.eval.experiments.base import Array, crossings, jf, jfs
from roadpreview.eval.experiments.data import EvalData

#: the height of the controlled drives' paper bumps, m (the δ of the fit)
BUMP_HEIGHT_M = 0.06


@dataclass(frozen=True)
class GapRow:
    """The crossings and the background of one gap (one controlled drive)."""

    gap_m: float
    distance_m: float  #: median lead distance at the crossings (NaN: none)
    positive_s: tuple[float, ...]  #: s of each crossing, px
    background_p99: float  #: 99th percentile of the background's s, px
    background_median: float  #: px (NaN: no background frame)
    background_frames: int
    separated: bool  #: the crossings' median s is above the background's p99

    def as_dict(self) -> dict[str, Any]:
        return {
            "gap_m": self.gap_m,
            "distance_m": jf(self.distance_m),
            "positive_s": jfs(self.positive_s),
            "background_p99": jf(self.background_p99),
            "background_median": jf(self.background_median),
            "background_frames": self.background_frames,
            "separated": self.separated,
        }


@dataclass(frozen=True)
class SignalFit:
    """One method: the crossings, the least-squares fit s = α x + β with x = f δ / d, and
    the separation per gap."""

    alpha: float
    beta: float
    r2: float
    background_p99_pooled: float  #: px
    #: the largest gap's distance up to which every gap separates (NaN: not even the first)
    separation_distance_m: float
    per_gap: tuple[GapRow, ...]
    d: tuple[float, ...]  #: lead distance at each crossing, m
    s: tuple[float, ...]  #: s at each crossing, px

    @property
    def n_points(self) -> int:
        return len(self.d)

    def as_dict(self) -> dict[str, Any]:
        return {
            "alpha": jf(self.alpha),
            "beta": jf(self.beta),
            "r2": jf(self.r2),
            "n_points": self.n_points,
            "background_p99_pooled": jf(self.background_p99_pooled),
            "separation_distance_m": jf(self.separation_distance_m),
            "per_gap": [r.as_dict() for r in self.per_gap],
            "points": {"d": jfs(self.d), "s": jfs(self.s)},
        }


@dataclass(frozen=True)
class SignalVsDistance:
    """E1's result."""

    focal_px: float
    size: tuple[int, int]
    delta_m: float
    methods: dict[str, SignalFit]

    def as_dict(self) -> dict[str, Any]:
        return {
            "focal_px": jf(self.focal_px),
            "size": list(self.size),
            "delta_m": self.delta_m,
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
        }


def _fit(x: Array, s: Array) -> tuple[float, float, float]:
    """α, β and R² of s = α x + β (NaN with fewer than two points)."""
    if x.size < 2:
        return math.nan, math.nan, math.nan
    a = np.column_stack([x, np.ones_like(x)])
    (alpha, beta), *_ = np.linalg.lstsq(a, s, rcond=None)
    ss_res = float(np.sum((s - (alpha * x + beta)) ** 2))
    ss_tot = float(np.sum((s - s.mean()) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else math.nan
    return float(alpha), float(beta), r2


def _method_fit(data: EvalData, m: str) -> SignalFit:
    plan = data.plan
    pos_d: list[float] = []
    pos_s: list[float] = []
    pos_x: list[float] = []
    pos_gap: list[float] = []
    bg_by_gap: dict[float, Array] = {}
    for job in data.jobs["controlled"]:
        gap = float(job.scenario.motion.gap_m)
        info, tr = data.info(job), data.scores(job)[m]
        f = data.focal_px(job)
        for e in info["events"]:
            if not e.get("lead_hits") or e.get("lead_front_t_s") is None:
                continue
            tc = float(e["lead_front_t_s"])
            if tc + plan.score_window_s[0] - data.detector_window_s < plan.e1_start_s:
                continue  # the detector window would reach into the start-up
            s_c, _ = window_max(tr.t, tr.s, tc, plan.score_window_s)
            d = float(e["lead_distance_m"])
            pos_d.append(d)
            pos_s.append(s_c)
            pos_x.append(f * float(e["height_m"]) / d)
            pos_gap.append(gap)
        cross = np.asarray(crossings(info, "lead") + crossings(info, "ego"))
        t = tr.t
        keep = (t >= plan.e1_start_s) & np.isfinite(tr.s)
        if cross.size:
            near = (t[:, None] >= cross[None, :] + plan.e1_exclude_s[0]) & (
                t[:, None] <= cross[None, :] + plan.e1_exclude_s[1]
            )
            keep &= ~near.any(axis=1)
        bg_by_gap[gap] = tr.s[keep]
    x = np.asarray(pos_x, dtype=np.float64)
    s = np.asarray(pos_s, dtype=np.float64)
    alpha, beta, r2 = _fit(x, s)
    bg_all = np.concatenate(list(bg_by_gap.values())) if bg_by_gap else np.empty(0)
    p99_all = float(np.percentile(bg_all, 99)) if bg_all.size else math.nan
    rows = []
    separated_to = math.nan
    broken = False
    gaps_of = np.asarray(pos_gap)
    dist = np.asarray(pos_d)
    for g in sorted(bg_by_gap):
        sel = gaps_of == g
        bg = bg_by_gap[g]
        p99 = float(np.percentile(bg, 99)) if bg.size >= 30 else p99_all
        s_g = s[sel]
        d_g = dist[sel]
        sep = bool(s_g.size and np.median(s_g) > p99)
        if sep and not broken:
            separated_to = float(np.median(d_g))
        elif s_g.size:
            broken = True
        rows.append(
            GapRow(
                gap_m=g,
                distance_m=float(np.median(d_g)) if d_g.size else math.nan,
                positive_s=tuple(float(v) for v in s_g),
                background_p99=p99,
                background_median=float(np.median(bg)) if bg.size else math.nan,
                background_frames=int(bg.size),
                separated=sep,
            )
        )
    return SignalFit(
        alpha=alpha,
        beta=beta,
        r2=r2,
        background_p99_pooled=p99_all,
        separation_distance_m=separated_to,
        per_gap=tuple(rows),
        d=tuple(pos_d),
        s=tuple(pos_s),
    )


def signal_vs_distance(data: EvalData) -> SignalVsDistance:
    """s at the lead's bump crossings vs distance; fit s(d) = α f δ / d + β; the largest
    distance where the crossings still stand out of the background's 99th percentile."""
    jobs = data.jobs["controlled"]
    return SignalVsDistance(
        focal_px=data.focal_px(jobs[0]) if jobs else math.nan,
        size=(int(data.plan.e1_size[0]), int(data.plan.e1_size[1])),
        delta_m=BUMP_HEIGHT_M,
        methods={m: _method_fit(data, m) for m in data.method_names},
    )
