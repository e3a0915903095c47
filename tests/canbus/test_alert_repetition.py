"""Alert repetition and end (`roadpreview.canbus.repetition`, `roadpreview.sinks.can`): a
synthetic stream of alerts at known ego speeds, driven into a `CanMemorySink` as the run
loop drives it, and read back from the frames (CRC and counter checked by `OutputDecoder`,
values by a plain cantools database).

The physics asserted: at constant speed the time to arrival decreases by exactly the time
elapsed between sends (within one LSB, 0.02 s, and the float time stamps), the distance by
speed x elapsed; the end comes when the rear axle has left the anomaly."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import cast

import cantools
import e2e.p01
import numpy as np
import pytest
from cantools.database.can import Database

from roadpreview.canbus.received import (
    OutputDecoder,
    ReceivedAlert,
    ReceivedAlertEnd,
    ReceivedConfirm,
    ReceivedOutput,
)
from roadpreview.canbus.repetition import (
    AlertEnd,
    AlertRepeater,
    AlertSend,
    EndCause,
    EndReason,
    RepetitionConfig,
)
from roadpreview.loop import RunSummary
from roadpreview.pipeline import FrameResult, PipelineConfig
from roadpreview.sinks.can import CanMemorySink, repetition_config
from roadpreview.types import (
    Alert,
    CameraFrame,
    Confirmation,
    ConfirmationResult,
    FusionMode,
    Side,
    Status,
)

REPO_DBC = Path(__file__).resolve().parents[2] / "data" / "roadpreview.dbc"
T0 = 1.7e9  # Unix time, as the replay stamps frames: float stamps carry ~0.2 us rounding
FPS = 30.0
CFG = RepetitionConfig()  # 0.1 s, front axle 0.2 m ahead of the camera, wheelbase 2.7 m
TTA_LSB = 0.02
DIST_LSB = 0.2
STATUS = Status(mode=FusionMode.FUSED)


def _alert(alert_id: int, t_cross: float, t_emit: float, distance_m: float | None) -> Alert:
    return Alert(
        t_s=t_cross,
        t_emit_s=t_emit,
        distance_m=distance_m,
        time_to_arrival_s=None,  # the sink counts from its own odometry
        severity_px=7.0,
        height_mm=55.0,
        side=Side.BOTH,
        confidence=0.9,
        mode=FusionMode.FUSED,
        alert_id=alert_id,
        height_std_mm=6.0,
        length_m=0.6,
        lead_speed_mps=10.0,
    )


def _drive(
    sink: CanMemorySink,
    t_end: float,
    speed: float | None,
    alerts: dict[int, list[Alert]],
    *,
    fps: float = FPS,
    confirmations: dict[int, list[ConfirmationResult]] | None = None,
) -> list[float]:
    """Frames k = 0 .. t_end * fps at ``T0 + k / fps``, the ego at ``speed``; frame k raises
    ``alerts[k]``. Returns the frame times."""
    times = []
    for k in range(round(t_end * fps) + 1):
        t = T0 + k / fps
        result = SimpleNamespace(
            t=t,
            alerts=tuple(alerts.get(k, ())),
            provisional=(),
            cancelled=(),
            preview=None,
            confirmations=tuple((confirmations or {}).get(k, ())),
            ego_speed_mps=speed,
        )
        sink.on_frame(CameraFrame(t, None), cast(FrameResult, result), STATUS)
        times.append(t)
    return times


def _decoded(sink: CanMemorySink) -> list[ReceivedOutput]:
    rx = OutputDecoder()
    got = [rx.decode(m) for m in sink.messages]
    assert rx.problems == {}
    assert rx.lost == 0
    return [g for g in got if g is not None]


def _of(kind: type, got: Sequence[ReceivedOutput]) -> list:  # type: ignore[type-arg]
    return [g for g in got if isinstance(g, kind)]


@pytest.fixture(scope="module")
def plain_db() -> Database:
    db = cantools.database.load_file(REPO_DBC, strict=True)
    assert isinstance(db, Database)
    return db


def test_at_constant_speed_the_time_to_arrival_counts_down_with_the_clock(
    plain_db: Database,
) -> None:
    """10 m/s; the lead crossed the anomaly at 0 s, 40.2 m ahead of the camera (40 m ahead of
    the front axle); the detector confirms it 1.2 s later. The front axle gets there at 4 s."""
    v, d_front = 10.0, 40.0
    sink = CanMemorySink()
    alert = _alert(1, T0 + 0.0, T0 + 1.2, d_front + CFG.camera_to_front_axle_m)
    _drive(sink, 5.0, v, {36: [alert]})  # frame 36 is t = 1.2 s
    got = _decoded(sink)
    sends = _of(ReceivedAlert, got)
    t = np.array([s.t_rx_s for s in sends]) - T0
    tta = np.array([s.time_to_arrival_s for s in sends], dtype=float)
    dist = np.array([s.distance_m for s in sends], dtype=float)
    # every 100 ms on the frames' clock (3 frames at 30 fps), from the emission on
    assert t[0] == pytest.approx(1.2, abs=1e-6)
    np.testing.assert_allclose(np.diff(t), CFG.period_s, atol=1e-6)
    # TTA(t) = (40 m - v t) / v: the arrival t + TTA is the same instant at every send
    np.testing.assert_allclose(t + tta, d_front / v, atol=TTA_LSB / 2 + 1e-6)
    np.testing.assert_allclose(np.diff(tta), -np.diff(t), atol=TTA_LSB + 1e-6)
    np.testing.assert_allclose(dist, d_front - v * t, atol=DIST_LSB / 2 + 1e-6)
    assert tta[0] == pytest.approx(4.0 - 1.2, abs=TTA_LSB / 2)
    assert (tta < 0).any()  # past the front axle the TTA goes negative until the end
    # the end: the rear axle (2.7 m behind) has left the 0.6 m anomaly plus 0.5 m at
    # 40 + 2.7 + 0.3 + 0.5 = 43.5 m, i.e. 4.35 s; the first frame at or after it
    ends = _of(ReceivedAlertEnd, got)
    assert len(ends) == CFG.end_repeats
    t_end = np.array([e.t_rx_s for e in ends]) - T0
    assert 4.35 - 1e-6 <= t_end[0] <= 4.35 + 1 / FPS
    np.testing.assert_allclose(np.diff(t_end), CFG.period_s, atol=1e-6)
    assert all(
        (e.reason, e.cause, e.alert_id) == (EndReason.PASSED, EndCause.NONE, 1) for e in ends
    )
    assert all(e.sends == len(sends) for e in ends)  # the loss check a receiver can make
    assert t[-1] < t_end[0]  # no RP_ALERT of the id after its end
    assert ends[0].distance_m is not None
    assert ends[0].distance_m <= -(CFG.wheelbase_m + 0.3 + CFG.pass_margin_m) + DIST_LSB / 2
    assert sink.repeater.active == 0
    # each RP_ALERT is followed by its RP_ALERT_DETAIL, and a plain cantools reads both
    ids = [m.arbitration_id for m in sink.messages]
    assert ids == [0x200, 0x203] * len(sends) + [0x205] * CFG.end_repeats
    by_id = {m.frame_id: m for m in plain_db.messages}
    for m in sink.messages:
        assert e2e.p01.e2e_p01_check(bytearray(m.data), m.arbitration_id)
    first = cast(dict[str, object], by_id[0x200].decode(bytes(sink.messages[0].data)))
    assert first["AlertLength"] == pytest.approx(0.6)
    assert first["AlertHeight"] == pytest.approx(56.0)  # 55 mm in 2 mm steps
    detail = cast(dict[str, object], by_id[0x203].decode(bytes(sink.messages[1].data)))
    assert detail["AlertCrossingAge"] == pytest.approx(1.2)
    last_end = cast(dict[str, object], by_id[0x205].decode(bytes(sink.messages[-1].data)))
    assert str(last_end["EndReason"]) == "PASSED"


def test_the_distance_driven_before_the_emission_is_taken_from_the_odometry() -> None:
    """The speed changes between the crossing and the emission: the distance at the emission
    is what the ego really drove, not the speed at the emission times the age."""
    sink = CanMemorySink()
    # 0..1 s at 5 m/s, then 15 m/s; crossing at 0.5 s, 30.2 m ahead; emitted at 1.5 s
    for k in range(int(1.5 * FPS) + 1):
        t = T0 + k / FPS
        v = 5.0 if k <= FPS else 15.0
        alerts = (_alert(4, T0 + 0.5, T0 + 1.5, 30.2),) if k == int(1.5 * FPS) else ()
        result = SimpleNamespace(
            t=t,
            alerts=alerts,
            provisional=(),
            cancelled=(),
            preview=None,
            confirmations=(),
            ego_speed_mps=v,
        )
        sink.on_frame(CameraFrame(t, None), cast(FrameResult, result), STATUS)
    (first,) = _of(ReceivedAlert, _decoded(sink))
    # driven 0.5..1.0 s at 5 m/s, the frame interval 1.0..1.033 s as the trapezoid's mean
    # (10 m/s), 1.033..1.5 s at 15 m/s
    driven = 0.5 * 5.0 + (1 / FPS) * 10.0 + (0.5 - 1 / FPS) * 15.0
    assert first.distance_m == pytest.approx(30.0 - driven, abs=DIST_LSB / 2)
    assert first.time_to_arrival_s == pytest.approx((30.0 - driven) / 15.0, abs=TTA_LSB / 2)


def test_at_another_frame_rate_the_sends_keep_the_period_on_average() -> None:
    """25 fps: 100 ms is 2.5 frames; a send is at most one frame late and the next is due a
    period after the scheduled time, so 10 sends per second stay 10 sends per second."""
    sink = CanMemorySink()
    _drive(sink, 4.0, 20.0, {0: [_alert(1, T0 - 1.0, T0, 120.2)]}, fps=25.0)
    sends = _of(ReceivedAlert, _decoded(sink))
    t = np.array([s.t_rx_s for s in sends]) - T0
    gaps = np.diff(t)
    assert gaps.min() >= CFG.period_s - 1 / 25.0 - 1e-6
    assert gaps.max() <= CFG.period_s + 1 / 25.0 + 1e-6
    assert len(sends) == pytest.approx(4.0 / CFG.period_s + 1, abs=1)
    tta = np.array([s.time_to_arrival_s for s in sends], dtype=float)
    # at 20 m/s, 100 m before the front axle at 0 s: arrival at 5 s, whatever the frame grid
    np.testing.assert_allclose(t + tta, (120.0 - 20.0) / 20.0, atol=TTA_LSB / 2 + 1e-6)


def test_close_cancels_the_active_alerts() -> None:
    sink = CanMemorySink()
    _drive(sink, 1.0, 10.0, {3: [_alert(9, T0, T0 + 0.1, 60.0)]})
    sink.close(RunSummary())
    got = _decoded(sink)
    ends = _of(ReceivedAlertEnd, got)
    assert [(e.alert_id, e.reason, e.cause) for e in ends] == [
        (9, EndReason.CANCELLED, EndCause.STOPPED)
    ] * CFG.end_repeats
    assert {e.t_rx_s for e in ends} == {T0 + 1.0}  # all at once, at the last time seen
    assert ends[0].sends == len(_of(ReceivedAlert, got)) == 10  # 0.1, 0.2, .. 1.0 s
    sink.close(RunSummary())  # a second close sends nothing more
    assert len(_of(ReceivedAlertEnd, _decoded(sink))) == CFG.end_repeats


def test_a_standing_ego_has_no_time_to_arrival_and_the_alert_times_out() -> None:
    sink = CanMemorySink()
    _drive(sink, 16.5, 0.0, {30: [_alert(2, T0 + 0.5, T0 + 1.0, 20.2)]})
    got = _decoded(sink)
    sends = _of(ReceivedAlert, got)
    assert all(s.time_to_arrival_s is None for s in sends)  # standstill: not available
    assert all(s.distance_m == pytest.approx(20.0, abs=DIST_LSB / 2) for s in sends)
    end = _of(ReceivedAlertEnd, got)[0]
    assert (end.reason, end.cause) == (EndReason.CANCELLED, EndCause.TIMEOUT)
    # 15 s after the lead's crossing ([anomaly.confirm] max_wait_s)
    assert end.t_rx_s - T0 == pytest.approx(0.5 + CFG.max_age_s, abs=1 / FPS + 1e-6)


def test_an_unknown_speed_makes_the_distance_unknown() -> None:
    sink = CanMemorySink()
    _drive(sink, 1.0, None, {3: [_alert(2, T0 - 0.5, T0 + 0.1, 20.2)]})
    sends = _of(ReceivedAlert, _decoded(sink))
    assert sends
    assert all(s.distance_m is None and s.time_to_arrival_s is None for s in sends)


def test_an_alert_already_passed_when_raised_only_ends() -> None:
    sink = CanMemorySink()
    _drive(sink, 0.5, 10.0, {3: [_alert(5, T0 - 5.0, T0 + 0.1, 20.0)]})  # 50 m driven since
    got = _decoded(sink)
    assert not _of(ReceivedAlert, got)
    ends = _of(ReceivedAlertEnd, got)
    assert ends
    assert (ends[0].reason, ends[0].sends) == (EndReason.PASSED, 0)


def test_ids_are_unique_while_active_and_confirmations_use_them() -> None:
    """Alert 257 comes while alert 1 (the same id modulo 256) is active: it gets id 2; its
    RP_CONFIRM after the end says 2 as well; after that 2 is free again."""
    sink = CanMemorySink()
    first = _alert(1, T0, T0 + 0.1, 60.0)
    clash = _alert(257, T0, T0 + 0.2, 30.0)
    confirm = ConfirmationResult(257, Confirmation.CONFIRMED, T0 + 4.0, T0 + 3.1, 3.0, 0.5)
    _drive(
        sink,
        4.0,
        10.0,
        {3: [first], 6: [clash]},
        confirmations={120: [confirm]},
    )
    got = _decoded(sink)
    ids_by_t: dict[float, set[int]] = {}
    for s in _of(ReceivedAlert, got):
        ids_by_t.setdefault(s.t_rx_s, set()).add(s.alert_id)
    assert {1, 2} in ids_by_t.values()  # both active at once, under different ids
    ends = {e.alert_id: e for e in _of(ReceivedAlertEnd, got)}
    assert ends[2].reason == EndReason.PASSED  # 30 m: passed at about 3.5 s
    (conf,) = _of(ReceivedConfirm, got)
    assert conf.alert_id == 2
    assert sink.repeater.can_id(257) == 257 % 256  # released: no longer mapped
    # a new alert 258 may now have id 2
    rep = AlertRepeater()
    rep.frame(0.0, 10.0, [_alert(1, -0.1, 0.0, 60.0), _alert(257, -0.1, 0.0, 60.0)])
    assert (rep.can_id(1), rep.can_id(257)) == (1, 2)


def test_too_many_active_alerts_drop_the_oldest() -> None:
    rep = AlertRepeater(RepetitionConfig(max_active=4))
    out = rep.frame(0.0, 10.0, [_alert(k, -0.1, 0.0, 80.0) for k in range(1, 5)])
    assert all(isinstance(o, AlertSend) for o in out)
    out = rep.frame(1 / FPS, 10.0, [_alert(5, -0.1, 1 / FPS, 80.0)])
    ends = [o for o in out if isinstance(o, AlertEnd)]
    assert [(e.alert.alert_id, e.cause) for e in ends] == [(1, EndCause.OVERFLOW)]
    assert rep.active == 4


def test_the_repetition_comes_from_the_configuration() -> None:
    cfg = PipelineConfig()
    cfg = replace(cfg, can=replace(cfg.can, alert_repeat_period_s=0.05))
    rep = repetition_config(cfg)
    assert rep.period_s == 0.05
    assert rep.wheelbase_m == cfg.anomaly.confirm.wheelbase_m
    assert rep.camera_to_front_axle_m == cfg.anomaly.alert.camera_to_front_axle_m
    assert rep.max_age_s == cfg.anomaly.confirm.max_wait_s
    sink = CanMemorySink(repetition=rep)
    _drive(sink, 1.0, 10.0, {0: [_alert(1, T0 - 0.5, T0, 60.0)]})
    t = [s.t_rx_s for s in _of(ReceivedAlert, _decoded(sink))]
    gaps = [b - a for a, b in itertools.pairwise(t)]
    # 50 ms at 30 fps: every 1.5 frames, i.e. alternately 1 and 2 frames apart
    assert np.mean(gaps) == pytest.approx(0.05, abs=0.005)
    assert max(gaps) <= 0.05 + 1 / FPS + 1e-6
    with pytest.raises(ValueError, match="period_s"):
        RepetitionConfig(period_s=0.0)
    assert math.isfinite(rep.pass_margin_m)


def test_a_confirmation_before_the_end_frees_the_id_at_the_end() -> None:
    """Creeping over a long anomaly, the ego's check (RP_CONFIRM) can come before the rear
    axle has left it: then the id is free as soon as the ends are out; without the check it
    waits for it (at most ``hold_s``)."""
    for confirm_early, free_id in ((True, 1), (False, 2)):
        rep = AlertRepeater()
        rep.frame(0.0, 10.0, [_alert(1, -0.1, 0.0, 5.0)])
        if confirm_early:
            rep.release(1)
        out: list[AlertSend | AlertEnd] = []
        for k in range(1, 60):  # 2 s at 10 m/s: passed after about 0.8 s, 3 ends by 1.1 s
            out += rep.frame(k / FPS, 10.0)
        assert sum(isinstance(o, AlertEnd) for o in out) == CFG.end_repeats
        rep.frame(2.0, 10.0, [_alert(257, 1.9, 2.0, 60.0)])
        assert rep.can_id(257) == free_id
