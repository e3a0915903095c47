"""roadpreview's outputs (RP_ALERT, RP_ALERT_DETAIL, RP_ALERT_END, RP_CONFIRM, RP_STATUS,
RP_ROAD_STATUS): cantools (strict) and `OutputDecoder` decode what we encode, E2E counters and
CRCs check."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import cantools
import e2e.p01
import numpy as np
import pytest
from cantools.database.can import Database
from cantools.typechecking import DecodeResultType, SignalDictType

from roadpreview.anomaly.roughness import ISO8608_GD_N0
from roadpreview.canbus import (
    DETECTOR_CODES,
    E2E_COUNTER_MODULUS,
    RP_ALERT,
    RP_ALERT_DETAIL,
    RP_CONFIRM,
    RP_ROAD_STATUS,
    RP_STATUS,
    AlertDetailEncoder,
    AlertEncoder,
    ConfirmEncoder,
    OutputDecoder,
    OutputEncoders,
    ReceivedAlert,
    ReceivedAlertDetail,
    ReceivedConfirm,
    ReceivedRoadStatus,
    ReceivedStatus,
    RoadStatusEncoder,
    StatusEncoder,
    alert_frames,
    read_can_log,
    write_can_log,
)
from roadpreview.canbus.dbc import RP_ALERT_END
from roadpreview.canbus.output import AlertEndEncoder
from roadpreview.canbus.received import ReceivedAlertEnd
from roadpreview.canbus.repetition import AlertEnd, AlertSend, EndCause, EndReason
from roadpreview.errors import ConfigError
from roadpreview.types import (
    ISO8608_CLASSES,
    Alert,
    Confirmation,
    ConfirmationResult,
    FusionMode,
    RoadState,
    Side,
    Status,
    SuppressionReason,
)

REPO_DBC = Path(__file__).resolve().parents[2] / "data" / "roadpreview.dbc"
DEG = math.pi / 180
KMH = 1 / 3.6
NA = "SignalNotAvailable"


@pytest.fixture(scope="module")
def strict_db() -> Database:
    """The DBC loaded by cantools itself, strictly: the receiver's view, not our loader's."""
    db = cantools.database.load_file(REPO_DBC, strict=True)
    assert isinstance(db, Database)
    return db


def _signals(decoded: DecodeResultType) -> SignalDictType:
    """cantools decodes a plain (non-container) message to a signal dict: narrow to it."""
    assert isinstance(decoded, dict)
    return decoded


def _random_alerts(n: int, seed: int = 0) -> list[Alert]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        t = 100.0 + k
        out.append(
            Alert(
                t_s=t,
                t_emit_s=t + float(rng.uniform(0, 1.4)),
                distance_m=float(rng.uniform(0, 204.4)),
                time_to_arrival_s=float(rng.uniform(0, 20.44)),
                severity_px=float(rng.uniform(0, 50.8)),
                height_mm=float(rng.uniform(-510, 510)),
                side=Side(int(rng.integers(0, 4))),
                confidence=float(rng.uniform(0, 1)),
                mode=FusionMode(int(rng.integers(0, 4))),
                alert_id=k + 1 + 250 * (k % 3),  # beyond 255 too: sent modulo 256
                height_std_mm=float(rng.uniform(0, 124)),
                length_m=float(rng.uniform(0, 6.2)),
                lead_speed_mps=float(rng.uniform(0, 127)) * KMH,
            )
        )
    return out


def _random_sends(n: int, seed: int = 0) -> list[AlertSend]:
    """The alerts as of a later send: front axle before (or, negative, past) the anomaly."""
    rng = np.random.default_rng(seed + 100)
    return [
        AlertSend(
            alert=a,
            can_id=a.alert_id % 256,
            t_s=a.t_emit_s + float(rng.uniform(0, 5)),
            distance_m=float(rng.uniform(-102.2, 102.2)),
            time_to_arrival_s=float(rng.uniform(-10.22, 10.22)),
            age_s=float(rng.uniform(0, 25.4)),
            count=int(rng.integers(1, 100)),
        )
        for a in _random_alerts(n, seed)
    ]


def _random_ends(n: int, seed: int = 4) -> list[AlertEnd]:
    rng = np.random.default_rng(seed)
    out = []
    for a in _random_alerts(n, seed):
        passed = bool(rng.integers(0, 2))
        out.append(
            AlertEnd(
                alert=a,
                can_id=int(rng.integers(0, 256)),
                t_s=a.t_emit_s + float(rng.uniform(0, 15)),
                reason=EndReason.PASSED if passed else EndReason.CANCELLED,
                cause=EndCause.NONE if passed else EndCause(int(rng.integers(1, 4))),
                sends=int(rng.integers(0, 300)),
                distance_m=float(rng.uniform(-102.2, 102.2)),
            )
        )
    return out


def _random_confirmations(n: int, seed: int = 2) -> list[ConfirmationResult]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        t = 200.0 + k
        out.append(
            ConfirmationResult(
                alert_id=k + 300,
                outcome=Confirmation(int(rng.integers(0, 3))),
                t_s=t,
                t_arrival_s=t - float(rng.uniform(0, 5.08)),
                peak_mps2=float(rng.uniform(0, 20.44)),
                background_mps2=float(rng.uniform(0, 5.08)),
            )
        )
    return out


def _random_road(rng: np.random.Generator) -> RoadState:
    ego = float(10 ** rng.uniform(-6, 0.3))  # 0 .. 63 dB re 1e-6 m^3
    lead = float(10 ** rng.uniform(-6, 0.3))
    return RoadState(
        iso_class=ISO8608_CLASSES[int(rng.integers(0, 8))],
        gd_n0=ego,
        ego_class=ISO8608_CLASSES[int(rng.integers(0, 8))],
        ego_gd_n0=ego,
        lead_class=ISO8608_CLASSES[int(rng.integers(0, 8))],
        lead_gd_n0=lead,
    )


def _random_statuses(n: int, seed: int = 1) -> list[Status]:
    rng = np.random.default_rng(seed)
    return [
        Status(
            mode=FusionMode(int(rng.integers(0, 4))),
            pitch_rad=float(rng.uniform(-10, 10)) * DEG,
            gyro_bias_rad_s=float(rng.uniform(-2.5, 2.5)) * DEG,
            texture_quality=float(rng.uniform(0, 1)),
            time_offset_s=float(rng.uniform(-0.127, 0.127)),
            suppressed=SuppressionReason(int(rng.integers(0, 4))),
            alerts_sent=int(rng.integers(0, 1000)),
            input_errors_total=int(rng.integers(0, 40)),
            frames_processed=int(rng.integers(0, 10**6)),
            road=_random_road(rng),
            precision=float(rng.uniform(0, 1)),
            confirmed=int(rng.integers(0, 1000)),
            not_felt=int(rng.integers(0, 1000)),
        )
        for _ in range(n)
    ]


def _db_gd(gd_n0: float) -> float:
    return 10 * math.log10(gd_n0 / 1e-6)


def _lsb(db: Database, message: str, signal: str) -> float:
    return float(db.get_message_by_name(message).get_signal_by_name(signal).scale)


def test_alerts_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = AlertEncoder()
    msg_def = strict_db.get_message_by_name(RP_ALERT)
    for send in _random_sends(300):
        frame = enc.encode(send)
        assert frame.arbitration_id == 0x200
        assert frame.dlc == 8
        assert not frame.is_extended_id
        assert frame.timestamp == send.t_s
        got = _signals(msg_def.decode(bytes(frame.data), decode_choices=False))
        alert = send.alert
        want = {
            "AlertDistance": send.distance_m,  # as of this send, signed
            "AlertTimeToArrival": send.time_to_arrival_s,
            "AlertHeight": alert.height_mm,
            "AlertLength": alert.length_m,
            "AlertConfidence": 100 * alert.confidence,
        }
        for name, value in want.items():
            lsb = _lsb(strict_db, RP_ALERT, name)
            assert got[name] == pytest.approx(value, abs=lsb / 2 + 1e-9), name
        assert got["AlertSide"] == int(alert.side)
        assert got["AlertFusionMode"] == int(alert.mode)
        assert got["AlertId"] == send.can_id
        assert "AlertSeverity" not in got  # the score is in RP_ALERT_DETAIL
        assert "AlertEventAge" not in got  # the crossing's age too (AlertCrossingAge)


def test_an_alert_at_its_emission_has_driven_its_share_at_constant_speed() -> None:
    """Encoding an `Alert` itself: the front axle (0.2 m ahead of the camera) covered
    age / TTA of its way since the crossing, and the TTA is counted from the emission."""
    alert = replace(_random_alerts(1)[0], t_s=10.0, t_emit_s=11.2, distance_m=30.2)
    alert = replace(alert, time_to_arrival_s=3.0)  # (30.2 - 0.2) m at 10 m/s
    send = AlertSend.at_emission(alert)
    assert send.t_s == 11.2
    assert send.distance_m == pytest.approx(30.0 - 10.0 * 1.2)
    assert send.time_to_arrival_s == pytest.approx(3.0 - 1.2)
    assert send.age_s == pytest.approx(1.2)
    back = OutputDecoder().decode(AlertEncoder().encode(alert))
    assert isinstance(back, ReceivedAlert)
    assert back.distance_m == pytest.approx(18.0, abs=0.1)
    assert back.arrival_t_s == pytest.approx(alert.t_s + 3.0, abs=0.01)  # the same instant
    still = AlertSend.at_emission(replace(alert, time_to_arrival_s=None))
    assert still.distance_m == pytest.approx(30.0)  # no speed: as at the crossing
    assert still.time_to_arrival_s is None


def test_alert_ends_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = AlertEndEncoder()
    msg_def = strict_db.get_message_by_name(RP_ALERT_END)
    for end in _random_ends(300):
        frame = enc.encode(end)
        assert (frame.arbitration_id, frame.dlc, frame.is_extended_id) == (0x205, 8, False)
        assert frame.timestamp == end.t_s
        got = _signals(msg_def.decode(bytes(frame.data), decode_choices=False))
        assert got["EndReason"] == int(end.reason)
        assert got["EndCause"] == int(end.cause)
        assert got["EndAlertId"] == end.can_id
        assert got["EndAlertSends"] == min(end.sends, 255)
        lsb = _lsb(strict_db, RP_ALERT_END, "EndDistance")
        assert got["EndDistance"] == pytest.approx(end.distance_m, abs=lsb / 2 + 1e-9)
    named = _signals(msg_def.decode(bytes(enc.encode(_random_ends(1, seed=9)[0]).data)))
    assert str(named["EndReason"]) in ("PASSED", "CANCELLED")
    unknown = replace(end, distance_m=None, reason=EndReason.CANCELLED, cause=EndCause.TIMEOUT)
    back = OutputDecoder().decode(AlertEndEncoder().encode(unknown))
    assert isinstance(back, ReceivedAlertEnd)
    assert back.distance_m is None
    assert (back.reason, back.cause, back.alert_id) == (
        EndReason.CANCELLED,
        EndCause.TIMEOUT,
        end.can_id,
    )


def test_alert_details_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = AlertDetailEncoder()
    msg_def = strict_db.get_message_by_name(RP_ALERT_DETAIL)
    for k, send in enumerate(_random_sends(300, seed=3)):
        detector = ("std", "two-axle")[k % 2]
        frame = enc.encode(send, detector)
        assert (frame.arbitration_id, frame.dlc, frame.is_extended_id) == (0x203, 8, False)
        assert frame.timestamp == send.t_s
        got = _signals(msg_def.decode(bytes(frame.data), decode_choices=False))
        alert = send.alert
        assert alert.lead_speed_mps is not None
        want = {
            "AlertHeightStd": alert.height_std_mm,
            "AlertScore": alert.severity_px,
            "AlertLeadSpeed": alert.lead_speed_mps / KMH,
            "AlertCrossingAge": send.age_s,
        }
        for name, value in want.items():
            lsb = _lsb(strict_db, RP_ALERT_DETAIL, name)
            assert got[name] == pytest.approx(value, abs=lsb / 2 + 1e-9), name
        assert got["AlertId"] == send.can_id
        assert "AlertLength" not in got  # in RP_ALERT itself
        assert got["DetailDetector"] == DETECTOR_CODES[detector]
    assert (
        str(_signals(msg_def.decode(bytes(enc.encode(alert, "std").data)))["DetailDetector"])
        == "STD"
    )
    assert (
        str(_signals(msg_def.decode(bytes(enc.encode(alert).data)))["DetailDetector"]) == "TWO_AXLE"
    )


def test_confirmations_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = ConfirmEncoder()
    msg_def = strict_db.get_message_by_name(RP_CONFIRM)
    rng = np.random.default_rng(5)
    for result in _random_confirmations(300):
        precision = float(rng.uniform(0, 1))
        frame = enc.encode(result, precision)
        assert (frame.arbitration_id, frame.dlc, frame.is_extended_id) == (0x204, 8, False)
        assert frame.timestamp == result.t_s  # decided at that frame
        got = _signals(msg_def.decode(bytes(frame.data), decode_choices=False))
        want = {
            "ConfirmPeakAccel": result.peak_mps2,
            "ConfirmBackgroundAccel": result.background_mps2,
            "ConfirmArrivalAge": result.t_s - result.t_arrival_s,
            "ConfirmPrecision": 100 * precision,
        }
        for name, value in want.items():
            lsb = _lsb(strict_db, RP_CONFIRM, name)
            assert got[name] == pytest.approx(value, abs=lsb / 2 + 1e-9), name
        assert got["ConfirmOutcome"] == int(result.outcome)
        assert got["ConfirmAlertId"] == result.alert_id % 256
    # the age is counted to the frame's own time stamp
    arrived = replace(result, t_arrival_s=result.t_s - 1.5)
    later = _signals(msg_def.decode(bytes(enc.encode(arrived, timestamp=result.t_s + 1.0).data)))
    assert later["ConfirmArrivalAge"] == pytest.approx(2.5, abs=0.01)


def test_road_statuses_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = RoadStatusEncoder()
    msg_def = strict_db.get_message_by_name(RP_ROAD_STATUS)
    for status in _random_statuses(300, seed=6):
        frame = enc.encode(status, timestamp=3.0)
        assert (frame.arbitration_id, frame.dlc, frame.is_extended_id) == (0x202, 8, False)
        got = _signals(msg_def.decode(bytes(frame.data), decode_choices=False))
        road = status.road
        assert road is not None
        assert status.precision is not None
        want = {
            "RoadGdEgo": min(max(_db_gd(road.ego_gd_n0), 0.0), 63.5),
            "RoadGdLead": min(max(_db_gd(road.lead_gd_n0), 0.0), 63.5),
            "OnlinePrecision": 100 * status.precision,
        }
        for name, value in want.items():
            lsb = _lsb(strict_db, RP_ROAD_STATUS, name)
            assert got[name] == pytest.approx(value, abs=lsb / 2 + 1e-9), name
        assert got["RoadClass"] == road.class_index
        assert got["RoadClassEgo"] == ISO8608_CLASSES.index(road.ego_class or "") + 1
        assert got["RoadClassLead"] == ISO8608_CLASSES.index(road.lead_class or "") + 1
        assert got["ConfirmedCount"] == status.confirmed % 256
        assert got["NotFeltCount"] == status.not_felt % 256


def test_road_class_levels_on_can_are_the_iso_8608_classes(strict_db: Database) -> None:
    """Each class's geometric-mean G_d(n0) goes out as its class and comes back within
    0.125 dB; the DBC's value table names the classes."""
    enc = RoadStatusEncoder()
    rx = OutputDecoder()
    msg_def = strict_db.get_message_by_name(RP_ROAD_STATUS)
    for k, (name, gd) in enumerate(ISO8608_GD_N0.items()):
        road = RoadState(name, gd, name, gd, name, gd)
        frame = enc.encode(Status(mode=FusionMode.FUSED, road=road), timestamp=float(k))
        assert str(_signals(msg_def.decode(bytes(frame.data)))["RoadClass"]) == name
        back = rx.decode(frame)
        assert isinstance(back, ReceivedRoadStatus)
        assert (back.iso_class, back.ego_class, back.lead_class) == (name, name, name)
        assert back.ego_gd_n0 is not None
        assert _db_gd(back.ego_gd_n0) == pytest.approx(_db_gd(gd), abs=0.125 + 1e-9)
    choices = msg_def.get_signal_by_name("RoadClass").choices
    assert choices is not None
    assert {int(k): str(v) for k, v in choices.items()} == {
        0: "UNKNOWN",
        **{i + 1: c for i, c in enumerate(ISO8608_CLASSES)},
    }


