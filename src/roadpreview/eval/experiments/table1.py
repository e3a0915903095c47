"""E4 (paper Table I and Fig. 7): cross-validated balanced accuracy and F-score, AUC and
ROC curves of the clip scores on the wild set; entire / hard / easy and tracked subsets;
every detector of the registry, each with the data set's ceiling."""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from roadpreview.eval.clips import ClipTable, window_max
from roadpreview.eval.cv import ENTIRE, SubsetResult, cross_validate
from roadpreview.eval.experiments.base import Array, BoolArray, jf, jfs
from roadpreview.eval.experiments.ceiling import ceiling_scores
from roadpreview.eval.experiments.data import EvalData
from roadpreview.eval.metrics import auc, best_f_threshold, confusion, roc_curve

#: bins of the expected signal f |δ| / d (px) for the AUC by signal strength
SIGNAL_BINS_PX = (0.0, 1.0, 2.0, 4.0, math.inf)
#: the common threshold of the ``at_1px`` operating point, px (the paper's and our default)
COMMON_THRESHOLD_PX = 1.0
#: the subsets whose ROC curves are kept
ROC_SUBSETS = ("entire", "hard")


@dataclass(frozen=True)
class OperatingPoint:
    tpr: float
    fpr: float
    f: float

    def as_dict(self) -> dict[str, Any]:
        return {"tpr": jf(self.tpr), "fpr": jf(self.fpr), "f": jf(self.f)}


@dataclass(frozen=True)
class Roc:
    fpr: Array
    tpr: Array


def _subset_dict(r: SubsetResult) -> dict[str, Any]:
    return {
        "n_pos": r.n_pos,
        "n_neg": r.n_neg,
        "ba_mean": jf(r.balanced_accuracy_mean),
        "ba_std": jf(r.balanced_accuracy_std),
        "f_mean": jf(r.f_score_mean),
        "f_std": jf(r.f_score_std),
        "auc": jf(r.auc),
        "auc_mean": jf(r.auc_mean),
        "auc_std": jf(r.auc_std),
    }


@dataclass(frozen=True)
class Table1Row:
    """One method (or the ceiling) on one detector's clip scores."""

    subsets: dict[str, SubsetResult]  #: `cross_validate`'s result, "entire" first
    fold_thresholds_px: tuple[float, ...]  #: the threshold chosen on each fold's training
    threshold_f_max_px: float  #: the F-maximising threshold on the whole set
    at_f_max: OperatingPoint  #: at ``threshold_f_max_px``
    at_1px: OperatingPoint  #: at `COMMON_THRESHOLD_PX`
    no_lead_clips: int  #: clips without any score in their window
    roc: dict[str, Roc]  #: per subset of `ROC_SUBSETS` with both classes

    def as_dict(self) -> dict[str, Any]:
        return {
            "subsets": {name: _subset_dict(r) for name, r in self.subsets.items()},
            "fold_thresholds_px": jfs(self.fold_thresholds_px),
            "threshold_f_max_px": jf(self.threshold_f_max_px),
            "at_f_max": self.at_f_max.as_dict(),
            "at_1px": self.at_1px.as_dict(),
            "no_lead_clips": self.no_lead_clips,
        }


@dataclass(frozen=True)
class SignalBin:
    lo_px: float
    hi_px: float  #: inf for the last bin
    n_pos: int
    auc: dict[str, float]  #: per method (and "ceiling")

    def as_dict(self) -> dict[str, Any]:
        return {
            "lo_px": self.lo_px,
            "hi_px": jf(self.hi_px),
            "n_pos": self.n_pos,
            "auc": {m: jf(v) for m, v in self.auc.items()},
        }


@dataclass(frozen=True)
class BySignal:
    """AUC of the positives in bins of expected signal against all backgrounds."""

    focal_px: float
    n_neg: int
    bins: tuple[SignalBin, ...]

    def as_dict(self) -> dict[str, Any]:
        return {
            "focal_px": self.focal_px,
            "n_neg": self.n_neg,
            "bins": [b.as_dict() for b in self.bins],
        }


@dataclass(frozen=True)
class DetectorTable:
    """Table I of one more detector of the registry, on its own clip scores."""

    methods: dict[str, Table1Row]
    ceiling: Table1Row
    by_signal: BySignal

    def as_dict(self) -> dict[str, Any]:
        return {
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
            "ceiling": self.ceiling.as_dict(),
            "by_signal": self.by_signal.as_dict(),
        }


@dataclass(frozen=True)
class Table1:
    """E4's result: the windowed std (the paper's detector) and every other detector."""

    counts: dict[str, int]  #: `ClipTable.counts` and ``ego_same_anomaly_in_window``
    size: tuple[int, int]
    methods: dict[str, Table1Row]
    ceiling: Table1Row
    by_signal: BySignal
    detectors: dict[str, DetectorTable]

    def as_dict(self) -> dict[str, Any]:
        return {
            "counts": dict(self.counts),
            "size": list(self.size),
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
            "ceiling": self.ceiling.as_dict(),
            "by_signal": self.by_signal.as_dict(),
            "detectors": {k: d.as_dict() for k, d in self.detectors.items()},
        }


