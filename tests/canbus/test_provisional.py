"""Provisional alerts on CAN (issue 27, DBC version 2): ``RP_ALERT_DETAIL.AlertState`` and
``RP_ALERT_END.EndCauseEx`` round-trip through cantools and `OutputDecoder`, a receiver built
on version 1 still decodes version-2 frames, and `AlertReceiver` follows an alert from the
frames: provisional -> confirmed -> passed, provisional -> cancelled (not confirmed)."""

from __future__ import annotations

import re
from dataclasses import replace
from typing import cast

import can
import cantools
import numpy as np
import pytest
from cantools.database.can import Database

from roadpreview.canbus import (
    DBC_VERSION,
    RP_ALERT,
    RP_ALERT_DETAIL,
    RP_ALERT_END,
    AlertReceiver,
    OutputDecoder,
    OutputEncoders,
    PreviewEncoder,
    ReceivedAlertDetail,
    ReceivedAlertEnd,
    ReceivedPreviewHeader,
    ReceivedPreviewPage,
    ReceiverState,
    encode_protected,
    load_database,
)
from roadpreview.canbus.dbc import dbc_text
from roadpreview.canbus.repetition import AlertEnd, AlertSend, EndCause, EndReason
from roadpreview.errors import ConfigError
from roadpreview.types import Alert, AlertState, FusionMode, RoadPreview, Side, Status

NONE, PROV, CONF, ENDED = (
    ReceiverState.NONE,
    ReceiverState.PROVISIONAL,
    ReceiverState.CONFIRMED,
    ReceiverState.ENDED,
)

#: the three alert messages exactly as version 1 of the DBC had them (a chassis ECU built
#: against it): version 2 must decode identically through these
V1_ALERT_MESSAGES = """
BO_ 512 RP_ALERT: 8 ROADPREVIEW
 SG_ RpAlert_CRC : 0|8@1+ (1,0) [0|255] "" CHASSIS
 SG_ RpAlert_Counter : 8|4@1+ (1,0) [0|14] "" CHASSIS
 SG_ AlertSide : 12|2@1+ (1,0) [0|3] "" CHASSIS
 SG_ AlertFusionMode : 14|2@1+ (1,0) [0|3] "" CHASSIS
 SG_ AlertId : 16|8@1+ (1,0) [0|255] "" CHASSIS
 SG_ AlertDistance : 24|10@1- (0.2,0) [-102.2|102.2] "m" CHASSIS
 SG_ AlertTimeToArrival : 34|10@1- (0.02,0) [-10.22|10.22] "s" CHASSIS
 SG_ AlertHeight : 44|9@1- (2,0) [-510|510] "mm" CHASSIS
 SG_ AlertLength : 53|6@1+ (0.1,0) [0|6.2] "m" CHASSIS
 SG_ AlertConfidence : 59|5@1+ (4,0) [0|100] "%" CHASSIS

BO_ 515 RP_ALERT_DETAIL: 8 ROADPREVIEW
 SG_ RpAlertDetail_CRC : 0|8@1+ (1,0) [0|255] "" CHASSIS
 SG_ RpAlertDetail_Counter : 8|4@1+ (1,0) [0|14] "" CHASSIS
 SG_ DetailDetector : 12|2@1+ (1,0) [0|1] "" CHASSIS
 SG_ AlertId : 16|8@1+ (1,0) [0|255] "" CHASSIS
 SG_ AlertHeightStd : 24|6@1+ (2,0) [0|124] "mm" CHASSIS
 SG_ AlertScore : 30|8@1+ (0.2,0) [0|50.8] "px|sd" CHASSIS
 SG_ AlertLeadSpeed : 38|8@1+ (0.5,0) [0|127] "km/h" CHASSIS
 SG_ AlertCrossingAge : 46|8@1+ (0.1,0) [0|25.4] "s" CHASSIS

BO_ 517 RP_ALERT_END: 8 ROADPREVIEW
 SG_ RpAlertEnd_CRC : 0|8@1+ (1,0) [0|255] "" CHASSIS
 SG_ RpAlertEnd_Counter : 8|4@1+ (1,0) [0|14] "" CHASSIS
 SG_ EndReason : 12|2@1+ (1,0) [0|1] "" CHASSIS
 SG_ EndCause : 14|2@1+ (1,0) [0|3] "" CHASSIS
 SG_ EndAlertId : 16|8@1+ (1,0) [0|255] "" CHASSIS
 SG_ EndAlertSends : 24|8@1+ (1,0) [0|255] "" CHASSIS
 SG_ EndDistance : 32|10@1- (0.2,0) [-102.2|102.2] "m" CHASSIS
"""