def test_statuses_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = StatusEncoder()
    msg_def = strict_db.get_message_by_name(RP_STATUS)
    for status in _random_statuses(300):
        new_errors = status.input_errors_total - enc.errors_sent
        if new_errors < 0:  # a lower total: the count restarted
            new_errors = status.input_errors_total
        got = _signals(msg_def.decode(bytes(enc.encode(status).data), decode_choices=False))
        assert status.pitch_rad is not None
        assert status.gyro_bias_rad_s is not None
        assert status.texture_quality is not None
        assert status.time_offset_s is not None
        want = {
            "StatusPitch": status.pitch_rad / DEG,
            "StatusGyroBias": status.gyro_bias_rad_s / DEG,
            "StatusTextureQuality": 100 * status.texture_quality,
            "StatusTimeOffset": 1000 * status.time_offset_s,
        }
        for name, value in want.items():
            lsb = _lsb(strict_db, RP_STATUS, name)
            assert got[name] == pytest.approx(value, abs=lsb / 2 + 1e-9), name
        assert got["StatusFusionMode"] == int(status.mode)
        assert got["StatusSuppression"] == int(status.suppressed)
        assert got["StatusAlertCount"] == status.alerts_sent % 16
        assert got["StatusInputErrors"] == min(new_errors, 15)
        assert got["StatusHeartbeat"] == status.frames_processed % 8


