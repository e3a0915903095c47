"""Clip scores: one number per labelled clip and method, the maximum of s(t) in a window.

s(t) is the standard deviation of y_c over the last second (paper eq. 1), so
a lead crossing at t_c raises s from about t_c (its front wheels climb a few
tenths of a second before the apex) until about t_c + 1 s + the duration of
the lead's response (its rear axle, then the body settling, a few tenths of
a second). The score of a clip centred at t_c is therefore

    score = max { s(t) : t_c + a <= t <= t_c + b },   (a, b) = `SCORE_WINDOW_S` = (-0.2, 1.2) s

and the same window is used for background clips. Frames without s (no
lead, start-up) are skipped; a clip without any s in its window scores 0 and
is counted as "no lead".

A background clip is *hard* when the ego crosses an anomaly while its score
can see it: its own crossing moves y_c from T (the detector window,
``[anomaly.std] window_s``) before the score window to its end, so the hard
window is ``(a - T, b)``. The functions take T as ``detector_window_s``; the
evaluation passes the configured one.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roadpreview.anomaly.config import DetectorConfig
from roadpreview.eval.runner import Trace
from roadpreview.sim.dataset import Clip, clips_of_recording

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: (a, b): the clip score is the maximum of s over [t_c + a, t_c + b], s
SCORE_WINDOW_S: tuple[float, float] = (-0.2, 1.2)
#: the detector's window T by default: `DetectorConfig.window_s` (paper: 30 frames at 30 fps)
DETECTOR_WINDOW_S = DetectorConfig().window_s


def hard_window(
    score_window: tuple[float, float] = SCORE_WINDOW_S,
    detector_window_s: float = DETECTOR_WINDOW_S,
) -> tuple[float, float]:
    """Where an ego crossing (relative to the clip centre) can reach the clip's score."""
    return score_window[0] - detector_window_s, score_window[1]


@dataclass(frozen=True)
class Scores:
    """A detector's score per frame of one trace: ``s`` describes the time ``t`` (the
    windowed std: the frame's time; the two-axle detector: the crossing it hypothesises,
    not monotonic in the frame order)."""

    t: Array
    s: Array


def window_max(
    t: Array, s: Array, center: float, window: tuple[float, float] = SCORE_WINDOW_S
) -> tuple[float, bool]:
    """The maximum of the finite s whose time lies in ``[center + a, center + b]`` and
    whether there was one (False: no lead in the window, the score is 0)."""
    lo_t, hi_t = center + window[0], center + window[1]
    if t.size < 2 or bool(np.all(np.diff(t) > 0)):
        lo = int(np.searchsorted(t, lo_t, side="left"))
        hi = int(np.searchsorted(t, hi_t, side="right"))
        seg = s[lo:hi]
    else:
        seg = s[(t >= lo_t) & (t <= hi_t)]
    seg = seg[np.isfinite(seg)]
    if seg.size == 0:
        return 0.0, False
    return float(seg.max()), True


def clip_scores(
    scores: Scores, centers: Iterable[float], window: tuple[float, float] = SCORE_WINDOW_S
) -> tuple[Array, BoolArray]:
    """`window_max` of one trace's scores at each centre: (scores, has_lead)."""
    out = [window_max(scores.t, scores.s, c, window) for c in centers]  # clips, not frames
    values = np.asarray([o[0] for o in out], dtype=np.float64)
    found = np.asarray([o[1] for o in out], dtype=np.bool_)
    return values, found


def draw_clips(
    folder: Path,
    name: str,
    seed: Sequence[int],
    *,
    window: tuple[float, float] = SCORE_WINDOW_S,
    clip_half_s: float = 2.5,
    clearance_s: float = 2.0,
    ego_crossing_share: float = 0.3,
    clear_of_hits_only: bool = True,
    background_spacing_s: float | None = 2.5,
    detector_window_s: float = DETECTOR_WINDOW_S,
) -> list[Clip]:
    """Positive and background clips of one recording (`clips_of_recording`), with the
    hard flag for backgrounds and a share of them on the ego's crossings."""
    return clips_of_recording(
        folder,
        name,
        np.random.default_rng(list(seed)),
        clip_half_s=clip_half_s,
        clearance_s=clearance_s,
        hard_window_s=hard_window(window, detector_window_s),
        ego_crossing_share=ego_crossing_share,
        clear_of_hits_only=clear_of_hits_only,
        background_spacing_s=background_spacing_s,
    )


