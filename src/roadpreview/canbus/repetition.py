"""Which alert frames go out when: repetition of each active alert until the ego has passed
its spot, then its end (``RP_ALERT`` / ``RP_ALERT_DETAIL``, ``RP_ALERT_END``).

`AlertRepeater` is pushed one camera frame at a time (its time and the ego's speed) with
the alerts the frame raised, and says what to send: an `AlertSend` (the alert as of
that frame) or an `AlertEnd`. No frames, no clocks: the CAN sinks encode what it says.

The ego's odometry s(t) is its speed integrated over the frames (trapezoids). An alert
says the anomaly was ``distance_m`` ahead of the camera when the lead crossed it (at
``t_s``); as of a frame at t the ego's front axle is

    r(t) = distance_m - camera_to_front_axle_m - (s(t) - s(t_s))

before it, and reaches it after TTA(t) = r(t) / v(t) at the current speed v(t) (none
below ``min_speed_mps``). Each active alert is sent at once, then every ``period_s``
on the frames' clock. It ends PASSED when the rear axle has left the anomaly,
r <= -(wheelbase + length / 2 + ``pass_margin_m``), and CANCELLED when it is not passed
within ``max_age_s`` of the crossing (TIMEOUT: the ego stands, creeps, or its speed is
unknown), when more than ``max_active`` alerts are active (OVERFLOW, the oldest goes)
or when the sender stops (STOPPED, `close`). The end goes out ``end_repeats`` times at
the period. The 8-bit CAN id of an alert is its sequence number modulo 256, or the next
free one: an id is not reused while its alert is active, its end is being repeated or
its ``RP_CONFIRM`` is pending (at most ``hold_s`` after its end).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum

from roadpreview.types import Alert

#: 8-bit alert ids on CAN
CAN_ID_MODULUS = 256
#: a frame this much before a send is due still sends (frame stamps carry float rounding)
_EARLY_S = 1e-3


class EndReason(IntEnum):
    """Why an alert ended; the integer goes on CAN (``RP_ALERT_END.EndReason``)."""

    PASSED = 0  #: the ego's rear axle has passed the anomaly
    CANCELLED = 1  #: roadpreview stopped tracking it before (`EndCause`)


class EndCause(IntEnum):
    """Why an alert was cancelled; the integer goes on CAN (``RP_ALERT_END.EndCause``)."""

    NONE = 0  #: not cancelled (PASSED)
    STOPPED = 1  #: the sender stops (end of input, shutdown)
    TIMEOUT = 2  #: not passed within ``max_age_s`` of the crossing
    OVERFLOW = 3  #: too many active alerts: the oldest was dropped
    #: a PROVISIONAL alert whose rear axle did not match (the two-axle fit did not confirm
    #: it). ``RP_ALERT_END.EndCause`` has 2 bits: it carries NONE for this cause and the
    #: full cause goes in ``EndCauseEx`` (DBC version 2)
    NOT_CONFIRMED = 4


@dataclass(frozen=True)
class RepetitionConfig:
    """How alerts are repeated and ended (module docstring). The CAN sinks build it from
    the pipeline's configuration (`roadpreview.sinks.can.repetition_config`)."""

    period_s: float = 0.1  #: repetition period (``[can] alert_repeat_period_s``), s
    #: the ego's front axle ahead of the camera (``[anomaly.alert]``), m
    camera_to_front_axle_m: float = 0.2
    wheelbase_m: float = 2.7  #: the ego's wheelbase (``[anomaly.confirm]``), m
    #: beyond the rear axle and the anomaly's far end: odometry and length errors, m
    pass_margin_m: float = 0.5
    #: slower: no time to arrival (``[anomaly.alert] min_speed_mps``), m/s
    min_speed_mps: float = 0.5
    #: not passed this long after the crossing: cancelled (``[anomaly.confirm] max_wait_s``), s
    max_age_s: float = 15.0
    end_repeats: int = 3  #: RP_ALERT_END frames per alert (one lost end is no stuck alert)
    max_active: int = 32  #: alerts repeated at once (bus load: 2 frames per alert per period)
    hold_s: float = 30.0  #: an ended alert's id waits at most this long for its RP_CONFIRM, s

    def __post_init__(self) -> None:
        if not (math.isfinite(self.period_s) and self.period_s > 0):
            raise ValueError(f"RepetitionConfig.period_s = {self.period_s}: must be > 0")
        if not 1 <= self.max_active < CAN_ID_MODULUS:
            raise ValueError(f"RepetitionConfig.max_active = {self.max_active}: 1..255")
        if self.end_repeats < 1:
            raise ValueError(f"RepetitionConfig.end_repeats = {self.end_repeats}: at least 1")


