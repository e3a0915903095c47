"""What the detector consumes and produces: trajectory samples, per-frame values, events.

A `TrajectorySample` is one camera frame's compensated lead-vehicle position
(paper eq. 4, ``docs/method.md``), with the context the detector needs to
judge it. A `DetectorFrame` is the detector's per-frame output (s(t) and why
it may be suppressed); an `AnomalyEvent` is one detected bump after
non-maximum suppression. Detectors follow the `Detector` protocol.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum
from operator import attrgetter
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from roadpreview.errors import InputDataError
from roadpreview.types import FusionMode, Side, SuppressionReason


@dataclass(frozen=True, slots=True)
class TrajectorySample:
    """One frame of the compensated lead trajectory and its context.

    Pixels follow ``docs/method.md`` (v down). Unknown floats are NaN;
    ``lead_accel_mps2`` and ``ego_speed_mps`` are None when no sensor gives
    them. ``valid=False`` marks a frame without a usable lead position (lost
    track); it is kept for its time stamp but not used in s(t).
    """

    t: float  #: frame time, s (one clock for the whole pipeline)
    y_c: float  #: compensated vertical image position of the lead, px (eq. 4)
    y_c_left: float = math.nan  #: the same for the left half of the lead, px
    y_c_right: float = math.nan  #: the same for the right half of the lead, px
    lead_distance_m: float = math.nan  #: distance from the ego camera to the lead, m
    lead_distance_std_m: float = math.nan  #: standard deviation of that distance, m
    mode: FusionMode = FusionMode.FUSED  #: where the compensating pitch came from
    lead_accel_mps2: float | None = None  #: lead's longitudinal acceleration, m/s² (+ forward)
    ego_speed_mps: float | None = None  #: ego speed over ground from CAN, m/s
    valid: bool = True  #: False when the lead position of this frame is unusable
    #: the correction subtracted from y to get y_c (f tan φ + the heave term), px; NaN if
    #: unknown. Its windowed spread says how hard the compensation is working
    compensation_px: float = math.nan
    #: camera focal length (vertical), px: turns pixels at the lead's distance into metres.
    #: NaN: unknown (the detector then works in pixels and gives no height)
    focal_px: float = math.nan
    #: the ego's vertical specific force over the frame interval, band-passed (gravity and
    #: slow tilt removed), m/s²: RMS and largest magnitude of the IMU samples since the
    #: previous frame; NaN without an accelerometer (`roadpreview.ego`)
    ego_accel_rms_mps2: float = math.nan
    ego_accel_peak_mps2: float = math.nan


@dataclass(frozen=True, slots=True)
class DetectorFrame:
    """The detector's output for one frame; values are NaN while undefined.

    ``score`` is the detector's own statistic against its ``threshold`` (the windowed
    std: s in px; the two-axle detector: the fitted road input in units of its running
    background); ``t_score`` is the time the score describes (the windowed std: this
    frame; the two-axle detector: the front axle's crossing it hypothesises). The s
    columns are the paper's eq. 1 (NaN for detectors that do not compute it).
    """

    t: float  #: frame time, s
    s: float  #: paper eq. 1 on the whole lead, px
    s_left: float  #: eq. 1 on the left half, px
    s_right: float  #: eq. 1 on the right half, px
    threshold_px: float  #: threshold in force at this frame, px (NaN: not a pixel threshold)
    n_samples: int  #: valid samples of the whole-lead trajectory in the window
    suppressed: SuppressionReason  #: why alerts are held back (falsy: they are not)
    score: float = math.nan  #: the detector's statistic (see the class docstring)
    threshold: float = math.nan  #: the threshold on ``score`` in force at this frame
    t_score: float = math.nan  #: the time ``score`` describes, s
    height_m: float = math.nan  #: road input the best fit stands for, m (bump +, pothole -)
    background_m: float = math.nan  #: running background of that estimate (1 std), m

    @property
    def above(self) -> bool:
        """True when the score exceeds the threshold (whether or not suppressed)."""
        return self.score > self.threshold


class EventKind(IntEnum):
    """What an event says about an anomaly (`AnomalyEvent.kind`)."""

    CONFIRMED = 0  #: the detector's full fit: an alert, or the confirmation of a provisional one
    PROVISIONAL = 1  #: an early look (the lead's front axle): confirmed or cancelled later
    CANCELLED = 2  #: a provisional event that the full fit did not confirm


@dataclass(frozen=True, slots=True)
class AnomalyEvent:
    """One detected anomaly: the peak of s(t) after non-maximum suppression.

    ``t_s`` is the estimated moment the lead crossed the anomaly (the
    steepest change of y_c in the peak's window), ``t_peak_s`` the frame of
    the peak of s and ``t_emit_s`` the frame at which the event was
    confirmed (``t_peak_s`` + the NMS window; with ``emit = "onset"`` the
    "peak" is the frame where s first exceeded the threshold, and the event is
    emitted there). Distance, speed and mode are
    the values at the crossing. A suppressed event (``suppressed`` truthy)
    is reported for visibility and must not raise an alert.
    """

    t_s: float  #: estimated crossing time, s
    t_peak_s: float  #: time of the peak of s, s
    t_emit_s: float  #: time the event was confirmed, s
    s_px: float  #: peak value of s, px
    s_left_px: float  #: s of the left half at the peak, px (NaN if unknown)
    s_right_px: float  #: s of the right half at the peak, px (NaN if unknown)
    threshold_px: float  #: threshold at the peak, px
    side: Side  #: left / right / both / unknown
    lead_distance_m: float  #: lead distance at the crossing, m (NaN if unknown)
    lead_distance_std_m: float  #: its standard deviation, m (NaN if unknown)
    ego_speed_mps: float | None  #: ego speed at the crossing, m/s
    mode: FusionMode  #: fusion mode at the crossing
    valid_fraction: float  #: share of the peak window's frames with a valid position
    suppressed: SuppressionReason  #: why this peak must not become an alert (falsy: it may)
    score: float = math.nan  #: the detector's statistic at the event (std: s_px)
    threshold: float = math.nan  #: the threshold on ``score`` at the event
    #: estimated road input: height of the anomaly (bump +, pothole -), m, and its std;
    #: NaN when the detector gives none (no focal length or distance)
    height_m: float = math.nan
    height_std_m: float = math.nan
    length_m: float = math.nan  #: estimated length along the road, m (NaN: not resolved)
    lead_speed_mps: float = math.nan  #: the lead's speed over ground at the crossing, m/s
    #: distance from the ego camera to the anomaly at ``t_s``, m (NaN: take the lead's)
    anomaly_distance_m: float = math.nan
    #: probability that the event is a real anomaly (calibrated; NaN: the detector has no
    #: calibration, the alert's heuristic applies)
    confidence: float = math.nan
    kind: EventKind = EventKind.CONFIRMED  #: confirmed, provisional or a cancellation
    #: the provisional event's number (1, 2, ...) that this event is, confirms or cancels;
    #: 0: none (a confirmed event without a provisional one before it)
    ref: int = 0


class Detector(Protocol):
    """A streaming anomaly detector: push one sample, get the events it confirms."""

    def push(self, sample: TrajectorySample) -> list[AnomalyEvent]:
        """Take the next frame (times increasing); return the events confirmed now."""
        ...

    def flush(self) -> list[AnomalyEvent]:
        """End of stream: confirm and return pending peaks."""
        ...

    def restart(self) -> list[AnomalyEvent]:
        """A new target: the pending events, then a window without the old one's frames."""
        ...

    @property
    def frame(self) -> DetectorFrame | None:
        """The output for the last pushed sample (None before the first)."""
        ...


class LastFrame:
    """`Detector.frame` for a detector that keeps its last output in ``_frame``."""

    _frame: DetectorFrame | None

    @property
    def frame(self) -> DetectorFrame | None:
        """The output for the last pushed sample (None before the first)."""
        return self._frame


def next_time(t: float, t_last: float) -> float:
    """A pushed sample's time ``t`` as a float, checked to be finite and after ``t_last``.

    Raises
    ------
    InputDataError
        When it is not.
    """
    t = float(t)
    if not math.isfinite(t) or t <= t_last:
        raise InputDataError(
            f"trajectory sample t = {t!r} s: times must be finite and increase"
            f" (previous {t_last} s)"
        )
    return t


def run_frames(
    detector: Detector, samples: Iterable[TrajectorySample], columns: tuple[str, ...]
) -> tuple[list[NDArray[np.float64]], NDArray[np.int64], list[AnomalyEvent]]:
    """Push every sample through ``detector`` and flush: the body of a detector's ``run``.

    Returns one array per `DetectorFrame` field named in ``columns`` (in that order) with
    its value at every frame, the frames' `SuppressionReason` bits, and every event.
    """
    pick = attrgetter(*columns)
    rows: list[tuple[float, ...]] = []
    suppressed: list[int] = []
    events: list[AnomalyEvent] = []
    for sample in samples:
        events.extend(detector.push(sample))
        f = detector.frame
        assert f is not None
        rows.append(pick(f))
        suppressed.append(int(f.suppressed))
    events.extend(detector.flush())
    table = np.array(rows, dtype=np.float64).reshape(-1, len(columns))
    return (
        [table[:, i].copy() for i in range(len(columns))],
        np.array(suppressed, dtype=np.int64),
        events,
    )
