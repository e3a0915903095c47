"""E5, texture loss: detection and pitch error inside the fog / tunnel / night segments of
the ``texture-loss`` drives against outside them."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from roadpreview.eval.experiments.base import (
    Array,
    BoolArray,
    hp_error,
    in_segments,
    jf,
    rms,
    segments,
)
from roadpreview.eval.experiments.data import EvalData
from roadpreview.eval.metrics import auc, confusion


@dataclass(frozen=True)
class Detection:
    """Clips inside (or outside) the segments: AUC, and BA at the method's threshold."""

    n_pos: int
    n_neg: int
    auc: float  #: NaN without both classes
    ba: float  #: NaN without both classes

    def as_dict(self) -> dict[str, Any]:
        return {"n_pos": self.n_pos, "n_neg": self.n_neg, "auc": jf(self.auc), "ba": jf(self.ba)}


@dataclass(frozen=True)
class TextureRow:
    inside: Detection
    outside: Detection
    #: pitch error inside the segments, high-passed by the detector window, deg RMS
    pitch_rms_hp_inside_deg: float
    #: pitch error inside the segments less its mean over the second before each, deg RMS
    pitch_rms_aligned_inside_deg: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "inside": self.inside.as_dict(),
            "outside": self.outside.as_dict(),
            "pitch_rms_hp_inside_deg": jf(self.pitch_rms_hp_inside_deg),
            "pitch_rms_aligned_inside_deg": jf(self.pitch_rms_aligned_inside_deg),
        }


@dataclass(frozen=True)
class TextureLoss:
    counts: dict[str, int]
    clips_inside: int
    size: tuple[int, int]
    methods: dict[str, TextureRow]

    def as_dict(self) -> dict[str, Any]:
        return {
            "counts": dict(self.counts),
            "clips_inside": self.clips_inside,
            "size": list(self.size),
            "methods": {m: r.as_dict() for m, r in self.methods.items()},
        }


def _detection(scores: Array, labels: BoolArray, threshold: float) -> Detection:
    both = bool(labels.any() and (~labels).any())
    return Detection(
        n_pos=int(labels.sum()),
        n_neg=int((~labels).sum()),
        auc=auc(scores, labels) if both else math.nan,
        ba=confusion(scores, labels, threshold).balanced_accuracy if both else math.nan,
    )


def _rms_deg(parts: list[Array]) -> float:
    return float(np.degrees(rms(np.concatenate(parts)))) if parts else math.nan


def texture_loss(data: EvalData, thresholds: Mapping[str, float]) -> TextureLoss:
    """Per method on the texture-loss set: AUC and BA (at the method's wild F-max
    threshold) for clips centred inside the fog / tunnel / night segments vs outside,
    and the pitch error inside them (RMS high-passed by the detector window, and RMS
    after aligning on the second before each segment)."""
    jobs = data.jobs["texture-loss"]
    table = data.clip_table("texture-loss")
    inside = np.zeros(len(table), dtype=np.bool_)
    i0 = 0
    for job in jobs:
        n = sum(1 for c in table.clips if c.recording == job.key)
        centers = np.asarray([c.t_center_s for c in table.clips[i0 : i0 + n]])
        inside[i0 : i0 + n] = in_segments(centers, segments(data.info(job)))
        i0 += n
    labels = table.labels
    res: dict[str, TextureRow] = {}
    for m in data.method_names:
        sc = table.scores[m]
        hp_err: list[Array] = []
        al_err: list[Array] = []
        for job in jobs:
            tr = data.traces(job)[m]
            truth = data.truth(job)
            err = tr["phi"] - np.interp(tr.t, truth["frame_t_s"], truth["cam_pitch_rad"])
            hp = hp_error(tr.t, err, data.detector_window_s)
            for _, s0, s1 in segments(data.info(job)):
                seg = (tr.t >= s0) & (tr.t <= s1)
                before = (tr.t >= s0 - 1.0) & (tr.t < s0)
                hp_err.append(hp[seg])
                if np.isfinite(err[before]).any():
                    al_err.append(err[seg] - np.nanmean(err[before]))
        res[m] = TextureRow(
            inside=_detection(sc[inside], labels[inside], thresholds[m]),
            outside=_detection(sc[~inside], labels[~inside], thresholds[m]),
            pitch_rms_hp_inside_deg=_rms_deg(hp_err),
            pitch_rms_aligned_inside_deg=_rms_deg(al_err),
        )
    return TextureLoss(
        counts=table.counts(),
        clips_inside=int(inside.sum()),
        size=(int(data.plan.texture_size[0]), int(data.plan.texture_size[1])),
        methods=res,
    )
