"""The two-axle detector's events (`roadpreview.anomaly.two_axle`): a whole run's
(`TwoAxleRun`), the excursion picker of the two-axle fit, and the provisional events of
its early fit with the list of those waiting for the two-axle fit to confirm or cancel
them (docs/detector.md, "Provisional alerts")."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.anomaly.base import AnomalyEvent, EventKind
from roadpreview.anomaly.config import TwoAxleConfig
from roadpreview.anomaly.two_axle_refine import Hypothesis
from roadpreview.anomaly.two_axle_signal import COL_D, COL_DSTD, COL_MODE, COL_T, COL_V, FloatArray
from roadpreview.types import FusionMode, Side, SuppressionReason


class ExcursionPicker:
    """One event per excursion above the threshold, at a fixed delay: the first eligible
    frame opens it, the best score within ``window_s`` describes it, and it is confirmed
    ``window_s`` after it opened (a bounded latency: `TwoAxleDetector._refine` then
    settles its alignment on the frames seen since)."""

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._cand: tuple[float, float, tuple[AnomalyEvent, Hypothesis]] | None = None

    def due(self, t: float) -> list[tuple[AnomalyEvent, Hypothesis]]:
        """The excursion confirmed at ``t`` (its window has passed), if any."""
        if self._cand is not None and t - self._cand[0] >= self.window_s - 1e-9:
            out = [self._cand[2]]
            self._cand = None
            return out
        return []

    def offer(
        self, t: float, value: float, describe: Callable[[], tuple[AnomalyEvent, Hypothesis]]
    ) -> None:
        """A frame's score (-inf: not eligible): opens an excursion or may improve it."""
        if math.isfinite(value):
            if self._cand is None:
                self._cand = (t, value, describe())
            elif value > self._cand[1]:
                self._cand = (self._cand[0], value, describe())

    def flush(self) -> list[tuple[AnomalyEvent, Hypothesis]]:
        if self._cand is None:
            return []
        out = [self._cand[2]]
        self._cand = None
        return out


@dataclass
class Pending:
    """A provisional event waiting for the two-axle fit to confirm or cancel it."""

    ref: int  #: its number
    event: AnomalyEvent
    check_t: float  #: by then the two-axle fit must have an excursion for it open, s
    due_t: float  #: by then it must be confirmed, s


@dataclass(frozen=True)
class TwoAxleRun:
    """A whole trajectory through the detector: per-frame arrays and all events."""

    t: FloatArray  #: frame times, s
    score: FloatArray  #: z per frame (NaN while undefined)
    t_score: FloatArray  #: the crossing time each score hypothesises, s
    height_m: FloatArray  #: the best fit's road input, m
    background_m: FloatArray  #: its background, m
    suppressed: NDArray[np.int64]
    events: list[AnomalyEvent]

    @property
    def alerts(self) -> list[AnomalyEvent]:
        """The confirmed events that raise (or confirm) an alert."""
        return [e for e in self.events if not e.suppressed and e.kind is EventKind.CONFIRMED]

    @property
    def provisional(self) -> list[AnomalyEvent]:
        """The provisional events that raise an alert."""
        return [e for e in self.events if not e.suppressed and e.kind is EventKind.PROVISIONAL]


def lead_at(rows: FloatArray, t: float) -> tuple[int, float, float]:
    """The frame of ``rows`` nearest after ``t``, and the lead's distance and its std at the
    frame nearest to it that has one (NaN: none)."""
    i = int(np.clip(np.searchsorted(rows[:, COL_T], t), 0, rows.shape[0] - 1))
    d = rows[:, COL_D]
    known = np.flatnonzero(np.isfinite(d))
    if not known.size:
        return i, math.nan, math.nan
    i_d = int(known[np.argmin(np.abs(known - i))])
    return i, float(d[i_d]), float(rows[i_d, COL_DSTD])


def calibrated(logit: tuple[float, float], score: float, threshold: float) -> float:
    """The probability 1 / (1 + exp(-(a + b ln(score / threshold)))) of a logistic
    calibration ``logit`` = (a, b) (the two-axle fit's and the early fit's)."""
    a, b = logit
    x = a + b * math.log(max(score, 1e-9) / threshold)
    return 1.0 / (1.0 + math.exp(-min(max(x, -50.0), 50.0)))


def fitted_event(
    cfg: TwoAxleConfig,
    rows: FloatArray,
    *,
    t: float,
    centre: float,
    side: Side,
    height_m: float,
    std_m: float,
    score: float,
    threshold: float,
    confidence: float,
    suppressed: SuppressionReason,
    lead_speed_mps: float,
    t_emit_s: float = math.nan,
    valid_fraction: float = 1.0,
    kind: EventKind = EventKind.CONFIRMED,
    ref: int = 0,
) -> AnomalyEvent:
    """The event of a fit (the two-axle fit's candidate, or the early fit's PROVISIONAL
    event) scored at ``t`` for the front axle over the anomaly's middle at ``centre``: the
    lead's distance (`lead_at`), the ego's speed and the fusion mode there."""
    i, distance, dstd = lead_at(rows, centre)
    speed = float(rows[i, COL_V])
    v = cfg.vehicle
    return AnomalyEvent(
        t_s=centre,
        t_peak_s=t,
        t_emit_s=t_emit_s,
        s_px=math.nan,
        s_left_px=math.nan,
        s_right_px=math.nan,
        threshold_px=math.nan,
        side=side,
        lead_distance_m=distance,
        lead_distance_std_m=dstd,
        ego_speed_mps=speed if math.isfinite(speed) else None,
        mode=FusionMode(int(rows[i, COL_MODE])),
        valid_fraction=valid_fraction,
        suppressed=suppressed,
        score=score,
        threshold=threshold,
        height_m=height_m,
        height_std_m=std_m,
        lead_speed_mps=lead_speed_mps,
        anomaly_distance_m=distance + v.rear_overhang_m + v.wheelbase_m,
        confidence=confidence,
        kind=kind,
        ref=ref,
    )