def _v1_text() -> str:
    """The shipped DBC with what version 2 added taken out again."""
    lines = dbc_text().splitlines()
    out, in_preview = [], False
    for line in lines:
        if line.startswith("BO_ 519 "):
            in_preview = True
        if in_preview:
            in_preview = bool(line.strip())
            continue
        added = re.search(r"\b519\b", line) or re.search(r"\b(AlertState|EndCauseEx)\b", line)
        if added and not line.startswith('CM_ "'):  # the file's comment names them: keep it
            continue
        out.append(line)
    return "\n".join(out).replace(f'VERSION "{DBC_VERSION}"', 'VERSION "roadpreview 1"')


@pytest.fixture(scope="module")
def db() -> Database:
    return load_database()


@pytest.fixture(scope="module")
def v1_db() -> Database:
    v1 = cantools.database.load_string(_v1_text(), database_format="dbc", strict=True)
    assert isinstance(v1, Database)
    return v1


def _alert(alert_id: int = 7, **kw: object) -> Alert:
    base = Alert(
        t_s=10.0,
        t_emit_s=10.5,
        distance_m=25.0,
        time_to_arrival_s=2.0,
        severity_px=6.0,
        height_mm=30.0,
        side=Side.BOTH,
        confidence=0.52,
        mode=FusionMode.FUSED,
        alert_id=alert_id,
        height_std_mm=12.0,
        length_m=0.6,
        lead_speed_mps=12.0,
        state=AlertState.PROVISIONAL,
    )
    return replace(base, **kw)  # type: ignore[arg-type]


def _send(alert: Alert, t: float, count: int) -> AlertSend:
    """The alert as of ``t`` (the ego drives 12.5 m/s towards it from 10.5 s on)."""
    distance = 24.8 - 12.5 * (t - 10.5)
    return AlertSend(
        alert, alert.alert_id % 256, t, distance, distance / 12.5, t - alert.t_s, count
    )


def _end(alert: Alert, t: float, reason: EndReason, cause: EndCause, sends: int) -> AlertEnd:
    return AlertEnd(alert, alert.alert_id % 256, t, reason, cause, sends, -3.4)


def _decoded(db: Database, frame: can.Message) -> dict[str, object]:
    return cast(dict[str, object], db.decode_message(frame.arbitration_id, bytes(frame.data)))


# --- the DBC -------------------------------------------------------------------------------


def test_the_dbc_is_version_2_and_names_the_new_values(db: Database) -> None:
    assert db.version == DBC_VERSION == "roadpreview 2"
    detail = db.get_message_by_name(RP_ALERT_DETAIL).get_signal_by_name("AlertState")
    assert (detail.start, detail.length) == (14, 2)
    assert {int(k): str(v) for k, v in (detail.choices or {}).items()} == {
        int(s): s.name for s in AlertState
    }
    ex = db.get_message_by_name(RP_ALERT_END).get_signal_by_name("EndCauseEx")
    assert (ex.start, ex.length) == (42, 3)
    assert {int(k): str(v) for k, v in (ex.choices or {}).items()} == {
        int(c): c.name for c in EndCause
    }
    # RP_ALERT has no free bit: it could not carry the state
    alert = db.get_message_by_name(RP_ALERT)
    assert sum(s.length for s in alert.signals) == 64


def test_version_2_moved_no_signal_of_version_1(db: Database, v1_db: Database) -> None:
    literal = cantools.database.load_string(
        'VERSION ""\nBU_: ROADPREVIEW CHASSIS\n' + V1_ALERT_MESSAGES, strict=True
    )
    assert isinstance(literal, Database)
    for name in (RP_ALERT, RP_ALERT_DETAIL, RP_ALERT_END):
        want = literal.get_message_by_name(name)
        for other in (v1_db.get_message_by_name(name), db.get_message_by_name(name)):
            for s in want.signals:
                got = other.get_signal_by_name(s.name)
                layout = (s.start, s.length, s.is_signed, s.scale, s.offset, s.minimum, s.maximum)
                assert layout == (
                    got.start,
                    got.length,
                    got.is_signed,
                    got.scale,
                    got.offset,
                    got.minimum,
                    got.maximum,
                ), f"{name}.{s.name}"
        v1_names = {s.name for s in v1_db.get_message_by_name(name).signals}
        assert v1_names == {s.name for s in want.signals}
    assert v1_db.version == "roadpreview 1"
    assert "RP_PREVIEW" not in {m.name for m in v1_db.messages}