@dataclass(frozen=True, slots=True)
class AlertSend:
    """Send the alert (``RP_ALERT`` + ``RP_ALERT_DETAIL``) as of ``t_s``."""

    alert: Alert
    can_id: int  #: its 8-bit id on CAN
    t_s: float  #: the frame's time
    #: the ego's front axle to the anomaly, signed (negative: passed); None: unknown, m
    distance_m: float | None
    time_to_arrival_s: float | None  #: distance / speed; None: unknown or standstill, s
    age_s: float  #: since the lead crossed the anomaly, s
    count: int  #: RP_ALERT frames for this alert so far, this one included

    @classmethod
    def at_emission(cls, alert: Alert, config: RepetitionConfig | None = None) -> AlertSend:
        """The alert's first send at its emission, from its own fields alone (no odometry):
        the ego drove at constant speed since the crossing, so the front axle has covered
        the share age / TTA of its way. Without a time to arrival (no speed, standstill)
        the distance is the one at the crossing."""
        cfg = config or RepetitionConfig()
        age = alert.t_emit_s - alert.t_s
        tta, distance = alert.time_to_arrival_s, alert.distance_m
        remaining: float | None = None
        if distance is not None and math.isfinite(distance):
            remaining = distance - cfg.camera_to_front_axle_m
            if tta is not None and tta > 0:
                remaining *= 1.0 - age / tta
        left = None if tta is None else tta - age
        can_id = alert.alert_id % CAN_ID_MODULUS
        return cls(alert, can_id, alert.t_emit_s, remaining, left, age, count=1)


@dataclass(frozen=True, slots=True)
class AlertEnd:
    """Send the alert's ``RP_ALERT_END`` (one of its ``end_repeats``)."""

    alert: Alert
    can_id: int
    t_s: float
    reason: EndReason
    cause: EndCause
    sends: int  #: RP_ALERT frames that were sent for it
    distance_m: float | None  #: as `AlertSend.distance_m`, at the end


@dataclass
class _Active:
    alert: Alert
    can_id: int
    next_t: float
    remaining_m: float  #: front axle to the anomaly as of the last frame (NaN: unknown)
    sends: int = 0
    confirmed: bool = False  #: its RP_CONFIRM went out already
    ended: tuple[EndReason, EndCause] | None = None
    ends_left: int = 0
    t_end: float = math.nan


@dataclass
class _Odometry:
    """s(t): the ego's distance driven, sampled at the frames, over the last ``keep_s``."""

    keep_s: float
    t: list[float] = field(default_factory=list)
    s: list[float] = field(default_factory=list)
    v: float = math.nan  #: speed at the last frame (NaN: unknown)
    unknown_since: float = -math.inf  #: end of the last interval with an unknown speed

    def push(self, t: float, speed: float | None) -> float:
        """One frame; returns the distance driven since the previous one (NaN: unknown)."""
        v = math.nan if speed is None or not math.isfinite(speed) else max(float(speed), 0.0)
        if not self.t:
            self.t.append(t)
            self.s.append(0.0)
            self.v = v
            return 0.0
        if t <= self.t[-1]:  # the same instant again (the flush at the end): no time passed
            return 0.0
        step = 0.5 * (v + self.v) * (t - self.t[-1])
        if not math.isfinite(step):
            self.unknown_since = t
        self.t.append(t)
        self.s.append(self.s[-1] + (step if math.isfinite(step) else 0.0))
        self.v = v
        cut = min(bisect.bisect_left(self.t, t - self.keep_s), len(self.t) - 2)
        if cut > 0:
            del self.t[:cut], self.s[:cut]
        return step

    def since(self, t0: float) -> float:
        """Distance driven from ``t0`` to the last frame; before the history, at the speed
        of its first frame (NaN: the speed was unknown in between)."""
        if not self.t or t0 < self.unknown_since:
            return math.nan
        now = self.s[-1]
        if t0 >= self.t[-1]:
            return 0.0
        k = bisect.bisect_right(self.t, t0)
        if k == 0:  # before the history
            v0 = self.v if len(self.t) == 1 else (self.s[1] - self.s[0]) / (self.t[1] - self.t[0])
            return now - self.s[0] + v0 * (self.t[0] - t0)
        t_a, t_b = self.t[k - 1], self.t[k]
        s_at = self.s[k - 1] + (self.s[k] - self.s[k - 1]) * (t0 - t_a) / (t_b - t_a)
        return now - s_at


