"""Alerts: what the predictive suspension is told about a detected anomaly.

`AlertBuilder` turns an `AnomalyEvent` into an `Alert`: where the anomaly is
(the lead's distance when it crossed it), when the ego gets there (distance
/ ego speed from CAN), how strong it is (s in px and a height estimate from
the paper's s = α f δ / d + β), which side, how confident we are, and the
fusion mode. Suppressed events give no alert (``build`` returns None).

Provisional events (`EventKind.PROVISIONAL`) give a PROVISIONAL alert with a new id; the
two-axle event that confirms one (its ``ref``) gives the CONFIRMED alert under the same id,
with ``t_first_s`` the provisional one's emission; a cancellation (`EventKind.CANCELLED`)
gives back, through `cancel`, the provisional alert it ends.
``roadpreview.canbus`` puts alerts on the bus (message ``RP_ALERT``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

from roadpreview.anomaly.base import AnomalyEvent, EventKind
from roadpreview.anomaly.config import AlertConfig, SignalModel
from roadpreview.configtools import check_ranges
from roadpreview.types import Alert, AlertState


@dataclass(frozen=True)
class AlertBatch:
    """A frame's alerts by kind."""

    #: CONFIRMED alerts: new ones, and provisional ones confirmed (their id again)
    confirmed: tuple[Alert, ...] = ()
    provisional: tuple[Alert, ...] = ()  #: PROVISIONAL alerts raised
    cancelled: tuple[Alert, ...] = ()  #: provisional alerts the two-axle fit did not confirm

    @property
    def new_ids(self) -> int:
        """Alert ids this batch raised (a confirmation keeps its provisional one's id)."""
        return len(self.provisional) + sum(not math.isfinite(a.t_first_s) for a in self.confirmed)


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
        self._provisional: dict[int, Alert] = {}  # by event ref: waiting for confirmation

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
        """The alert for ``event``; None when the event is suppressed or a cancellation
        (`cancel`)."""
        if event.suppressed or event.kind is EventKind.CANCELLED:
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
        earlier = self._provisional.pop(event.ref, None) if event.ref else None
        if earlier is None:
            self.alerts_built += 1
            alert_id, t_first = self.alerts_built, math.nan
        else:
            alert_id, t_first = earlier.alert_id, earlier.t_emit_s
        provisional = event.kind is EventKind.PROVISIONAL
        alert = Alert(
            t_s=event.t_s,
            t_emit_s=event.t_emit_s,
            distance_m=distance,
            time_to_arrival_s=tta,
            severity_px=event.score if math.isfinite(event.score) else event.s_px,
            height_mm=None if height is None else 1000.0 * height,
            side=event.side,
            confidence=float(min(1.0, max(0.0, confidence))),
            mode=event.mode,
            alert_id=alert_id,
            height_std_mm=_mm(event.height_std_m),
            length_m=event.length_m if math.isfinite(event.length_m) else None,
            lead_speed_mps=event.lead_speed_mps if math.isfinite(event.lead_speed_mps) else None,
            state=AlertState.PROVISIONAL if provisional else AlertState.CONFIRMED,
            t_first_s=t_first,
        )
        if provisional:
            self._provisional[event.ref] = alert
        return alert

    def cancel(self, event: AnomalyEvent) -> Alert | None:
        """The provisional alert a cancellation ends (its emission time the cancellation's);
        None when there is none (it was suppressed, or ``event`` is no cancellation)."""
        if event.kind is not EventKind.CANCELLED:
            return None
        alert = self._provisional.pop(event.ref, None)
        return None if alert is None else replace(alert, t_emit_s=event.t_emit_s)

    def take(self, events: Iterable[AnomalyEvent]) -> AlertBatch:
        """The alerts of a frame's events, by kind (`AlertBatch`)."""
        confirmed: list[Alert] = []
        provisional: list[Alert] = []
        cancelled: list[Alert] = []
        for e in events:
            if e.kind is EventKind.CANCELLED:
                c = self.cancel(e)
                if c is not None:
                    cancelled.append(c)
                continue
            a = self.build(e)
            if a is not None:
                (provisional if a.state is AlertState.PROVISIONAL else confirmed).append(a)
        return AlertBatch(tuple(confirmed), tuple(provisional), tuple(cancelled))

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
