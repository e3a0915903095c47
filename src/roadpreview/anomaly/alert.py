"""Alerts: what the predictive suspension is told about a detected anomaly.

`AlertBuilder` turns an `AnomalyEvent` into an `Alert`: where the anomaly is
(the lead's distance when it crossed it), when the ego gets there (distance
/ ego speed from CAN), how strong it is (s in px and a height estimate from
the paper's s = α f δ / d + β), which side, how confident we are, and the
fusion mode. Suppressed events give no alert (``build`` returns None).
``roadpreview.canbus`` puts alerts on the bus (message ``RP_ALERT``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from roadpreview.anomaly.base import AnomalyEvent, Side
from roadpreview.anomaly.config import AlertConfig, SignalModel
from roadpreview.configtools import check_ranges
from roadpreview.fusion.mode import FusionMode


@dataclass(frozen=True, slots=True)
class Alert:
    """A predictive alert about one road anomaly ahead.

    Times are on the pipeline's clock. The anomaly is ``distance_m`` ahead of
    the ego at ``t_s`` and reached at ``t_s + time_to_arrival_s`` if the speed
    stays the same; the alert exists from ``t_emit_s`` on (detection delay
    ``t_emit_s - t_s``). None: unknown.
    """

    t_s: float  #: when the lead crossed the anomaly, s
    t_emit_s: float  #: when the detector confirmed it, s
    distance_m: float | None  #: distance from the ego camera to the anomaly at t_s, m
    time_to_arrival_s: float | None  #: until the ego's front axle is there, from t_s, s
    severity_px: float  #: the detector's score (std: peak s in px; two-axle: background stds)
    #: estimated anomaly height, mm: signed (bump +, pothole -) from the two-axle
    #: detector's inverse model; the std detector's α f δ / d model gives a magnitude
    height_mm: float | None
    side: Side  #: left / right / both / unknown
    #: probability that the anomaly is real (two-axle: calibrated on the evaluation's
    #: training folds); the std detector's is a heuristic (docs/detector.md)
    confidence: float
    mode: FusionMode  #: fusion mode at the crossing
    alert_id: int = 0  #: sequence number of the alert since start (CAN: modulo 256)
    height_std_mm: float | None = None  #: std of ``height_mm`` (None: unknown)
    length_m: float | None = None  #: estimated length along the road (None: not resolved)
    lead_speed_mps: float | None = None  #: the lead's speed when it crossed, m/s

    @property
    def arrival_t_s(self) -> float | None:
        """Predicted time the ego reaches the anomaly (None if unknown)."""
        return None if self.time_to_arrival_s is None else self.t_s + self.time_to_arrival_s

    def time_left_s(self, now_s: float) -> float | None:
        """Time until the ego reaches the anomaly, seen at ``now_s`` (None if unknown)."""
        arrival = self.arrival_t_s
        return None if arrival is None else arrival - now_s


class AlertBuilder:
    """Events in, alerts out (module docstring)."""

    def __init__(
        self, config: AlertConfig | None = None, signal: SignalModel | None = None
    ) -> None:
        self.config = config or AlertConfig()
        check_ranges(self.config, "AlertConfig")
        self.config.validate()
        self.signal = signal or SignalModel()
        self.alerts_built = 0  #: alerts built so far (the last one's id)

    def confidence(self, event: AnomalyEvent) -> float:
        """Heuristic confidence in [0, 1] (docs/detector.md).

        The product of: the margin over the threshold, 1 - (thr / s)², which is
        0 at the threshold and 0.75 at twice it; the share of valid frames in
        the peak window; and the per-mode factor of `AlertConfig`.
        """
        if not (event.s_px > 0 and math.isfinite(event.s_px)):
            return 0.0
        margin = max(0.0, 1.0 - (event.threshold_px / event.s_px) ** 2)
        mode = self.config.mode_confidence[int(event.mode)]
        return float(min(1.0, max(0.0, margin * event.valid_fraction * mode)))

    def build(self, event: AnomalyEvent) -> Alert | None:
        """The alert for ``event``; None when the event is suppressed."""
        if event.suppressed:
            return None
        d = event.lead_distance_m
        ahead = event.anomaly_distance_m if math.isfinite(event.anomaly_distance_m) else d
        distance = ahead if math.isfinite(ahead) and ahead > 0 else None
        speed = event.ego_speed_mps
        tta = None
        if (
            distance is not None
            and speed is not None
            and speed >= max(self.config.min_speed_mps, 1e-9)
        ):
            tta = max(distance - self.config.camera_to_front_axle_m, 0.0) / speed
        if math.isfinite(event.height_m):
            height: float | None = event.height_m
        else:
            height = self.signal.height_m(event.s_px, d)
        confidence = event.confidence
        if not math.isfinite(confidence):
            confidence = self.confidence(event)
        self.alerts_built += 1
        return Alert(
            t_s=event.t_s,
            t_emit_s=event.t_emit_s,
            distance_m=distance,
            time_to_arrival_s=tta,
            severity_px=event.score if math.isfinite(event.score) else event.s_px,
            height_mm=None if height is None else 1000.0 * height,
            side=event.side,
            confidence=float(min(1.0, max(0.0, confidence))),
            mode=event.mode,
            alert_id=self.alerts_built,
            height_std_mm=_mm(event.height_std_m),
            length_m=event.length_m if math.isfinite(event.length_m) else None,
            lead_speed_mps=event.lead_speed_mps if math.isfinite(event.lead_speed_mps) else None,
        )

    def build_all(self, events: Iterable[AnomalyEvent]) -> list[Alert]:
        """Alerts for the events that are not suppressed, in order."""
        alerts = []
        for e in events:
            a = self.build(e)
            if a is not None:
                alerts.append(a)
        return alerts


def _mm(x: float) -> float | None:
    return 1000.0 * x if math.isfinite(x) else None