class AlertRepeater:
    """Active alerts in, what to send at each frame out (module docstring)."""

    def __init__(self, config: RepetitionConfig | None = None) -> None:
        self.config = config or RepetitionConfig()
        self._odo = _Odometry(keep_s=self.config.max_age_s + 1.0)
        self._active: dict[int, _Active] = {}  # by alert_id, in the order they came
        self._held: dict[int, tuple[int, float]] = {}  # alert_id -> (can id, ended at)
        self.t = -math.inf  #: the last frame's time

    @property
    def active(self) -> int:
        """Alerts being repeated (their end not sent yet)."""
        return sum(a.ended is None for a in self._active.values())

    def can_id(self, alert_id: int) -> int:
        """The 8-bit CAN id of ``alert_id`` (its sequence number modulo 256 when it was
        never given another one)."""
        a = self._active.get(alert_id)
        if a is not None:
            return a.can_id
        held = self._held.get(alert_id)
        return held[0] if held is not None else alert_id % CAN_ID_MODULUS

    def release(self, alert_id: int) -> None:
        """The alert's ``RP_CONFIRM`` went out: its id may be used again after its end."""
        self._held.pop(alert_id, None)
        a = self._active.get(alert_id)
        if a is not None:
            a.confirmed = True

    def frame(
        self,
        t_s: float,
        speed_mps: float | None,
        alerts: Sequence[Alert] = (),
        cancelled: Sequence[Alert] = (),
    ) -> list[AlertSend | AlertEnd]:
        """One camera frame: the ego's speed then, the alerts it raised or changed (a
        provisional alert confirmed comes again with its id) and the provisional alerts it
        cancelled (ended CANCELLED, `EndCause.NOT_CONFIRMED`)."""
        step = self._odo.push(t_s, speed_mps)
        self.t = max(self.t, t_s)
        out: list[AlertSend | AlertEnd] = []
        for a in self._active.values():  # (an ended one too: its end frames say where)
            a.remaining_m -= step
        for alert in cancelled:
            out += self.cancel(alert.alert_id, t_s, EndCause.NOT_CONFIRMED)
        for alert in alerts:
            out += self._add(alert, t_s)
        for a in list(self._active.values()):
            out += self._due(a, t_s)
        self._forget(t_s)
        return out

    def cancel(self, alert_id: int, t_s: float, cause: EndCause) -> list[AlertEnd]:
        """End an active alert now as CANCELLED with ``cause`` (a provisional alert the
        two-axle fit did not confirm: `EndCause.NOT_CONFIRMED`); its first end frame goes
        out at once. Unknown or already ended ids: nothing."""
        a = self._active.get(alert_id)
        if a is None or a.ended is not None:
            return []
        self._end(a, t_s, EndReason.CANCELLED, cause)
        return [self._end_frame(a, t_s)]

    def close(self, t_s: float | None = None) -> list[AlertEnd]:
        """The sender stops: every active alert is cancelled (STOPPED) and every end not
        yet repeated ``end_repeats`` times goes out now."""
        t = self.t if t_s is None else t_s
        out: list[AlertEnd] = []
        for a in list(self._active.values()):
            if a.ended is None:
                self._end(a, t, EndReason.CANCELLED, EndCause.STOPPED)
            while a.ends_left > 0:
                out.append(self._end_frame(a, t))
        self._forget(t)
        return out

    # -- inside -----------------------------------------------------------------------------

    def _add(self, alert: Alert, t: float) -> list[AlertSend | AlertEnd]:
        cfg = self.config
        out: list[AlertSend | AlertEnd] = []
        known = self._active.get(alert.alert_id)
        if known is not None:
            if known.ended is None and alert.state != known.alert.state:
                # a provisional alert confirmed: the refined alert replaces it under the same
                # id, sent at once (the receiver learns the state change without waiting a
                # period); where the ego is stays what the odometry says
                known.alert = alert
                if math.isfinite(known.remaining_m) and alert.distance_m is not None:
                    known.remaining_m = (
                        alert.distance_m
                        - cfg.camera_to_front_axle_m
                        - self._odo.since(alert.t_s)
                    )
                known.next_t = t
            return out  # the same alert again: already repeated
        if self.active >= cfg.max_active:
            oldest = next(a for a in self._active.values() if a.ended is None)
            self._end(oldest, t, EndReason.CANCELLED, EndCause.OVERFLOW)
            out.append(self._end_frame(oldest, t))
        remaining = math.nan
        if alert.distance_m is not None and math.isfinite(alert.distance_m):
            remaining = alert.distance_m - cfg.camera_to_front_axle_m - self._odo.since(alert.t_s)
        entry = _Active(alert, self._free_id(alert.alert_id), next_t=t, remaining_m=remaining)
        self._active[alert.alert_id] = entry
        return out

    def _free_id(self, alert_id: int) -> int:
        used = {a.can_id for a in self._active.values()} | {c for c, _ in self._held.values()}
        for k in range(CAN_ID_MODULUS):
            cand = (alert_id + k) % CAN_ID_MODULUS
            if cand not in used:
                return cand
        raise RuntimeError("no free 8-bit alert id")  # max_active < 256 and holds expire

    def _due(self, a: _Active, t: float) -> list[AlertSend | AlertEnd]:
        cfg = self.config
        if a.ended is None:
            age = t - a.alert.t_s
            if math.isfinite(a.remaining_m) and a.remaining_m <= -self._pass_at(a.alert):
                self._end(a, t, EndReason.PASSED, EndCause.NONE)
            elif age > cfg.max_age_s:
                self._end(a, t, EndReason.CANCELLED, EndCause.TIMEOUT)
        if t < a.next_t - _EARLY_S:
            return []
        # the next send: one period on, or one period from now after a gap in the frames
        a.next_t = a.next_t + cfg.period_s if t < a.next_t + cfg.period_s else t + cfg.period_s
        if a.ended is not None:
            return [self._end_frame(a, t)] if a.ends_left > 0 else []
        a.sends += 1
        return [
            AlertSend(
                alert=a.alert,
                can_id=a.can_id,
                t_s=t,
                distance_m=_finite(a.remaining_m),
                time_to_arrival_s=self._tta(a.remaining_m),
                age_s=t - a.alert.t_s,
                count=a.sends,
            )
        ]

    def _pass_at(self, alert: Alert) -> float:
        """How far beyond the anomaly the front axle is when the rear axle has left it."""
        half = 0.5 * alert.length_m if alert.length_m is not None else 0.0
        return self.config.wheelbase_m + max(half, 0.0) + self.config.pass_margin_m

    def _tta(self, remaining_m: float) -> float | None:
        v = self._odo.v
        if not (math.isfinite(remaining_m) and math.isfinite(v)) or v < self.config.min_speed_mps:
            return None
        return remaining_m / v

    def _end(self, a: _Active, t: float, reason: EndReason, cause: EndCause) -> None:
        a.ended = (reason, cause)
        a.ends_left = self.config.end_repeats
        a.t_end = t
        a.next_t = t  # the first end goes out at once

    def _end_frame(self, a: _Active, t: float) -> AlertEnd:
        assert a.ended is not None
        a.ends_left -= 1
        a.next_t = t + self.config.period_s
        return AlertEnd(
            alert=a.alert,
            can_id=a.can_id,
            t_s=t,
            reason=a.ended[0],
            cause=a.ended[1],
            sends=a.sends,
            distance_m=_finite(a.remaining_m),
        )

    def _forget(self, t: float) -> None:
        """Ended alerts whose ends are all out leave the table; their ids wait for their
        RP_CONFIRM (at most ``hold_s``)."""
        for alert_id, a in list(self._active.items()):
            if a.ended is not None and a.ends_left == 0:
                del self._active[alert_id]
                if not a.confirmed:
                    self._held[alert_id] = (a.can_id, a.t_end)
        for alert_id, (_, t_end) in list(self._held.items()):
            if t - t_end > self.config.hold_s:
                del self._held[alert_id]


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


__all__ = [
    "AlertEnd",
    "AlertRepeater",
    "AlertSend",
    "EndCause",
    "EndReason",
    "RepetitionConfig",
]