def test_unknown_values_are_signal_not_available_and_large_ones_saturate(
    strict_db: Database,
) -> None:
    enc = AlertEncoder()
    detail = AlertDetailEncoder()
    alert = Alert(
        t_s=1.0,
        t_emit_s=31.0,  # 30 s old: beyond 25.4 s
        distance_m=None,
        time_to_arrival_s=None,
        severity_px=80.0,  # beyond 50.8
        height_mm=None,
        side=Side.LEFT,
        confidence=1.0,
        mode=FusionMode.IMU_ONLY,
        alert_id=256 + 7,
    )
    got = _signals(strict_db.get_message_by_name(RP_ALERT).decode(bytes(enc.encode(alert).data)))
    assert str(got["AlertDistance"]) == NA
    assert str(got["AlertTimeToArrival"]) == NA
    assert str(got["AlertHeight"]) == NA
    assert str(got["AlertLength"]) == NA
    assert got["AlertConfidence"] == 100
    assert got["AlertId"] == 7
    assert str(got["AlertSide"]) == "LEFT"
    assert str(got["AlertFusionMode"]) == "IMU_ONLY"
    assert enc.saturated == {}
    got = _signals(
        strict_db.get_message_by_name(RP_ALERT_DETAIL).decode(bytes(detail.encode(alert).data))
    )
    assert got["AlertScore"] == pytest.approx(50.8)
    assert got["AlertCrossingAge"] == pytest.approx(25.4)
    for name in ("AlertHeightStd", "AlertLeadSpeed"):
        assert str(got[name]) == NA, name
    assert detail.saturated == {"AlertScore": 1, "AlertCrossingAge": 1}
    # beyond the ranges: heights both ways, distance and TTA both ways, std, length, lead
    # speed, confidence
    big = AlertSend(
        alert=replace(
            alert,
            height_mm=900.0,
            height_std_mm=300.0,
            length_m=40.0,
            lead_speed_mps=60.0,  # 216 km/h
            confidence=float("nan"),
        ),
        can_id=7,
        t_s=31.0,
        distance_m=500.0,
        time_to_arrival_s=40.0,
        age_s=-0.5,  # before the crossing: not a valid age
        count=1,
    )
    got = _signals(strict_db.get_message_by_name(RP_ALERT).decode(bytes(enc.encode(big).data)))
    assert got["AlertHeight"] == 510
    assert got["AlertDistance"] == pytest.approx(102.2)
    assert got["AlertTimeToArrival"] == pytest.approx(10.22)
    assert got["AlertLength"] == pytest.approx(6.2)
    assert str(got["AlertConfidence"]) == NA
    hole = replace(
        big, alert=replace(big.alert, height_mm=-900.0), distance_m=-500.0, time_to_arrival_s=-40.0
    )
    got = _signals(strict_db.get_message_by_name(RP_ALERT).decode(bytes(enc.encode(hole).data)))
    assert got["AlertHeight"] == -510
    assert got["AlertDistance"] == pytest.approx(-102.2)
    assert got["AlertTimeToArrival"] == pytest.approx(-10.22)
    got = _signals(
        strict_db.get_message_by_name(RP_ALERT_DETAIL).decode(bytes(detail.encode(big).data))
    )
    assert got["AlertHeightStd"] == 124
    assert str(got["AlertCrossingAge"]) == NA
    assert got["AlertLeadSpeed"] == 127
    status = StatusEncoder().encode(Status(mode=FusionMode.DEGRADED))
    got = _signals(strict_db.get_message_by_name(RP_STATUS).decode(bytes(status.data)))
    for name in ("StatusPitch", "StatusGyroBias", "StatusTextureQuality", "StatusTimeOffset"):
        assert str(got[name]) == NA, name


