"""E5, detection range: recall vs the lead's distance per camera resolution at a bounded
false-positive rate."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from roadpreview.eval.experiments.base import jf, jfs
from roadpreview.eval.experiments.data import EvalData

#: each method's threshold keeps the false-positive rate on the resolution's background
#: clips at or below this (a recall at the F-max threshold alone says nothing when that
#: threshold flags nearly every clip)
RANGE_MAX_FPR = 0.1


@dataclass(frozen=True)
class RangeRow:
    threshold_px: float  #: the smallest threshold with FPR <= `RANGE_MAX_FPR`
    fpr: float
    recall: tuple[float, ...]  #: per distance bin (NaN: no positive in the bin)
    positives: tuple[int, ...]  #: per distance bin
    range_m: float  #: lower edge of the first bin with recall < 50 % (else the last edge)
    range_open: bool  #: recall never fell below 50 %: the range is >= the last edge

    def as_dict(self) -> dict[str, Any]:
        return {
            "threshold_px": jf(self.threshold_px),
            "fpr": jf(self.fpr),
            "recall": jfs(self.recall),
            "positives": list(self.positives),
            "range_m": jf(self.range_m),
            "range_open": self.range_open,
        }


@dataclass(frozen=True)
class RangeOfSize:
    recordings: int
    positives: int  #: tracked positive clips
    backgrounds: int  #: tracked background clips
    untracked_clips: int
    methods: dict[str, RangeRow]

    def as_dict(self) -> dict[str, Any]:
        return {
            "recordings": self.recordings,
            "positives": self.positives,
            "backgrounds": self.backgrounds,
            "untracked_clips": self.untracked_clips,
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
        }


@dataclass(frozen=True)
class DetectionRange:
    bins_m: tuple[float, ...]  #: edges of the distance bins, m
    sizes: dict[str, RangeOfSize]  #: per resolution "WxH"

    def as_dict(self) -> dict[str, Any]:
        return {
            "bins_m": list(self.bins_m),
            "sizes": {k: v.as_dict() for k, v in self.sizes.items()},
        }


def detection_range(data: EvalData) -> DetectionRange:
    """Recall vs the lead's distance per resolution at each method's threshold for a
    false-positive rate of at most `RANGE_MAX_FPR` on that resolution's background clips;
    the range is the lower edge of the first distance bin whose recall is below 50 %.
    Tracked clips only (`clips.tracked_clips`)."""
    plan = data.plan
    edges = np.asarray(plan.distance_bins_m, dtype=np.float64)
    sizes: dict[str, RangeOfSize] = {}
    for size in plan.range_sizes:
        jobs = plan.range_jobs(data.jobs, size)
        full = data.clip_table(f"range-{size[0]}x{size[1]}", jobs)
        # the clips where the tracker followed the true lead: the range is a question of
        # resolution, not of the tracker's failures (Table I's "tracked" subsets)
        table = full.subset(full.masks["tracked"])
        labels = table.labels
        d = table.true_distance_m
        per_m: dict[str, RangeRow] = {}
        for m in data.method_names:
            sc = table.scores[m]
            bg = np.sort(sc[~labels])
            # the smallest threshold that flags (score > threshold) at most RANGE_MAX_FPR of
            # the backgrounds: the background score of rank ceil((1 - fpr) n)
            thr = float(bg[max(0, math.ceil((1.0 - RANGE_MAX_FPR) * bg.size) - 1)])
            hit = sc > thr
            recall: list[float] = []
            counts: list[int] = []
            rng_m: float | None = None
            for i in range(edges.size - 1):
                sel = labels & (d >= edges[i]) & (d < edges[i + 1])
                counts.append(int(sel.sum()))
                r = float(hit[sel].mean()) if sel.any() else math.nan
                recall.append(r)
                if rng_m is None and sel.any() and r < 0.5:
                    rng_m = float(edges[i])
            per_m[m] = RangeRow(
                threshold_px=thr,
                fpr=float((bg > thr).mean()),
                recall=tuple(recall),
                positives=tuple(counts),
                range_m=rng_m if rng_m is not None else float(edges[-1]),
                range_open=rng_m is None,
            )
        sizes[f"{size[0]}x{size[1]}"] = RangeOfSize(
            recordings=len(jobs),
            positives=int(labels.sum()),
            backgrounds=int((~labels).sum()),
            untracked_clips=len(full) - len(table),
            methods=per_m,
        )
    return DetectionRange(bins_m=tuple(float(v) for v in edges), sizes=sizes)
