"""Provisional alerts (issue 27): the two-axle detector's early fit at the lead's front axle,
confirmed under the same alert id by the two-axle fit or cancelled when the rear axle does
not match; the alert repeater and a receiver following the states on CAN."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import can
import pytest
from tests.anomaly.test_two_axle import _trajectory

from roadpreview.anomaly import AlertBuilder, AnomalyEvent, EventKind, TwoAxleConfig
from roadpreview.anomaly.two_axle import TwoAxleDetector
from roadpreview.canbus import AlertReceiver, OutputDecoder, OutputEncoders
from roadpreview.canbus.receiver import ReceiverState
from roadpreview.canbus.repetition import (
    AlertEnd,
    AlertRepeater,
    AlertSend,
    EndCause,
    EndReason,
)
from roadpreview.types import AlertState

#: the bump of these tests: pulse start under the front axle, height, duration under a wheel
T0, HEIGHT, DUR = 20.0, 0.05, 0.2
APEX = T0 + DUR / 2


def _events(cfg: TwoAxleConfig | None = None, **kw: object) -> list[AnomalyEvent]:
    det = TwoAxleDetector(cfg)
    out: list[AnomalyEvent] = []
    for s in _trajectory(**kw):  # type: ignore[arg-type]
        out += det.push(s)
    return out + det.flush()


def test_a_bump_is_alerted_provisionally_at_the_front_axle_then_confirmed_under_its_id() -> None:
    events = _events(events=[(T0, HEIGHT, DUR, "both")])
    prov = [e for e in events if e.kind is EventKind.PROVISIONAL and not e.suppressed]
    conf = [e for e in events if e.kind is EventKind.CONFIRMED and not e.suppressed]
    assert len(prov) == 1
    assert len(conf) == 1
    p, c = prov[0], conf[0]
    # the early fit ends provisional_lag_s (0.2 s) after the apex: sent at most a frame later
    assert p.t_emit_s - APEX <= 0.2 + 1 / 30 + 1e-6
    # the two-axle fit waits for the rear axle (τ = 0.27 s at 10 m/s) and post_s after it
    cfg = TwoAxleConfig()
    assert c.t_emit_s - APEX > cfg.vehicle.wheelbase_m / 10.0 + cfg.post_s
    assert c.ref == p.ref
    assert abs(p.t_s - APEX) <= 0.15  # the crossing within a few frames
    assert p.height_m > 0.0
    assert c.height_m == pytest.approx(HEIGHT, rel=0.3)
    assert not [e for e in events if e.kind is EventKind.CANCELLED]
    # as alerts: one id, provisional then confirmed, the confirmation remembering when the
    # first RP_ALERT went out
    builder = AlertBuilder()
    first = builder.take([p])
    second = builder.take([c])
    assert first.provisional
    assert not first.confirmed
    (a_p,), (a_c,) = first.provisional, second.confirmed
    assert a_p.state is AlertState.PROVISIONAL
    assert a_c.state is AlertState.CONFIRMED
    assert a_c.alert_id == a_p.alert_id
    assert a_c.t_first_sent_s == pytest.approx(p.t_emit_s)
    assert first.new_ids + second.new_ids == 1


def test_provisional_triggers_the_rear_axle_does_not_confirm_are_cancelled_in_time() -> None:
    """A rough road without an anomaly and a provisional threshold far too low: every
    provisional event is cancelled, none confirmed, each within the time the two-axle fit
    needs to have seen its crossing (lag + the longest duration's half + post + check +
    the peak window)."""
    cfg = TwoAxleConfig(provisional_threshold_z=1.5)
    events = _events(cfg, rough_mm=3.0, duration_s=60.0)
    prov = {e.ref: e for e in events if e.kind is EventKind.PROVISIONAL and not e.suppressed}
    cancelled = [e for e in events if e.kind is EventKind.CANCELLED]
    assert len(prov) >= 3  # the low threshold does trigger
    assert not [e for e in events if e.kind is EventKind.CONFIRMED and not e.suppressed]
    assert {e.ref for e in cancelled} == set(prov)
    tau = cfg.vehicle.wheelbase_m / 10.0
    limit = tau + max(cfg.durations_s) / 2 + cfg.post_s + cfg.provisional_check_s
    for e in cancelled:
        assert 0.0 < e.t_emit_s - e.t_s <= limit + cfg.peak_window_s + 0.1
    builder = AlertBuilder()
    batch = builder.take(sorted(events, key=lambda e: e.t_emit_s))
    # (take() of the whole run: the provisional alerts and then their cancellations)
    assert len(batch.cancelled) == len(prov)


def test_without_the_provisional_stage_the_confirmed_events_are_the_same() -> None:
    """The provisional stage only adds: the two-axle fit's events are unchanged."""
    kw = {"events": [(T0, HEIGHT, DUR, "both"), (32.0, -0.04, 0.03, "left")], "rough_mm": 1.0}
    with_p = [e for e in _events(None, **kw) if e.kind is EventKind.CONFIRMED]
    without = _events(TwoAxleConfig(provisional=False), **kw)
    assert [replace(e, ref=0) for e in with_p] == without