def test_a_pothole_goes_out_as_a_negative_height(strict_db: Database) -> None:
    """Signed AlertHeight: -60 mm is raw -30 (two's complement in 9 bits), +60 mm raw +30."""
    msg_def = strict_db.get_message_by_name(RP_ALERT)
    base = _random_alerts(1, seed=8)[0]
    enc = AlertEncoder()
    rx = OutputDecoder()
    for height, raw in ((-60.0, -30), (60.0, 30), (-4.0, -2), (-510.0, -255), (0.0, 0)):
        alert = replace(base, height_mm=height)
        frame = enc.encode(alert)
        assert _signals(msg_def.decode(bytes(frame.data), scaling=False))["AlertHeight"] == raw
        bits = (int.from_bytes(frame.data, "little") >> 44) & 0x1FF
        assert bits == raw % 512  # the 9 bits on the wire
        back = rx.decode(frame)
        assert isinstance(back, ReceivedAlert)
        assert back.height_mm == pytest.approx(height, abs=1.0)
        assert back.height_mm is not None
        assert (back.height_mm < 0) == (height < -1.0)


def test_confirmation_and_road_status_not_available(strict_db: Database) -> None:
    nan = float("nan")
    never = ConfirmationResult(5, Confirmation.UNKNOWN, 30.0, nan, nan, nan)
    frame = ConfirmEncoder().encode(never)
    got = _signals(strict_db.get_message_by_name(RP_CONFIRM).decode(bytes(frame.data)))
    for name in ("ConfirmPeakAccel", "ConfirmBackgroundAccel", "ConfirmArrivalAge"):
        assert str(got[name]) == NA, name
    assert str(got["ConfirmPrecision"]) == NA  # no precision given
    assert str(got["ConfirmOutcome"]) == "UNKNOWN"
    back = OutputDecoder().decode(frame)
    assert isinstance(back, ReceivedConfirm)
    assert (back.peak_mps2, back.background_mps2, back.arrival_age_s, back.precision) == (
        None,
        None,
        None,
        None,
    )
    assert back.t_arrival_s is None
    assert back.outcome == Confirmation.UNKNOWN
    # beyond the ranges: saturate
    hard = ConfirmationResult(6, Confirmation.CONFIRMED, 30.0, 20.0, 45.0, 9.0)
    conf = ConfirmEncoder()
    got = _signals(
        strict_db.get_message_by_name(RP_CONFIRM).decode(bytes(conf.encode(hard, 1.2).data))
    )
    assert got["ConfirmPeakAccel"] == pytest.approx(20.44)
    assert got["ConfirmBackgroundAccel"] == pytest.approx(5.08)
    assert got["ConfirmArrivalAge"] == pytest.approx(5.08)
    assert got["ConfirmPrecision"] == 100
    assert set(conf.saturated) == {
        "ConfirmPeakAccel",
        "ConfirmBackgroundAccel",
        "ConfirmArrivalAge",
        "ConfirmPrecision",
    }
    # a status at its defaults (what Pipeline.status() gives before it fills the road part)
    road = RoadStatusEncoder().encode(Status(mode=FusionMode.FUSED))
    got = _signals(strict_db.get_message_by_name(RP_ROAD_STATUS).decode(bytes(road.data)))
    for name in ("RoadClass", "RoadClassEgo", "RoadClassLead"):
        assert str(got[name]) == "UNKNOWN", name
    for name in ("RoadGdEgo", "RoadGdLead", "OnlinePrecision"):
        assert str(got[name]) == NA, name
    assert (got["ConfirmedCount"], got["NotFeltCount"]) == (0, 0)
    back = OutputDecoder().decode(road)
    assert back == ReceivedRoadStatus(0.0, 0, None, None, None, None, None, None, 0, 0)
    # an estimate that is not positive has no level; out of range levels saturate
    odd = RoadState("A", 0.0, None, 0.0, "H", 50.0)  # 50 m^3: 77 dB
    got = _signals(
        strict_db.get_message_by_name(RP_ROAD_STATUS).decode(
            bytes(
                RoadStatusEncoder()
                .encode(Status(mode=FusionMode.FUSED, road=odd, confirmed=257))
                .data
            )
        )
    )
    assert str(got["RoadGdEgo"]) == NA
    assert got["RoadGdLead"] == pytest.approx(63.5)
    assert str(got["RoadClass"]) == "A"
    assert str(got["RoadClassLead"]) == "H"
    assert got["ConfirmedCount"] == 1