def _row(
    data: EvalData,
    table: ClipTable,
    scores: Array,
    subsets: Mapping[str, BoolArray],
    no_lead_clips: int,
) -> Table1Row:
    """Table I cells (cross-validated BA and F, AUC) and ROCs of one score per clip."""
    plan = data.plan
    labels = table.labels
    cv = cross_validate(
        scores, labels, subsets=subsets, groups=table.groups, k=plan.cv_k, seed=plan.cv_seed
    )
    thr_all = best_f_threshold(scores, labels)
    c_best = confusion(scores, labels, thr_all)
    c_common = confusion(scores, labels, COMMON_THRESHOLD_PX)
    roc: dict[str, Roc] = {}
    masks = {ENTIRE: np.ones_like(labels), **subsets}
    for name in ROC_SUBSETS:
        mask = masks[name]
        if labels[mask].any() and (~labels[mask]).any():
            fpr, tpr, _ = roc_curve(scores[mask], labels[mask])
            roc[name] = Roc(fpr, tpr)
    return Table1Row(
        subsets=cv,
        fold_thresholds_px=tuple(fr.threshold for fr in cv[ENTIRE].folds),
        threshold_f_max_px=thr_all,
        at_f_max=OperatingPoint(c_best.tpr, c_best.fpr, c_best.f_score),
        at_1px=OperatingPoint(c_common.tpr, c_common.fpr, c_common.f_score),
        no_lead_clips=no_lead_clips,
        roc=roc,
    )


def _method_rows(
    data: EvalData, table: ClipTable, subsets: Mapping[str, BoolArray]
) -> dict[str, Table1Row]:
    return {
        m: _row(
            data,
            table,
            table.scores[m],
            subsets,
            int((~table.has_lead[m]).sum()) if m in table.has_lead else 0,
        )
        for m in data.method_names
    }


def clip_ceiling(data: EvalData, table: ClipTable, detector: str = "std") -> Array:
    """The detector on each clip's recording's true compensated trajectory
    (`ceiling_scores`), scored like a method (`window_max`)."""
    ref = data.reference_anomaly
    by_key = {j.key: j for j in data.jobs["wild"]}
    window = data.score_window(detector)
    cache: dict[str, tuple[Array, Array]] = {}
    out = np.zeros(len(table))
    for i, c in enumerate(table.clips):  # clips, not frames
        if c.recording not in cache:
            job = by_key[c.recording]
            sc = ceiling_scores(data.truth(job), data.focal_px(job), ref, detector)
            cache[c.recording] = (sc.t, sc.s)
        t, s = cache[c.recording]
        out[i] = window_max(t, s, c.t_center_s, window)[0]
    return out


def auc_by_signal(data: EvalData, table: ClipTable, scores: Mapping[str, Array]) -> BySignal:
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
            SignalBin(
                lo_px=lo,
                hi_px=hi,
                n_pos=int(pos.sum()),
                auc={m: auc(v[keep], labels[keep]) for m, v in scores.items()},
            )
        )
    return BySignal(focal_px=f, n_neg=int((~labels).sum()), bins=tuple(bins))


def _same_anomaly_positives(data: EvalData, table: ClipTable) -> int:
    """Positives whose ego crosses the same anomaly inside the score window: there the
    ego's own pitching adds to the uncompensated score of a true event."""
    events = {
        (j.key, int(e["index"])): e for j in data.jobs["wild"] for e in data.info(j)["events"]
    }
    same = 0
    for c in table.clips:
        if c.label and c.event_index is not None:
            e = events[(c.recording, c.event_index)]
            te = e.get("ego_front_t_s")
            if e.get("ego_hits") and te is not None:
                same += int(float(te) - c.t_center_s <= data.plan.score_window_s[1])
    return same


def table1(data: EvalData) -> Table1:
    """5-fold cross-validated BA and F-score at the F-maximising threshold (chosen on the
    training folds), AUC; entire / hard / easy subsets of the wild set; ROC curves. The
    paper's detector (windowed std) first, then every other detector of the registry on
    the same clips and methods, each with the data set's ceiling (the detector on the true
    compensated trajectory)."""
    table = data.clip_table("wild")
    hard = table.hard
    tracked = table.masks["tracked"]
    subsets = {
        "hard": hard,
        "easy": ~hard,
        "tracked": tracked,
        "tracked-hard": tracked & hard,
        "tracked-easy": tracked & ~hard,
    }
    detectors: dict[str, DetectorTable] = {}
    for det in data.detectors:
        if det == "std":
            continue
        t_det = data.clip_table("wild", detector=det)
        ceil = clip_ceiling(data, t_det, det)
        detectors[det] = DetectorTable(
            methods=_method_rows(data, t_det, subsets),
            ceiling=_row(data, t_det, ceil, subsets, 0),
            by_signal=auc_by_signal(
                data, t_det, {"ceiling": ceil, **{m: t_det.scores[m] for m in data.method_names}}
            ),
        )
    ceiling = clip_ceiling(data, table)
    return Table1(
        counts={
            **table.counts(),
            "ego_same_anomaly_in_window": _same_anomaly_positives(data, table),
        },
        size=(int(data.plan.wild_size[0]), int(data.plan.wild_size[1])),
        methods=_method_rows(data, table, subsets),
        ceiling=_row(data, table, ceiling, subsets, 0),
        by_signal=auc_by_signal(
            data, table, {"ceiling": ceiling, **{m: table.scores[m] for m in data.method_names}}
        ),
        detectors=detectors,
    )


def thresholds_of(data: EvalData) -> dict[str, float]:
    """Each method's F-maximising threshold on the whole wild clip set."""
    table = data.clip_table("wild")
    return {m: best_f_threshold(table.scores[m], table.labels) for m in data.method_names}