def _send_all(
    rep: AlertRepeater, enc: OutputEncoders, items: Sequence[AlertSend | AlertEnd]
) -> list[can.Message]:
    frames: list[can.Message] = []
    for item in items:
        if isinstance(item, AlertEnd):
            frames.append(enc.end.encode(item))
        else:
            frames += enc.alert_frames(item)
    return frames


def test_a_receiver_follows_provisional_confirmed_passed_and_provisional_cancelled() -> None:
    """Two provisional alerts on CAN through the repeater: the first is confirmed (the same
    CAN id, RP_ALERT_DETAIL's state flips) and passed, the second cancelled NOT_CONFIRMED."""
    events = _events(events=[(T0, HEIGHT, DUR, "both")])
    p = next(e for e in events if e.kind is EventKind.PROVISIONAL)
    c = next(e for e in events if e.kind is EventKind.CONFIRMED)
    false = replace(p, t_s=p.t_s + 5.0, t_emit_s=p.t_emit_s + 5.0, ref=p.ref + 1)
    cancel = replace(false, t_emit_s=false.t_emit_s + 1.2, kind=EventKind.CANCELLED)
    builder = AlertBuilder()
    rep = AlertRepeater()
    enc = OutputEncoders()
    dec = OutputDecoder()
    rx = AlertReceiver()
    due = sorted([p, c, false, cancel], key=lambda e: e.t_emit_s)
    frames = []
    for k in range(300, 1200):  # 10 .. 40 s at 30 fps
        t = k / 30
        now = [e for e in due if e.t_emit_s <= t + 1e-9]
        due = due[len(now) :]
        batch = builder.take(now)
        sends = rep.frame(t, 10.0, (*batch.provisional, *batch.confirmed), batch.cancelled)
        frames += _send_all(rep, enc, sends)
    for f in frames:
        rx.push(dec.decode(f))
    ids = sorted({tr.alert_id for tr in rx.transitions})
    assert len(ids) == 2
    first = [tr.after for tr in rx.transitions if tr.alert_id == ids[0]]
    second = [tr.after for tr in rx.transitions if tr.alert_id == ids[1]]
    assert first == [ReceiverState.PROVISIONAL, ReceiverState.CONFIRMED, ReceiverState.ENDED]
    assert second == [ReceiverState.PROVISIONAL, ReceiverState.ENDED]
    end_1 = [tr.life for tr in rx.transitions if tr.alert_id == ids[0]][-1]
    end_2 = [tr.life for tr in rx.transitions if tr.alert_id == ids[1]][-1]
    assert end_1.was_provisional
    assert end_1.reason is EndReason.PASSED
    assert end_2.reason is EndReason.CANCELLED
    assert end_2.cause is EndCause.NOT_CONFIRMED
    assert not rx.problems