@dataclass
class ClipTable:
    """Labelled clips of a data set with every method's score."""

    clips: list[Clip]
    scores: dict[str, Array] = field(default_factory=dict)
    has_lead: dict[str, BoolArray] = field(default_factory=dict)
    #: per clip: the truth's lead distance at the clip centre (m; NaN unknown)
    true_distance_m: Array = field(default_factory=lambda: np.empty(0))
    #: per clip: extra boolean masks (e.g. "low-texture")
    masks: dict[str, BoolArray] = field(default_factory=dict)

    @property
    def labels(self) -> BoolArray:
        return np.asarray([c.label == 1 for c in self.clips], dtype=np.bool_)

    @property
    def hard(self) -> BoolArray:
        return np.asarray([c.hard for c in self.clips], dtype=np.bool_)

    @property
    def groups(self) -> NDArray[Any]:
        return np.asarray([c.recording for c in self.clips])

    @property
    def n_pos(self) -> int:
        return int(self.labels.sum())

    @property
    def n_neg(self) -> int:
        return len(self.clips) - self.n_pos

    def __len__(self) -> int:
        return len(self.clips)

    def subset(self, mask: BoolArray) -> ClipTable:
        idx = np.flatnonzero(mask)
        return ClipTable(
            clips=[self.clips[i] for i in idx],
            scores={m: v[idx] for m, v in self.scores.items()},
            has_lead={m: v[idx] for m, v in self.has_lead.items()},
            true_distance_m=self.true_distance_m[idx],
            masks={k: v[idx] for k, v in self.masks.items()},
        )

    def counts(self) -> dict[str, int]:
        lab, hard = self.labels, self.hard
        ego = np.asarray([c.kind == "ego-crossing" for c in self.clips], dtype=np.bool_)
        return {
            "clips": len(self),
            "positives": int(lab.sum()),
            "backgrounds": int((~lab).sum()),
            "hard_positives": int((lab & hard).sum()),
            "hard_backgrounds": int((~lab & hard).sum()),
            "ego_crossing_backgrounds": int(ego.sum()),
            "tracked": int(self.masks["tracked"].sum()) if "tracked" in self.masks else -1,
            "recordings": len(set(self.groups.tolist())),
        }


