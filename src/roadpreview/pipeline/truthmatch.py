"""Match a run's alerts to a simulator recording's true events (replay ``--truth``).

An alert matches a true event when the lead crossed the anomaly (front axle
over the apex) between ``before_s`` before and ``after_s`` after the alert's
crossing time. Events the lead hits within ``max_distance_m`` are the ones
that should be detected; an alert that matches no event at all (hit or not)
is a false alarm. Timing per hit (issue 27): the latency of the first ``RP_ALERT``
(the provisional one, if any) and of the confirmation after the lead's front axle crossed;
the lead time, when the ego reaches the anomaly minus the first ``RP_ALERT``; the time
headway, when the ego reaches it minus when the lead did.

Provisional alerts are matched the same way, separately (`match_provisional`): a
provisional alert that matches no event is a provisional false alarm, and it was cancelled
in time when its ``RP_ALERT_END`` (CANCELLED) went out before the ego would have reached
the spot it named.
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
    #: ego arrival minus the first RP_ALERT of the alert (NaN: no alert or no arrival)
    lead_time_s: float
    #: the alert's crossing time minus the lead's true crossing, s (NaN: no alert)
    crossing_error_s: float = math.nan
    #: the ego's true arrival minus the alert's crossing time, s (NaN: no alert or arrival)
    tta_true_s: float = math.nan
    #: the alert's predicted time to arrival minus ``tta_true_s``, s (NaN: either unknown)
    tta_error_s: float = math.nan
    #: the first RP_ALERT (provisional or confirmed) after the lead's front axle crossed, s
    latency_s: float = math.nan
    #: the confirmation (the two-axle fit's alert) after the lead's front axle crossed, s
    latency_confirmed_s: float = math.nan
    #: the ego's front axle at the anomaly after the lead's (NaN: the ego does not get there)
    headway_s: float = math.nan

    @property
    def outcome(self) -> str:
        if self.alert is not None:
            return "hit"
        return "miss" if self.expected else "-"


@dataclass(frozen=True)
class ProvisionalTally:
    """Provisional alerts against the truth (`match_provisional`)."""

    alerts: int  #: provisional alerts raised
    hits: int  #: ... that match an event the lead crosses
    false_alarms: int  #: ... that match no event
    cancelled_in_time: int  #: false alarms CANCELLED before the ego would reach the spot
    confirmed: int  #: provisional alerts the two-axle fit confirmed
    duration_s: float

    @property
    def false_alarms_per_min(self) -> float:
        return self.false_alarms / (self.duration_s / 60.0) if self.duration_s else math.nan

    @property
    def cancelled_share(self) -> float:
        """Share of the provisional false alarms cancelled in time (NaN: none)."""
        return self.cancelled_in_time / self.false_alarms if self.false_alarms else math.nan


@dataclass(frozen=True)
class MatchReport:
    rows: list[MatchRow]
    false_alarms: list[Alert]
    duration_s: float
    #: the recording's time zero on the alerts' clock (for printing)
    t0: float = 0.0
    provisional: ProvisionalTally | None = None  #: the provisional alerts (None: not given)

    def latencies(self) -> list[float]:
        """Latency of the first RP_ALERT of every hit, s."""
        return [r.latency_s for r in self.rows if r.expected and r.alert is not None]

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
            "event  kind      size    side   lead crosses  distance  headway  outcome"
            "  latency first / confirmed  lead time  severity",
        ]
        for r in self.rows:
            a = r.alert
            sev = f"{a.severity_px:5.2f} px" if a else ""
            lt = _s(r.lead_time_s)
            lat = f"{_s(r.latency_s)} / {_s(r.latency_confirmed_s)}" if a else " " * 19
            lines.append(
                f"{r.event_index:5d}  {r.kind:8s} {r.height_mm:+5.0f} mm  {r.lead_side:5s}  "
                f"{r.t_lead_s:9.2f} s  {r.distance_m:6.1f} m  {_s(r.headway_s)}  {r.outcome:7s}"
                f"  {lat:>25s}  {lt}  {sev}"
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
        firsts = [x for x in self.latencies() if math.isfinite(x)]
        if firsts:
            early = sum(x <= FIRST_ALERT_LATENCY_S for x in firsts)
            median = sorted(firsts)[len(firsts) // 2]
            lines.append(
                f"first RP_ALERT within {FIRST_ALERT_LATENCY_S:.1f} s of the lead's front axle:"
                f" {early}/{len(firsts)} hits (latency median {median:.2f} s)"
            )
        p = self.provisional
        if p is not None:
            lines.append(
                f"provisional alerts: {p.alerts} ({p.confirmed} confirmed), {p.hits} on an"
                f" anomaly, {p.false_alarms} false ({p.false_alarms_per_min:.2f}/min),"
                f" {p.cancelled_in_time} of them cancelled before the ego got there"
            )
        return "\n".join(lines)


#: the issue's latency target for the first RP_ALERT after the lead's front axle, s
FIRST_ALERT_LATENCY_S = 0.3


def _s(x: float) -> str:
    return f"{x:5.2f} s" if math.isfinite(x) else "      -"


def match_alerts(
    alerts: Sequence[Alert],
    events: Sequence[dict[str, Any]],
    *,
    t0: float,
    duration_s: float,
    max_distance_m: float = 25.0,
    before_s: float = 0.6,
    after_s: float = 1.2,
    provisional: Sequence[Alert] | None = None,
    cancelled: Sequence[Alert] | None = None,
) -> MatchReport:
    """Match alerts (times on the log clock) to truth events (times from ``t0``); with
    ``provisional`` (and the ``cancelled`` ones), their tally too (`match_provisional`)."""
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
        latency = latency_confirmed = headway = math.nan
        t_ego_rel = e.get("ego_front_t_s")
        if t_ego_rel is not None:
            headway = float(t_ego_rel) - float(t_lead)
        if best is not None:
            used.add(best)
            alert = alerts[best]
            crossing_error = alert.t_s - t_abs
            latency = alert.t_first_sent_s - t_abs
            latency_confirmed = alert.t_emit_s - t_abs
            t_ego = e.get("ego_front_t_s")
            if t_ego is not None:
                lead_time = t0 + float(t_ego) - alert.t_first_sent_s
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
                latency_s=latency,
                latency_confirmed_s=latency_confirmed,
                headway_s=headway,
            )
        )
    false_alarms = [a for i, a in enumerate(alerts) if i not in used]
    tally = None
    if provisional is not None:
        tally = match_provisional(
            provisional,
            cancelled or (),
            alerts,
            events,
            t0=t0,
            duration_s=duration_s,
            max_distance_m=max_distance_m,
            before_s=before_s,
            after_s=after_s,
        )
    return MatchReport(
        rows=rows, false_alarms=false_alarms, duration_s=duration_s, t0=t0, provisional=tally
    )


def match_provisional(
    provisional: Sequence[Alert],
    cancelled: Sequence[Alert],
    confirmed: Sequence[Alert],
    events: Sequence[dict[str, Any]],
    *,
    t0: float,
    duration_s: float,
    max_distance_m: float = 25.0,
    before_s: float = 0.6,
    after_s: float = 1.2,
) -> ProvisionalTally:
    """The provisional alerts against the truth (as `match_alerts`): hits, false alarms,
    and the false alarms whose cancellation went out before the ego would have reached the
    spot they named (their crossing plus their time to arrival; without one, never)."""
    rep = match_alerts(
        provisional,
        events,
        t0=t0,
        duration_s=duration_s,
        max_distance_m=max_distance_m,
        before_s=before_s,
        after_s=after_s,
    )
    ended = {a.alert_id: a.t_emit_s for a in cancelled}
    in_time = 0
    for a in rep.false_alarms:
        arrive = a.arrival_t_s
        if a.alert_id in ended and arrive is not None and ended[a.alert_id] <= arrive:
            in_time += 1
    ids = {a.alert_id for a in confirmed}
    return ProvisionalTally(
        alerts=len(provisional),
        hits=sum(r.alert is not None for r in rep.rows),
        false_alarms=len(rep.false_alarms),
        cancelled_in_time=in_time,
        confirmed=sum(a.alert_id in ids for a in provisional),
        duration_s=duration_s,
    )