# --- the new signals round-trip ------------------------------------------------------------


@pytest.mark.parametrize("state", list(AlertState))
def test_alert_state_round_trips(db: Database, state: AlertState) -> None:
    enc = OutputEncoders()
    send = _send(_alert(state=state), 10.6, 2)
    _alert_frame, detail_frame = enc.alert_frames(send)
    d = _decoded(db, detail_frame)
    assert str(d["AlertState"]) == state.name
    assert d["AlertCrossingAge"] == pytest.approx(0.6, abs=0.05)
    got = OutputDecoder(db).decode(detail_frame)
    assert isinstance(got, ReceivedAlertDetail)
    assert got.state == state
    assert got.height_std_mm == pytest.approx(12.0, abs=1.0)
    assert enc.detail.values(send)["AlertState"] == int(state)


@pytest.mark.parametrize("cause", list(EndCause))
def test_the_end_cause_round_trips_and_fits_version_1(db: Database, cause: EndCause) -> None:
    reason = EndReason.PASSED if cause == EndCause.NONE else EndReason.CANCELLED
    frame = OutputEncoders().end.encode(_end(_alert(), 11.0, reason, cause, 6))
    d = _decoded(db, frame)
    assert str(d["EndCauseEx"]) == cause.name
    assert str(d["EndCause"]) == (cause.name if cause <= 3 else "NONE")
    assert str(d["EndReason"]) == reason.name
    assert d["EndAlertSends"] == 6
    assert d["EndDistance"] == pytest.approx(-3.4, abs=0.1)
    got = OutputDecoder(db).decode(frame)
    assert isinstance(got, ReceivedAlertEnd)
    assert (got.reason, got.cause, got.alert_id) == (reason, cause, 7)


# --- compatibility -------------------------------------------------------------------------


def _v2_frames() -> list[can.Message]:
    """A provisional alert sent twice, confirmed twice, then cancelled NOT_CONFIRMED (another
    id), one TIMEOUT, and a preview snapshot: all of version 2."""
    enc = OutputEncoders()
    prov = _alert(7)
    conf = replace(prov, state=AlertState.CONFIRMED, height_mm=42.0, confidence=0.9)
    other = _alert(8, height_mm=-20.0, side=Side.LEFT)
    frames = [
        *enc.alert_frames(_send(prov, 10.5, 1)),
        *enc.alert_frames(_send(other, 10.5, 1)),
        *enc.alert_frames(_send(prov, 10.6, 2)),
        *enc.alert_frames(_send(conf, 10.7, 3)),
        enc.end.encode(_end(other, 10.7, EndReason.CANCELLED, EndCause.NOT_CONFIRMED, 1)),
        *enc.alert_frames(_send(conf, 10.8, 4)),
        enc.end.encode(_end(conf, 10.9, EndReason.CANCELLED, EndCause.TIMEOUT, 4)),
    ]
    preview = RoadPreview(10.9, 0.5, 0.0, np.full((1, 6), 0.01), np.full((1, 6), 0.004), False, 3.0)
    frames += PreviewEncoder(enc.alert.db).encode(preview, timestamp=10.9)
    return frames


def test_a_version_1_receiver_decodes_version_2_frames(db: Database, v1_db: Database) -> None:
    frames = _v2_frames()
    ids = {m.frame_id for m in v1_db.messages}
    for f in frames:
        if f.arbitration_id not in ids:  # RP_PREVIEW: an id version 1 does not know
            assert f.arbitration_id == 0x207
            continue
        old, new = _decoded(v1_db, f), _decoded(db, f)
        # every version-1 signal has the value version 2 gives it
        assert {k: str(v) for k, v in old.items()} == {
            k: str(v) for k, v in new.items() if k in old
        }
        if f.arbitration_id == 0x205 and str(new["EndCauseEx"]) == "NOT_CONFIRMED":
            assert (str(old["EndReason"]), str(old["EndCause"])) == ("CANCELLED", "NONE")
    # and through roadpreview's own decoder built on version 1
    rx1, rx2 = OutputDecoder(v1_db), OutputDecoder(db)
    got1, got2 = [rx1.decode(f) for f in frames], [rx2.decode(f) for f in frames]
    assert rx1.problems == rx2.problems == {}
    for a, b in zip(got1, got2, strict=True):
        if isinstance(b, ReceivedAlertDetail):
            assert isinstance(a, ReceivedAlertDetail)
            assert a.state == AlertState.CONFIRMED  # version 1 knows no other
            assert replace(a, state=b.state) == b
        elif isinstance(b, ReceivedAlertEnd):
            assert isinstance(a, ReceivedAlertEnd)
            assert a.reason == b.reason == EndReason.CANCELLED
            assert a.cause == (EndCause.NONE if b.cause == EndCause.NOT_CONFIRMED else b.cause)
        elif isinstance(b, ReceivedPreviewHeader | ReceivedPreviewPage):
            assert a is None  # version 1 has no RP_PREVIEW
        else:
            assert a == b
    # a version-1 alert receiver still sees every alert and its end
    life1 = AlertReceiver()
    life1.push_all(got1)
    assert life1.state(7) == life1.state(8) == ENDED
    ended = life1.get(8)
    assert ended is not None
    assert ended.reason == EndReason.CANCELLED


