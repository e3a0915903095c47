"""RP_ALERT / RP_STATUS: cantools (strict) decodes what we encode, E2E counters and CRCs check."""

from __future__ import annotations

import math
from pathlib import Path

import cantools
import e2e.p01
import numpy as np
import pytest
from cantools.database.can import Database

from roadpreview.anomaly import Alert, Side, SuppressionReason
from roadpreview.canbus import (
    E2E_COUNTER_MODULUS,
    RP_ALERT,
    RP_STATUS,
    AlertEncoder,
    OutputDecoder,
    ReceivedAlert,
    ReceivedStatus,
    Status,
    StatusEncoder,
    alert_frames,
    read_can_log,
    write_can_log,
)
from roadpreview.fusion.mode import FusionMode

REPO_DBC = Path(__file__).resolve().parents[2] / "data" / "roadpreview.dbc"
DEG = math.pi / 180


@pytest.fixture(scope="module")
def strict_db() -> Database:
    """The DBC loaded by cantools itself, strictly: the receiver's view, not our loader's."""
    db = cantools.database.load_file(REPO_DBC, strict=True)
    assert isinstance(db, Database)
    return db


def _random_alerts(n: int, seed: int = 0) -> list[Alert]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        t = 100.0 + k
        out.append(
            Alert(
                t_s=t,
                t_emit_s=t + float(rng.uniform(0, 3.1)),
                distance_m=float(rng.uniform(0, 204.4)),
                time_to_arrival_s=float(rng.uniform(0, 20.44)),
                severity_px=float(rng.uniform(0, 51)),
                height_mm=float(rng.uniform(0, 508)),
                side=Side(int(rng.integers(0, 4))),
                confidence=float(rng.uniform(0, 1)),
                mode=FusionMode(int(rng.integers(0, 4))),
            )
        )
    return out


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
        )
        for _ in range(n)
    ]


def _lsb(db: Database, message: str, signal: str) -> float:
    return float(db.get_message_by_name(message).get_signal_by_name(signal).scale)


def test_alerts_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = AlertEncoder()
    msg_def = strict_db.get_message_by_name(RP_ALERT)
    for alert in _random_alerts(300):
        frame = enc.encode(alert)
        assert frame.arbitration_id == 0x200
        assert frame.dlc == 8
        assert not frame.is_extended_id
        got = msg_def.decode(frame.data, decode_choices=False)
        want = {
            "AlertDistance": alert.distance_m,
            "AlertTimeToArrival": alert.time_to_arrival_s,
            "AlertSeverity": alert.severity_px,
            "AlertHeight": alert.height_mm,
            "AlertConfidence": 100 * alert.confidence,
            "AlertEventAge": alert.t_emit_s - alert.t_s,
        }
        for name, value in want.items():
            lsb = _lsb(strict_db, RP_ALERT, name)
            assert got[name] == pytest.approx(value, abs=lsb / 2 + 1e-9), name
        assert got["AlertSide"] == int(alert.side)
        assert got["AlertFusionMode"] == int(alert.mode)


def test_statuses_decode_with_cantools_to_the_same_values(strict_db: Database) -> None:
    enc = StatusEncoder()
    msg_def = strict_db.get_message_by_name(RP_STATUS)
    for status in _random_statuses(300):
        new_errors = status.input_errors_total - enc.errors_sent
        if new_errors < 0:  # a lower total: the count restarted
            new_errors = status.input_errors_total
        got = msg_def.decode(enc.encode(status).data, decode_choices=False)
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
    alert = Alert(
        t_s=1.0,
        t_emit_s=9.0,  # 8 s old: beyond 3.1 s
        distance_m=None,
        time_to_arrival_s=None,
        severity_px=80.0,  # beyond 51 px
        height_mm=None,
        side=Side.LEFT,
        confidence=1.0,
        mode=FusionMode.IMU_ONLY,
    )
    got = strict_db.get_message_by_name(RP_ALERT).decode(enc.encode(alert).data)
    assert str(got["AlertDistance"]) == "SignalNotAvailable"
    assert str(got["AlertTimeToArrival"]) == "SignalNotAvailable"
    assert str(got["AlertHeight"]) == "SignalNotAvailable"
    assert got["AlertSeverity"] == pytest.approx(51.0)
    assert got["AlertEventAge"] == pytest.approx(3.1)
    assert str(got["AlertSide"]) == "LEFT"
    assert str(got["AlertFusionMode"]) == "IMU_ONLY"
    assert enc.saturated == {"AlertSeverity": 1, "AlertEventAge": 1}
    status = StatusEncoder().encode(Status(mode=FusionMode.DEGRADED))
    got = strict_db.get_message_by_name(RP_STATUS).decode(status.data)
    for name in ("StatusPitch", "StatusGyroBias", "StatusTextureQuality", "StatusTimeOffset"):
        assert str(got[name]) == "SignalNotAvailable", name