def test_an_unknown_detector_name_is_a_config_error() -> None:
    alert = _random_alerts(1)[0]
    with pytest.raises(ConfigError, match="'cnn'"):
        AlertDetailEncoder().encode(alert, "cnn")


def test_enum_values_on_can_match_the_code(strict_db: Database) -> None:
    """FusionMode, Side and SuppressionReason: the DBC's value tables use the enums' names."""
    for message, signal, enum in (
        (RP_ALERT, "AlertFusionMode", FusionMode),
        (RP_STATUS, "StatusFusionMode", FusionMode),
        (RP_ALERT, "AlertSide", Side),
        (RP_CONFIRM, "ConfirmOutcome", Confirmation),
        (RP_ALERT_END, "EndReason", EndReason),
        (RP_ALERT_END, "EndCauseEx", EndCause),  # the full cause (version 2)
    ):
        choices = strict_db.get_message_by_name(message).get_signal_by_name(signal).choices
        assert choices is not None
        assert {int(k): str(v) for k, v in choices.items()} == {int(e): e.name for e in enum}
    # the 2-bit EndCause of version 1 has the causes that fit it
    v1 = strict_db.get_message_by_name(RP_ALERT_END).get_signal_by_name("EndCause").choices
    assert v1 is not None
    assert {int(k): str(v) for k, v in v1.items()} == {int(e): e.name for e in EndCause if e <= 3}
    supp = strict_db.get_message_by_name(RP_STATUS).get_signal_by_name("StatusSuppression")
    assert supp.choices is not None
    assert str(supp.choices[int(SuppressionReason.LEAD_ACCEL)]) == "LEAD_ACCEL"
    assert str(supp.choices[int(SuppressionReason.DEGRADED)]) == "DEGRADED"
    det = strict_db.get_message_by_name(RP_ALERT_DETAIL).get_signal_by_name("DetailDetector")
    assert det.choices is not None
    assert {str(v): int(k) for k, v in det.choices.items()} == {
        name.upper().replace("-", "_"): code for name, code in DETECTOR_CODES.items()
    }