def test_a_version_2_receiver_reads_a_version_1_sender(db: Database, v1_db: Database) -> None:
    """A version-1 sender leaves the new bits 0: confirmed alerts, the cause in EndCause."""
    detail = v1_db.get_message_by_name(RP_ALERT_DETAIL)
    end = v1_db.get_message_by_name(RP_ALERT_END)
    detail_values = {
        "DetailDetector": 1,
        "AlertId": 3,
        "AlertHeightStd": 8.0,
        "AlertScore": 5.0,
        "AlertLeadSpeed": 50.0,
        "AlertCrossingAge": 1.2,
    }
    end_values = {
        "EndReason": 1,
        "EndCause": 2,
        "EndAlertId": 3,
        "EndAlertSends": 9,
        "EndDistance": 4.0,
    }
    frames = [
        can.Message(arbitration_id=m.frame_id, data=encode_protected(m, v, 0), is_extended_id=False)
        for m, v in ((detail, detail_values), (end, end_values))
    ]
    got = [OutputDecoder(db).decode(f) for f in frames]
    assert isinstance(got[0], ReceivedAlertDetail)
    assert got[0].state == AlertState.CONFIRMED
    assert isinstance(got[1], ReceivedAlertEnd)
    assert (got[1].reason, got[1].cause) == (EndReason.CANCELLED, EndCause.TIMEOUT)


# --- the receiver's state machine ----------------------------------------------------------


def _follow(frames: list[can.Message]) -> AlertReceiver:
    decoder = OutputDecoder()
    rx = AlertReceiver()
    rx.push_all(decoder.decode(f) for f in frames)
    assert decoder.problems == {}
    return rx


def _steps(rx: AlertReceiver, alert_id: int) -> list[tuple[ReceiverState, ReceiverState, float]]:
    return [(t.before, t.after, round(t.t_s, 3)) for t in rx.transitions if t.alert_id == alert_id]


def test_provisional_then_confirmed_then_passed() -> None:
    enc = OutputEncoders()
    prov = _alert(7)
    conf = replace(prov, state=AlertState.CONFIRMED, height_mm=42.0, length_m=0.8, confidence=0.92)
    frames: list[can.Message] = []
    for k, (alert, t) in enumerate(((prov, 10.5), (prov, 10.6), (conf, 10.7), (conf, 10.8))):
        frames += enc.alert_frames(_send(alert, t, k + 1))
    frames += [enc.end.encode(_end(conf, t, EndReason.PASSED, EndCause.NONE, 4))
               for t in (10.9, 11.0, 11.1)]  # fmt: skip
    rx = _follow(frames)
    assert _steps(rx, 7) == [(NONE, PROV, 10.5), (PROV, CONF, 10.7), (CONF, ENDED, 10.9)]
    life = rx.get(7)
    assert life is not None
    assert life.was_provisional
    assert life.t_confirmed_s == pytest.approx(10.7)
    assert (life.reason, life.cause, life.stale) == (EndReason.PASSED, EndCause.NONE, False)
    assert life.alert is not None
    assert life.alert.height_mm == pytest.approx(42.0, abs=1.0)  # the refined height
    assert life.alert.length_m == pytest.approx(0.8, abs=0.05)
    assert life.alert.confidence == pytest.approx(0.92, abs=0.02)
    assert rx.active == {}
    assert rx.problems == {}


