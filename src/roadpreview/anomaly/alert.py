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

from roadpreview.anomaly.base import AnomalyEvent
from roadpreview.anomaly.config import AlertConfig, SignalModel
from roadpreview.configtools import check_ranges
from roadpreview.types import Alert


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
