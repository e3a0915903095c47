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
    distance_m: float | None  #: distance ahead of the ego at t_s (the lead's distance), m
    time_to_arrival_s: float | None  #: distance / ego speed, from t_s, s
    severity_px: float  #: peak of s(t), px
    height_mm: float | None  #: estimated anomaly height (α f δ / d model), mm
    side: Side  #: left / right / both / unknown
    confidence: float  #: 0..1, heuristic (docs/detector.md), not a calibrated probability
    mode: FusionMode  #: fusion mode at the crossing

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
        distance = d if math.isfinite(d) and d > 0 else None
        speed = event.ego_speed_mps
        tta = None
        if (
            distance is not None
            and speed is not None
            and speed >= max(self.config.min_speed_mps, 1e-9)
        ):
            tta = distance / speed
        height = self.signal.height_m(event.s_px, d)
        return Alert(
            t_s=event.t_s,
            t_emit_s=event.t_emit_s,
            distance_m=distance,
            time_to_arrival_s=tta,
            severity_px=event.s_px,
            height_mm=None if height is None else 1000.0 * height,
            side=event.side,
            confidence=self.confidence(event),
            mode=event.mode,
        )

    def build_all(self, events: Iterable[AnomalyEvent]) -> list[Alert]:
        """Alerts for the events that are not suppressed, in order."""
        alerts = []
        for e in events:
            a = self.build(e)
            if a is not None:
                alerts.append(a)
        return alerts