def test_provisional_then_cancelled_not_confirmed_and_the_id_comes_back() -> None:
    enc = OutputEncoders()
    prov = _alert(9)
    frames = [*enc.alert_frames(_send(prov, 10.5, 1)), *enc.alert_frames(_send(prov, 10.6, 2))]
    rx = AlertReceiver()
    decoder = OutputDecoder()
    rx.push_all(decoder.decode(f) for f in frames)
    assert rx.state(9) == PROV
    assert set(rx.active) == {9}
    life = rx.get(9)
    assert life is not None
    assert life.detail is not None
    assert life.detail.state == AlertState.PROVISIONAL
    ends = [
        enc.end.encode(_end(prov, t, EndReason.CANCELLED, EndCause.NOT_CONFIRMED, 2))
        for t in (10.7, 10.8, 10.9)
    ]
    rx.push_all(decoder.decode(f) for f in ends)
    assert _steps(rx, 9) == [(NONE, PROV, 10.5), (PROV, ENDED, 10.7)]  # the repeats: nothing
    life = rx.get(9)
    assert life is not None
    assert (life.reason, life.cause) == (EndReason.CANCELLED, EndCause.NOT_CONFIRMED)
    assert life.t_confirmed_s != life.t_confirmed_s  # NaN: never confirmed
    # the id is free again: a later alert confirmed from its first frame (no provisional)
    later = _alert(9, state=AlertState.CONFIRMED, t_s=11.5, t_emit_s=12.0)
    rx.push_all(decoder.decode(f) for f in enc.alert_frames(_send(later, 12.0, 1)))
    assert _steps(rx, 9)[2:] == [(NONE, PROV, 12.0), (PROV, CONF, 12.0)]  # in the same send
    life = rx.get(9)
    assert life is not None
    assert not life.was_provisional
    assert life.end is None
    assert rx.problems == {}


def test_silence_ends_an_alert_and_a_late_end_gives_its_reason() -> None:
    enc = OutputEncoders()
    prov = _alert(4)
    rx = AlertReceiver()
    decoder = OutputDecoder()
    rx.push_all(decoder.decode(f) for f in enc.alert_frames(_send(prov, 10.5, 1)))
    status = enc.status_frames(Status(mode=FusionMode.FUSED), timestamp=10.9)
    assert rx.push_all(decoder.decode(f) for f in status) == []  # 0.4 s: still active
    status = enc.status_frames(Status(mode=FusionMode.FUSED), timestamp=11.1)
    steps = rx.push_all(decoder.decode(f) for f in status)
    assert [(s.before, s.after) for s in steps] == [(PROV, ENDED)]
    life = rx.get(4)
    assert life is not None
    assert life.stale
    assert life.reason is None
    end = enc.end.encode(_end(prov, 11.2, EndReason.CANCELLED, EndCause.STOPPED, 1))
    assert rx.push(decoder.decode(end)) == []
    life = rx.get(4)
    assert life is not None
    assert life.stale
    assert life.cause == EndCause.STOPPED


def test_a_detail_cannot_take_a_confirmed_alert_back() -> None:
    enc = OutputEncoders()
    conf = _alert(5, state=AlertState.CONFIRMED)
    frames = [
        *enc.alert_frames(_send(conf, 10.5, 1)),
        *enc.alert_frames(_send(replace(conf, state=AlertState.PROVISIONAL), 10.6, 2)),
        enc.end.encode(_end(conf, 10.7, EndReason.CANCELLED, EndCause.NOT_CONFIRMED, 2)),
    ]
    rx = _follow(frames)
    assert _steps(rx, 5) == [(NONE, PROV, 10.5), (PROV, CONF, 10.5), (CONF, ENDED, 10.7)]
    assert rx.problems == {"state_regressed": 1, "not_confirmed_after_confirmed": 1}


def test_lost_frames_still_give_a_life() -> None:
    """A lost RP_ALERT: its detail starts the alert; a whole life lost: the end alone."""
    enc = OutputEncoders()
    prov = _alert(6)
    _, detail = enc.alert_frames(_send(prov, 10.5, 1))
    end = enc.end.encode(_end(_alert(2), 10.6, EndReason.PASSED, EndCause.NONE, 3))
    rx = _follow([detail, end])
    assert _steps(rx, 6) == [(NONE, PROV, 10.5)]
    assert _steps(rx, 2) == [(NONE, ENDED, 10.6)]
    with pytest.raises(ConfigError, match="stale_s"):
        AlertReceiver(stale_s=0.0)
