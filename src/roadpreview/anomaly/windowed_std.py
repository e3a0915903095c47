"""The paper's detector: s(t) = std of y_c over the last T seconds, threshold, NMS (eq. 1).

`WindowedStdDetector` takes one `TrajectorySample` per camera frame and keeps
s(t) for the whole lead and for its left and right halves as running
moments (`WindowedMoments`, one vector of three channels, plus a fourth for
the compensation applied). By default s is taken around the window's
least-squares line (``detrend``; the paper's plain std with ``detrend =
false``). A frame's s is compared with the threshold (the paper's pixel
threshold, or optionally one that follows the distance, raised while the
compensation swings, ``docs/detector.md``); peaks above it go through
non-maximum suppression (`PeakPicker`), so one bump gives one event. Frames
during and after a hard acceleration of the lead, DEGRADED fusion or an
IMU_ONLY fusion whose gyro bias has not settled are
*suppressed*: their peaks come out as events with a ``suppressed`` reason,
through a separate NMS so that they cannot hide a real bump next to them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from roadpreview.anomaly.base import (
    AnomalyEvent,
    DetectorFrame,
    LastFrame,
    TrajectorySample,
    next_time,
    run_frames,
)
from roadpreview.anomaly.config import DetectorConfig
from roadpreview.anomaly.nms import OnsetPicker, PeakPicker
from roadpreview.anomaly.running import WindowedMoments
from roadpreview.anomaly.suppression import SuppressionTracker
from roadpreview.configtools import check_ranges
from roadpreview.types import FusionMode, Side, SuppressionReason

FloatArray = NDArray[np.float64]

# auxiliary columns kept per frame in the window
_AUX_DISTANCE, _AUX_DISTANCE_STD, _AUX_SPEED, _AUX_MODE = range(4)


def classify_side(s_left: float, s_right: float, both_ratio: float) -> Side:
    """LEFT / RIGHT when one half moves clearly more, BOTH when they are alike."""
    if not (math.isfinite(s_left) and math.isfinite(s_right)):
        return Side.UNKNOWN
    lo, hi = min(s_left, s_right), max(s_left, s_right)
    if hi <= 0 or lo >= both_ratio * hi:
        return Side.BOTH
    return Side.LEFT if s_left > s_right else Side.RIGHT


@dataclass(frozen=True)
class DetectorRun:
    """A whole trajectory through the detector: per-frame arrays and all events."""

    t: FloatArray  #: frame times, s
    s: FloatArray  #: s(t), px (NaN while undefined)
    s_left: FloatArray  #: s of the left half, px
    s_right: FloatArray  #: s of the right half, px
    threshold_px: FloatArray  #: threshold per frame, px
    suppressed: NDArray[np.int64]  #: `SuppressionReason` bits per frame
    events: list[AnomalyEvent]  #: every event, suppressed ones included

    @property
    def alerts(self) -> list[AnomalyEvent]:
        """The events that are not suppressed."""
        return [e for e in self.events if not e.suppressed]


class WindowedStdDetector(LastFrame):
    """Streaming windowed-std detector with NMS, sides and suppression (module docstring).

    ``push`` costs O(1) per frame (plus O(window) when a new peak candidate
    appears, which only happens above threshold). Times must increase.
    """

    def __init__(self, config: DetectorConfig | None = None) -> None:
        self.config = config or DetectorConfig()
        check_ranges(self.config, "DetectorConfig")
        self.config.validate()
        self._moments = self._new_moments()
        self._nms = self._picker()
        self._nms_suppressed = self._picker()
        cfg = self.config
        self._suppression = SuppressionTracker(
            lead_accel_limit_mps2=cfg.lead_accel_limit_mps2,
            settle_s=cfg.imu_only_settle_s,
            span_s=cfg.window_s + cfg.suppress_hold_s,
        )
        # a FUSED stretch counts as a frame interval, or at most one window across a gap
        self._suppression.max_step_s = cfg.window_s
        self._frame: DetectorFrame | None = None
        self._t_last = -math.inf

    def _picker(self) -> PeakPicker[AnomalyEvent] | OnsetPicker[AnomalyEvent]:
        """Events at their peak (the paper's NMS) or at their onset (``emit``)."""
        if self.config.emit == "onset":
            return OnsetPicker(self.config.nms_window_s)
        return PeakPicker(self.config.nms_window_s)

    @property
    def moments(self) -> WindowedMoments:
        """The running moments (channels: whole lead, left half, right half, the
        compensation applied)."""
        return self._moments

    def _new_moments(self) -> WindowedMoments:
        # channels: whole lead, left half, right half, the compensation applied
        return WindowedMoments(
            self.config.window_s,
            4,
            aux_columns=4,
            recompute_every=self.config.recompute_every,
            trend=self.config.detrend,
        )

    def threshold_px(self, distance_m: float, s_comp_px: float = math.nan) -> float:
        """The threshold at a lead distance (NaN distance: the pixel threshold), raised in
        quadrature by ``compensation_error_fraction`` times the windowed std of the
        compensation (NaN: not raised)."""
        cfg = self.config
        thr = cfg.threshold_px
        if cfg.threshold_mode == "distance" and math.isfinite(distance_m) and distance_m > 0:
            thr = max(thr, cfg.signal.s_px(cfg.min_height_m, distance_m))
        if cfg.compensation_error_fraction > 0 and math.isfinite(s_comp_px):
            thr = math.hypot(thr, cfg.compensation_error_fraction * s_comp_px)
        return thr

    def _s_values(self, t: float) -> tuple[list[float], int]:
        """s of the four channels (NaN where undefined) and the whole-lead sample count."""
        cfg = self.config
        m = self._moments
        counts = m.counts()
        need = max(cfg.min_samples, math.ceil(cfg.min_valid_fraction * m.size))
        if t - m.oldest_t < cfg.min_span_fraction * cfg.window_s - m.time_tol_s:
            return [math.nan] * 4, counts[0]
        s = m.detrended_std_values() if cfg.detrend else m.std_values()
        return [v if n >= need else math.nan for v, n in zip(s, counts, strict=True)], counts[0]

    def _describe_peak(
        self, t: float, s: list[float], threshold: float, suppressed: SuppressionReason
    ) -> AnomalyEvent:
        """The event a peak at ``t`` would be (its emission time is set on confirmation)."""
        times, x, aux = self._moments.window()
        y = x[:, 0]
        steps = np.abs(np.diff(y))  # NaN next to an invalid frame
        finite = np.isfinite(steps)
        # the crossing: the steepest change of y_c in the window (a step's edge, a bump's flank)
        i = int(np.argmax(np.where(finite, steps, -1.0))) + 1 if finite.any() else len(times) - 1
        distance = float(aux[i, _AUX_DISTANCE])
        distance_std = float(aux[i, _AUX_DISTANCE_STD])
        if not math.isfinite(distance):  # the crossing frame has none: nearest one that has
            known = np.flatnonzero(np.isfinite(aux[:, _AUX_DISTANCE]))
            if known.size:
                j = int(known[np.argmin(np.abs(known - i))])
                distance = float(aux[j, _AUX_DISTANCE])
                distance_std = float(aux[j, _AUX_DISTANCE_STD])
        speed = float(aux[i, _AUX_SPEED])
        return AnomalyEvent(
            t_s=float(times[i]),
            t_peak_s=t,
            t_emit_s=math.nan,
            s_px=s[0],
            s_left_px=s[1],
            s_right_px=s[2],
            threshold_px=threshold,
            side=classify_side(s[1], s[2], self.config.both_sides_ratio),
            lead_distance_m=distance,
            lead_distance_std_m=distance_std,
            ego_speed_mps=speed if math.isfinite(speed) else None,
            mode=FusionMode(int(aux[i, _AUX_MODE])),
            valid_fraction=float(np.count_nonzero(np.isfinite(y)) / len(y)),
            suppressed=suppressed,
            score=s[0],
            threshold=threshold,
        )

    def push(self, sample: TrajectorySample) -> list[AnomalyEvent]:
        """Take the next frame; return the events confirmed at it (suppressed ones included)."""
        t = self._t_last = next_time(sample.t, self._t_last)
        if sample.valid:
            x = [sample.y_c, sample.y_c_left, sample.y_c_right]
            x = [float(v) if math.isfinite(v) else math.nan for v in x]
        else:
            x = [math.nan] * 3
        comp = float(sample.compensation_px)
        x.append(comp if math.isfinite(comp) else math.nan)
        speed = sample.ego_speed_mps
        aux = [
            sample.lead_distance_m,
            sample.lead_distance_std_m,
            math.nan if speed is None else speed,
            int(sample.mode),
        ]
        self._moments.push(t, x, aux)
        s, n = self._s_values(t)
        threshold = self.threshold_px(sample.lead_distance_m, s[3])
        suppressed = self._suppression.push(sample)
        self._frame = DetectorFrame(
            t=t,
            s=s[0],
            s_left=s[1],
            s_right=s[2],
            threshold_px=threshold,
            n_samples=n,
            suppressed=suppressed,
            score=s[0],
            threshold=threshold,
            t_score=t,
        )
        value = s[0] if s[0] > threshold else -math.inf
        main, other = (-math.inf, value) if suppressed else (value, -math.inf)

        def describe() -> AnomalyEvent:
            return self._describe_peak(t, s, threshold, suppressed)

        confirmed = self._nms.push(t, main, describe)
        confirmed += self._nms_suppressed.push(t, other, describe)
        return [replace(e, t_emit_s=t) for e in confirmed]

    def restart(self) -> list[AnomalyEvent]:
        """A new target (the tracker switched vehicles): confirm pending peaks and start an
        empty window, so that the jump between two vehicles' trajectories is not a bump."""
        events = self.flush()
        self._moments = self._new_moments()
        self._nms = self._picker()
        self._nms_suppressed = self._picker()
        return events

    def flush(self) -> list[AnomalyEvent]:
        """End of stream: pending peaks, confirmed at the last frame's time."""
        pending = self._nms.flush() + self._nms_suppressed.flush()
        return [replace(e, t_emit_s=self._t_last) for e in pending]

    def run(self, samples: Iterable[TrajectorySample]) -> DetectorRun:
        """Push every sample, flush, and return per-frame arrays and all events."""
        columns, suppressed, events = run_frames(
            self, samples, ("t", "s", "s_left", "s_right", "threshold_px")
        )
        t, s, s_left, s_right, threshold_px = columns
        return DetectorRun(t, s, s_left, s_right, threshold_px, suppressed, events)