def test_e2e_counters_advance_and_crcs_check_with_autosar_e2e(strict_db: Database) -> None:
    frames = alert_frames(_random_alerts(40), OutputEncoders())
    alerts = [f for f in frames if f.arbitration_id == 0x200]
    details = [f for f in frames if f.arbitration_id == 0x203]
    assert len(alerts) == len(details) == 40
    for own in (alerts, details):  # one counter per message
        counters = [f.data[1] & 0x0F for f in own]
        assert counters == [k % E2E_COUNTER_MODULUS for k in range(40)]  # 0..14, 0..14, ...
    conf_enc = ConfirmEncoder()
    confirms = [conf_enc.encode(c, 0.5) for c in _random_confirmations(20)]
    assert [f.data[1] & 0x0F for f in confirms] == [k % 15 for k in range(20)]
    status = StatusEncoder()
    road = RoadStatusEncoder()
    statuses = _random_statuses(20)
    sframes = [status.encode(s) for s in statuses]
    rframes = [road.encode(s) for s in statuses]
    assert [f.data[1] & 0x0F for f in sframes] == [k % 15 for k in range(20)]
    assert [f.data[1] & 0x0F for f in rframes] == [k % 15 for k in range(20)]
    end_enc = AlertEndEncoder()
    ends = [end_enc.encode(e) for e in _random_ends(20)]
    assert [f.data[1] & 0x0F for f in ends] == [k % 15 for k in range(20)]
    ids = {
        0x200: alerts,
        0x201: sframes,
        0x202: rframes,
        0x203: details,
        0x204: confirms,
        0x205: ends,
    }
    for data_id, own in ids.items():
        for f in own:
            assert f.arbitration_id == data_id
            assert e2e.p01.e2e_p01_check(bytearray(f.data), data_id)
            for other in set(ids) - {data_id}:  # the same bytes under another data ID fail
                assert not e2e.p01.e2e_p01_check(bytearray(f.data), other), (data_id, other)