def box_iou(a: Array, b: Array) -> Array:
    """Intersection over union of boxes (x0, y0, x1, y1) row by row; NaN rows give 0."""
    x0 = np.maximum(a[:, 0], b[:, 0])
    y0 = np.maximum(a[:, 1], b[:, 1])
    x1 = np.minimum(a[:, 2], b[:, 2])
    y1 = np.minimum(a[:, 3], b[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = inter / (area_a + area_b - inter)
    return np.asarray(np.nan_to_num(iou, nan=0.0), dtype=np.float64)


#: a clip is "tracked" when the lead's box overlaps the true one (IoU >= this) ...
TRACKED_IOU = 0.5
#: ... in at least this share of the frames its score depends on
TRACKED_SHARE = 0.8


def tracked_clips(
    trace: Trace,
    true_box: Array,
    centers: Sequence[float],
    window: tuple[float, float] = SCORE_WINDOW_S,
    detector_window_s: float = DETECTOR_WINDOW_S,
) -> BoolArray:
    """Whether the tracker followed the true lead over the frames each clip's score
    depends on (``[t_c + a - T, t_c + b]``); the vision is shared, so any trace will do."""
    box = np.column_stack([trace[c] for c in ("box_x0", "box_y0", "box_x1", "box_y1")])
    good = box_iou(box, true_box[: len(trace)]) >= TRACKED_IOU
    out = []
    for c in centers:  # clips, not frames
        lo = int(np.searchsorted(trace.t, c + window[0] - detector_window_s, side="left"))
        hi = int(np.searchsorted(trace.t, c + window[1], side="right"))
        out.append(hi > lo and float(good[lo:hi].mean()) >= TRACKED_SHARE)
    return np.asarray(out, dtype=np.bool_)


def score_table(
    clips_by_recording: Mapping[str, list[Clip]],
    scores_by_recording: Mapping[str, Mapping[str, Scores]],
    truth_by_recording: Mapping[str, Mapping[str, Array]],
    window: tuple[float, float] = SCORE_WINDOW_S,
    *,
    boxes_by_recording: Mapping[str, Trace],
    tracked_window: tuple[float, float] = SCORE_WINDOW_S,
    detector_window_s: float = DETECTOR_WINDOW_S,
) -> ClipTable:
    """All clips of a data set with every method's score (recording key -> clips,
    -> method scores, -> truth arrays ``frame_t_s``, ``lead_distance_m`` and
    ``lead_box_px``), with the mask ``tracked`` (`tracked_clips` of the recording's trace
    in ``boxes_by_recording`` over ``tracked_window``)."""
    clips: list[Clip] = []
    scores: dict[str, list[Array]] = {}
    found: dict[str, list[BoolArray]] = {}
    dist: list[Array] = []
    tracked: list[BoolArray] = []
    for key, rec_clips in clips_by_recording.items():
        if not rec_clips:
            continue
        clips += rec_clips
        centers = [c.t_center_s for c in rec_clips]
        for m, sc in scores_by_recording[key].items():
            values, ok = clip_scores(sc, centers, window)
            scores.setdefault(m, []).append(values)
            found.setdefault(m, []).append(ok)
        truth = truth_by_recording[key]
        dist.append(np.interp(centers, truth["frame_t_s"], truth["lead_distance_m"]))
        boxes = boxes_by_recording[key]
        tracked.append(
            tracked_clips(boxes, truth["lead_box_px"], centers, tracked_window, detector_window_s)
        )
    return ClipTable(
        clips=clips,
        scores={m: np.concatenate(v) for m, v in scores.items()},
        has_lead={m: np.concatenate(v) for m, v in found.items()},
        true_distance_m=np.concatenate(dist) if dist else np.empty(0),
        masks={"tracked": np.concatenate(tracked) if tracked else np.empty(0, dtype=np.bool_)},
    )


def background_windows(
    duration_s: float,
    lead_crossings: Sequence[float],
    *,
    step_s: float = 0.5,
    window: tuple[float, float] = SCORE_WINDOW_S,
    start_s: float = 2.5,
    lead_response_s: tuple[float, float] = (-0.3, 1.0),
    detector_window_s: float = DETECTOR_WINDOW_S,
) -> Array:
    """Centres of background windows every ``step_s`` whose score cannot see any lead
    crossing: the lead's response ``[t_l + r0, t_l + r1]`` stays outside the y_c the
    window's s uses, ``[t + a - T, t + b]``."""
    t = np.arange(start_s, duration_s - window[1] - 0.1, step_s)
    if not len(lead_crossings) or not t.size:
        return t
    tl = np.asarray(lead_crossings, dtype=np.float64)
    lo = t[:, None] + window[0] - detector_window_s
    hi = t[:, None] + window[1]
    clash = (tl[None, :] + lead_response_s[1] >= lo) & (tl[None, :] + lead_response_s[0] <= hi)
    return t[~clash.any(axis=1)]


def mean_abs_rate(t: Array, rate: Array, lo: Array, hi: Array) -> Array:
    """Mean |rate| over ``[lo_i, hi_i]`` for each window (cumulative sums: vectorised)."""
    c = np.concatenate([[0.0], np.cumsum(np.abs(rate))])
    i0 = np.searchsorted(t, lo, side="left")
    i1 = np.searchsorted(t, hi, side="right")
    n = np.maximum(i1 - i0, 1)
    out = (c[i1] - c[i0]) / n
    out[i1 <= i0] = math.nan
    return np.asarray(out, dtype=np.float64)