def test_enum_values_on_can_match_the_code(strict_db: Database) -> None:
    """FusionMode, Side and SuppressionReason: the DBC's value tables use the enums' names."""
    for message, signal, enum in (
        (RP_ALERT, "AlertFusionMode", FusionMode),
        (RP_STATUS, "StatusFusionMode", FusionMode),
        (RP_ALERT, "AlertSide", Side),
    ):
        choices = strict_db.get_message_by_name(message).get_signal_by_name(signal).choices
        assert choices is not None
        assert {int(k): str(v) for k, v in choices.items()} == {int(e): e.name for e in enum}
    supp = strict_db.get_message_by_name(RP_STATUS).get_signal_by_name("StatusSuppression")
    assert supp.choices is not None
    assert str(supp.choices[int(SuppressionReason.LEAD_ACCEL)]) == "LEAD_ACCEL"
    assert str(supp.choices[int(SuppressionReason.DEGRADED)]) == "DEGRADED"


def test_e2e_counters_advance_and_crcs_check_with_autosar_e2e(strict_db: Database) -> None:
    enc = AlertEncoder()
    frames = alert_frames(_random_alerts(40), enc)
    counters = [f.data[1] & 0x0F for f in frames]
    assert counters == [k % E2E_COUNTER_MODULUS for k in range(40)]  # 0..14, 0..14, ...
    for f in frames:
        assert e2e.p01.e2e_p01_check(bytearray(f.data), 0x200)
        assert not e2e.p01.e2e_p01_check(bytearray(f.data), 0x201)  # wrong data ID
    status = StatusEncoder()
    sframes = [status.encode(s) for s in _random_statuses(20)]
    assert [f.data[1] & 0x0F for f in sframes] == [k % 15 for k in range(20)]
    assert all(e2e.p01.e2e_p01_check(bytearray(f.data), 0x201) for f in sframes)


def test_a_corrupted_frame_fails_the_check_and_is_dropped_by_the_receiver() -> None:
    frames = alert_frames(_random_alerts(6))
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
    alert = _random_alerts(1, seed=4)[0]
    got = OutputDecoder().decode(AlertEncoder().encode(alert))
    assert isinstance(got, ReceivedAlert)
    assert got.distance_m == pytest.approx(alert.distance_m, abs=0.1)
    assert got.time_to_arrival_s == pytest.approx(alert.time_to_arrival_s, abs=0.01)
    assert got.event_age_s == pytest.approx(alert.t_emit_s - alert.t_s, abs=0.025)
    assert got.confidence == pytest.approx(alert.confidence, abs=0.01)
    assert got.side == alert.side
    assert got.mode == alert.mode
    assert got.time_left_s == pytest.approx(got.time_to_arrival_s - got.event_age_s)  # type: ignore[operator]
    status = _random_statuses(1, seed=9)[0]
    back = OutputDecoder().decode(StatusEncoder().encode(status, timestamp=5.0))
    assert isinstance(back, ReceivedStatus)
    assert back.t_rx_s == 5.0
    assert back.pitch_rad == pytest.approx(status.pitch_rad, abs=0.0025 * DEG)
    assert back.time_offset_s == pytest.approx(status.time_offset_s, abs=0.0005)
    assert back.suppressed == status.suppressed


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
    frames = alert_frames(alerts)
    path = tmp_path / f"alerts{suffix}"
    assert write_can_log(path, frames) == 20
    rx = OutputDecoder()
    back = [rx.decode(m) for m in read_can_log(path, errors="raise")]
    assert all(isinstance(b, ReceivedAlert) for b in back)
    assert [b.t_rx_s for b in back] == pytest.approx([a.t_emit_s for a in alerts], abs=2e-6)  # type: ignore[union-attr]
    assert rx.problems == {}


def test_status_input_errors_count_since_the_previous_frame(strict_db: Database) -> None:
    enc = StatusEncoder()
    msg_def = strict_db.get_message_by_name(RP_STATUS)
    sent = []
    for total in (0, 3, 3, 10, 40, 41):
        frame = enc.encode(Status(mode=FusionMode.FUSED, input_errors_total=total))
        sent.append(msg_def.decode(frame.data, decode_choices=False)["StatusInputErrors"])
    assert sent == [0, 3, 0, 7, 15, 1]  # 30 new errors saturate at 15