def test_a_corrupted_frame_fails_the_check_and_is_dropped_by_the_receiver() -> None:
    frames = [f for f in alert_frames(_random_alerts(6)) if f.arbitration_id == 0x200]
    rx = OutputDecoder()
    for i in range(8):
        for bit in (0x01, 0x10, 0x80):
            bad = bytearray(frames[0].data)
            bad[i] ^= bit
            assert not e2e.p01.e2e_p01_check(bad, 0x200), (i, bit)
    broken = frames[2]
    broken.data = bytearray(broken.data)
    broken.data[4] ^= 0x20
    got = [rx.decode(f) for f in frames]
    assert got[2] is None
    assert all(isinstance(g, ReceivedAlert) for k, g in enumerate(got) if k != 2)
    assert rx.problems == {"crc": 1}
    assert rx.lost == 1  # counter jumped from 1 to 3
    assert rx.decode(frames[5]) is None  # the same frame again: a repeated counter
    assert rx.problems["counter_repeated"] == 1


def test_receiver_gets_back_what_was_sent() -> None:
    send = _random_sends(1, seed=4)[0]
    alert = send.alert
    got = OutputDecoder().decode(AlertEncoder().encode(send))
    assert isinstance(got, ReceivedAlert)
    assert got.t_rx_s == send.t_s
    assert got.alert_id == send.can_id
    assert got.distance_m == pytest.approx(send.distance_m, abs=0.1)
    assert got.time_to_arrival_s == pytest.approx(send.time_to_arrival_s, abs=0.01)
    assert got.height_mm == pytest.approx(alert.height_mm, abs=1.0)
    assert got.length_m == pytest.approx(alert.length_m, abs=0.05)
    assert got.confidence == pytest.approx(alert.confidence, abs=0.02)
    assert got.side == alert.side
    assert got.mode == alert.mode
    assert got.time_to_arrival_s is not None
    assert got.arrival_t_s == pytest.approx(send.t_s + got.time_to_arrival_s)
    status = _random_statuses(1, seed=9)[0]
    back = OutputDecoder().decode(StatusEncoder().encode(status, timestamp=5.0))
    assert isinstance(back, ReceivedStatus)
    assert back.t_rx_s == 5.0
    assert back.pitch_rad == pytest.approx(status.pitch_rad, abs=0.0025 * DEG)
    assert back.time_offset_s == pytest.approx(status.time_offset_s, abs=0.0005)
    assert back.suppressed == status.suppressed


