"""Match a run's alerts to a simulator recording's true events (replay ``--truth``).

An alert matches a true event when the lead crossed the anomaly (front axle
over the apex) between ``before_s`` before and ``after_s`` after the alert's
crossing time. Events the lead hits within ``max_distance_m`` are the ones
that should be detected; an alert that matches no event at all (hit or not)
is a false alarm. Lead time = when the ego reaches the anomaly minus when the
alert was emitted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from roadpreview.types import Alert


@dataclass(frozen=True)
class MatchRow:
    event_index: int
    kind: str
    height_mm: float
    lead_side: str
    t_lead_s: float
    distance_m: float
    expected: bool  #: the lead hits it within range: it should be detected
    alert: Alert | None
    lead_time_s: float  #: ego arrival minus alert emission (NaN: no alert or no arrival)
    #: the alert's crossing time minus the lead's true crossing, s (NaN: no alert)
    crossing_error_s: float = math.nan
    #: the ego's true arrival minus the alert's crossing time, s (NaN: no alert or arrival)
    tta_true_s: float = math.nan
    #: the alert's predicted time to arrival minus ``tta_true_s``, s (NaN: either unknown)
    tta_error_s: float = math.nan

    @property
    def outcome(self) -> str:
        if self.alert is not None:
            return "hit"
        return "miss" if self.expected else "-"


@dataclass(frozen=True)
class MatchReport:
    rows: list[MatchRow]
    false_alarms: list[Alert]
    duration_s: float
    #: the recording's time zero on the alerts' clock (for printing)
    t0: float = 0.0

    @property
    def expected(self) -> int:
        return sum(r.expected for r in self.rows)

    @property
    def hits(self) -> int:
        return sum(r.expected and r.alert is not None for r in self.rows)

    @property
    def recall(self) -> float:
        return self.hits / self.expected if self.expected else math.nan

    @property
    def false_alarms_per_min(self) -> float:
        return len(self.false_alarms) / (self.duration_s / 60.0) if self.duration_s else math.nan

    def table(self) -> str:
        lines = [
            "event  kind      size    side   lead crosses  distance  outcome  lead time  severity",
        ]
        for r in self.rows:
            a = r.alert
            sev = f"{a.severity_px:5.2f} px" if a else ""
            lt = f"{r.lead_time_s:6.2f} s" if math.isfinite(r.lead_time_s) else "      -"
            lines.append(
                f"{r.event_index:5d}  {r.kind:8s} {r.height_mm:+5.0f} mm  {r.lead_side:5s}  "
                f"{r.t_lead_s:9.2f} s  {r.distance_m:6.1f} m  {r.outcome:7s}  {lt}  {sev}"
            )
        for a in self.false_alarms:
            lines.append(
                f"    -  false alarm at {a.t_s - self.t0:.2f} s, severity {a.severity_px:.2f} px"
            )
        lines.append(
            f"detected {self.hits}/{self.expected} anomalies the lead crosses within range "
            f"({100 * self.recall:.0f} %), {len(self.false_alarms)} false alarm(s) "
            f"({self.false_alarms_per_min:.2f}/min)"
        )
        return "\n".join(lines)


def match_alerts(
    alerts: Sequence[Alert],
    events: Sequence[dict[str, Any]],
    *,
    t0: float,
    duration_s: float,
    max_distance_m: float = 25.0,
    before_s: float = 0.6,
    after_s: float = 1.2,
) -> MatchReport:
    """Match alerts (times on the log clock) to truth events (times from ``t0``)."""
    used: set[int] = set()
    rows: list[MatchRow] = []
    for e in events:
        t_lead = e.get("lead_front_t_s")
        if t_lead is None:
            continue
        t_abs = t0 + float(t_lead)
        dist = float(e["lead_distance_m"]) if e.get("lead_distance_m") is not None else math.nan
        expected = bool(e["lead_hits"]) and dist <= max_distance_m
        best: int | None = None
        for i, a in enumerate(alerts):  # a handful of alerts per minute
            if i in used or not (t_abs - before_s <= a.t_s <= t_abs + after_s):
                continue
            if best is None or abs(a.t_s - t_abs) < abs(alerts[best].t_s - t_abs):
                best = i
        alert = None
        lead_time = crossing_error = tta_true = tta_error = math.nan
        if best is not None:
            used.add(best)
            alert = alerts[best]
            crossing_error = alert.t_s - t_abs
            t_ego = e.get("ego_front_t_s")
            if t_ego is not None:
                lead_time = t0 + float(t_ego) - alert.t_emit_s
                tta_true = t0 + float(t_ego) - alert.t_s
                if alert.time_to_arrival_s is not None:
                    tta_error = alert.time_to_arrival_s - tta_true
        rows.append(
            MatchRow(
                event_index=int(e["index"]),
                kind=str(e["kind"]),
                height_mm=1000.0 * float(e["height_m"]),
                lead_side=str(e["lead_side"]),
                t_lead_s=float(t_lead),
                distance_m=dist,
                expected=expected,
                alert=alert,
                lead_time_s=lead_time,
                crossing_error_s=crossing_error,
                tta_true_s=tta_true,
                tta_error_s=tta_error,
            )
        )
    false_alarms = [a for i, a in enumerate(alerts) if i not in used]
    return MatchReport(rows=rows, false_alarms=false_alarms, duration_s=duration_s, t0=t0)