def test_receiver_gets_back_details_confirmations_and_road_status() -> None:
    rx = OutputDecoder()
    enc = AlertDetailEncoder()
    for k, send in enumerate(_random_sends(50, seed=10)):
        detector = ("std", "two-axle")[k % 2]
        alert = send.alert
        d = rx.decode(enc.encode(send, detector))
        assert isinstance(d, ReceivedAlertDetail)
        assert d.alert_id == send.can_id
        assert d.detector == detector
        assert d.t_rx_s == send.t_s
        assert d.height_std_mm == pytest.approx(alert.height_std_mm, abs=1.0)
        assert d.crossing_age_s == pytest.approx(send.age_s, abs=0.05)
        assert d.score == pytest.approx(alert.severity_px, abs=0.1)
        assert d.lead_speed_mps == pytest.approx(alert.lead_speed_mps, abs=0.25 * KMH)
    conf = ConfirmEncoder()
    for k, result in enumerate(_random_confirmations(50, seed=11)):
        precision = k / 49
        c = rx.decode(conf.encode(result, precision))
        assert isinstance(c, ReceivedConfirm)
        assert c.alert_id == result.alert_id % 256
        assert c.outcome == result.outcome
        assert c.t_rx_s == result.t_s
        assert c.peak_mps2 == pytest.approx(result.peak_mps2, abs=0.01)
        assert c.background_mps2 == pytest.approx(result.background_mps2, abs=0.01)
        assert c.arrival_age_s == pytest.approx(result.t_s - result.t_arrival_s, abs=0.01)
        assert c.t_arrival_s == pytest.approx(result.t_arrival_s, abs=0.01)
        assert c.precision == pytest.approx(precision, abs=0.005)
    road = RoadStatusEncoder()
    for k, status in enumerate(_random_statuses(50, seed=12)):
        r = rx.decode(road.encode(status, timestamp=float(k)))
        assert isinstance(r, ReceivedRoadStatus)
        assert status.road is not None
        assert r.t_rx_s == float(k)
        assert (r.iso_class, r.ego_class, r.lead_class) == (
            status.road.iso_class,
            status.road.ego_class,
            status.road.lead_class,
        )
        for got_gd, sent_gd in (
            (r.ego_gd_n0, status.road.ego_gd_n0),
            (r.lead_gd_n0, status.road.lead_gd_n0),
        ):
            assert got_gd is not None
            want_db = min(max(_db_gd(sent_gd), 0.0), 63.5)
            assert _db_gd(got_gd) == pytest.approx(want_db, abs=0.125 + 1e-9)
        assert r.precision == pytest.approx(status.precision, abs=0.005)
        assert (r.confirmed, r.not_felt) == (status.confirmed % 256, status.not_felt % 256)
    assert rx.problems == {}
    assert rx.lost == 0


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log", ".trc", ".csv"])
def test_alerts_written_to_a_log_read_back(tmp_path: Path, suffix: str) -> None:
    alerts = _random_alerts(20)
    alerts = [
        Alert(
            **{
                **{f: getattr(a, f) for f in a.__dataclass_fields__},
                "t_s": 1.7e9 + k,
                "t_emit_s": 1.7e9 + k + 0.9,
            }
        )
        for k, a in enumerate(alerts)
    ]
    frames = alert_frames(alerts, detector="std")
    path = tmp_path / f"alerts{suffix}"
    assert write_can_log(path, frames) == 40
    rx = OutputDecoder()
    back = [rx.decode(m) for m in read_can_log(path, errors="raise")]
    # RP_ALERT, then its RP_ALERT_DETAIL with the same id, for each alert in order
    assert [type(b) for b in back] == [ReceivedAlert, ReceivedAlertDetail] * 20
    heads = [b for b in back[::2] if isinstance(b, ReceivedAlert)]
    details = [b for b in back[1::2] if isinstance(b, ReceivedAlertDetail)]
    assert [b.t_rx_s for b in heads] == pytest.approx([a.t_emit_s for a in alerts], abs=2e-6)
    assert [b.alert_id for b in heads] == [a.alert_id % 256 for a in alerts]
    assert [b.alert_id for b in details] == [a.alert_id % 256 for a in alerts]
    assert {b.detector for b in details} == {"std"}
    assert rx.problems == {}


def test_status_input_errors_count_since_the_previous_frame(strict_db: Database) -> None:
    enc = StatusEncoder()
    msg_def = strict_db.get_message_by_name(RP_STATUS)
    sent = []
    for total in (0, 3, 3, 10, 40, 41):
        frame = enc.encode(Status(mode=FusionMode.FUSED, input_errors_total=total))
        sent.append(
            _signals(msg_def.decode(bytes(frame.data), decode_choices=False))["StatusInputErrors"]
        )
    assert sent == [0, 3, 0, 7, 15, 1]  # 30 new errors saturate at 15
