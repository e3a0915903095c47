"""The project DBC: loads strictly, is fully documented, and every simulated frame decodes back."""

from __future__ import annotations

import os
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from cantools.database.can import Database
from cantools.typechecking import DecodeResultType, SignalDictType

from roadpreview.canbus.dbc import (
    E2E_COUNTER_MODULUS,
    IMU_ACCEL,
    IMU_RATES,
    RESERVED_OUTPUT_IDS,
    RP_ALERT,
    RP_ALERT_DETAIL,
    RP_ALERT_END,
    RP_CONFIRM,
    RP_INPUT_STATUS,
    RP_PREVIEW,
    RP_ROAD_STATUS,
    RP_STATUS,
    VEHICLE_SPEED,
    WHEEL_SPEEDS,
    check_protected,
    e2e_layout,
    encode_protected,
    load_database,
)
from roadpreview.canbus.samples import ImuMeasurements
from roadpreview.errors import InputDataError
from roadpreview.preview import PreviewConfig
from roadpreview.sim.canlog import (
    DEFAULT_T0_UNIX_S,
    imu_to_messages,
    merge_on_bus,
    speed_to_messages,
)
from roadpreview.sim.imu import (
    DEG,
    KMH,
    ImuConfig,
    ImuSamples,
    SpeedSamples,
    SpeedSensorConfig,
    simulate_imu,
    simulate_speed,
)

ROOT = Path(__file__).resolve().parents[2]
REPO_DBC = ROOT / "data" / "roadpreview.dbc"


def _crc8_j1850(data: bytes, init: int = 0x00) -> int:
    """CRC-8 SAE J1850 (poly 0x1D), no final XOR; E2E P01 chains it from start 0x00."""
    crc = init
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def _p01_crc(data_id: int, payload: bytes) -> int:
    return _crc8_j1850(bytes([data_id & 0xFF, data_id >> 8]) + payload[1:])


@pytest.fixture(scope="module")
def db() -> Database:
    return load_database()


@pytest.fixture(scope="module")
def imu_samples() -> ImuSamples:
    t = np.arange(0.0, 3.0005, 0.001)
    zeros = np.zeros_like(t)
    omega = np.column_stack(
        [
            0.3 * np.sin(3 * t),
            0.5 * np.sin(5 * t),
            1.2 * np.sin(1.1 * t),  # up to ~70 deg/s
        ]
    )
    acc = np.column_stack([2 * np.sin(t), 3 * np.cos(2 * t), 4 * np.sin(7 * t)])
    att = np.column_stack([0.05 * np.sin(t), 0.03 * np.sin(2 * t), zeros])
    return simulate_imu(t, omega, acc, att, ImuConfig.smartphone(), np.random.default_rng(11))


@pytest.fixture(scope="module")
def speed_samples() -> SpeedSamples:
    t = np.arange(0.0, 3.0005, 0.001)
    v = np.interp(t, [0, 0.5, 1.0, 3.0], [0.0, 0.0, 30.0, 70.0])  # up to 252 km/h
    wheels = np.column_stack([v * 1.01, v * 0.99, v, v * 1.002])
    return simulate_speed(t, v, SpeedSensorConfig(), np.random.default_rng(12), wheels)


# --- the file ---------------------------------------------------------------------------------


def test_repo_copy_is_a_relative_symlink_to_the_packaged_dbc() -> None:
    assert REPO_DBC.is_symlink()
    assert not os.path.isabs(os.readlink(REPO_DBC))
    packaged = ROOT / "src" / "roadpreview" / "data" / "roadpreview.dbc"
    assert REPO_DBC.resolve() == packaged.resolve()


def test_loads_strict_with_cantools(db: Database) -> None:
    direct = cantools.database.load_file(REPO_DBC, strict=True)
    assert isinstance(direct, Database)
    assert sorted(m.name for m in direct.messages) == sorted(m.name for m in db.messages)
    assert load_database(REPO_DBC).get_message_by_name(IMU_RATES).frame_id == 0x130


def test_messages_are_complete_and_in_the_documented_ranges(db: Database) -> None:
    inputs = {IMU_RATES: 0x130, IMU_ACCEL: 0x131, VEHICLE_SPEED: 0x140, WHEEL_SPEEDS: 0x141}
    outputs = {
        RP_ALERT: 0x200,
        RP_STATUS: 0x201,
        RP_ROAD_STATUS: 0x202,
        RP_ALERT_DETAIL: 0x203,
        RP_CONFIRM: 0x204,
        RP_ALERT_END: 0x205,
        RP_INPUT_STATUS: 0x206,
        RP_PREVIEW: 0x207,
    }
    assert {m.name: m.frame_id for m in db.messages} == inputs | outputs
    for m in db.messages:
        assert not m.is_extended_frame
        assert m.frame_id < 0x800
        if m.name in inputs:
            assert 0x130 <= m.frame_id <= 0x14F
            assert m.frame_id not in RESERVED_OUTPUT_IDS
            assert m.cycle_time in (10, 20)
            assert m.senders in (["IMU"], ["ESC"])
        else:  # only roadpreview's outputs live in the reserved range
            assert m.frame_id in RESERVED_OUTPUT_IDS
            assert m.senders == ["ROADPREVIEW"]
        assert m.length == 8
        assert m.comment
        # per multiplexer value (RP_PREVIEW's pages): the signals of one frame fit its 64 bits
        for mux in {i for s in m.signals for i in s.multiplexer_ids or [-1]}:  # -1: plain
            here = [s for s in m.signals if s.multiplexer_ids is None or mux in s.multiplexer_ids]
            assert sum(s.length for s in here) <= 64, (m.name, mux)
        layout = e2e_layout(m)
        assert layout.data_id == m.frame_id
        for s in m.signals:
            assert s.comment, f"{m.name}.{s.name} has no comment"
            assert s.minimum is not None
            assert s.maximum is not None
            if s.scale != 1:
                assert s.unit, f"{m.name}.{s.name} has no unit"
            assert s.byte_order == "little_endian"
    for cyclic in (RP_STATUS, RP_ROAD_STATUS):
        assert db.get_message_by_name(cyclic).cycle_time == 100
        assert db.get_message_by_name(cyclic).send_type == "Cyclic"
    # every 100 ms while an alert is active / the inputs have problems; a preview every
    # 200 ms (`[preview] period_s`) while one exists
    for repeated, cycle in (
        (RP_ALERT, 100),
        (RP_ALERT_DETAIL, 100),
        (RP_INPUT_STATUS, 100),
        (RP_PREVIEW, round(1000 * PreviewConfig().period_s)),
    ):
        assert db.get_message_by_name(repeated).cycle_time == cycle
        assert db.get_message_by_name(repeated).send_type == "IfActive"
    for event in (RP_CONFIRM, RP_ALERT_END):
        assert db.get_message_by_name(event).send_type == "Event"
        assert not db.get_message_by_name(event).cycle_time


def test_the_top_comment_lists_every_output_id() -> None:
    text = REPO_DBC.read_text()
    top = next(line for line in text.splitlines() if line.startswith('CM_ "'))
    for name, fid in (
        (RP_ALERT, 0x200),
        (RP_STATUS, 0x201),
        (RP_ROAD_STATUS, 0x202),
        (RP_ALERT_DETAIL, 0x203),
        (RP_CONFIRM, 0x204),
        (RP_ALERT_END, 0x205),
        (RP_INPUT_STATUS, 0x206),
        (RP_PREVIEW, 0x207),
    ):
        assert f"0x{fid:03X} {name}" in top, name


# the output layouts a chassis ECU is built against: (start, length, signed, scale, min, max,
# raw value meaning "not available" or None)
OUTPUT_LAYOUTS: dict[str, dict[str, tuple[int, int, bool, float, float, float, int | None]]] = {
    RP_ALERT: {
        "AlertSide": (12, 2, False, 1, 0, 3, None),
        "AlertFusionMode": (14, 2, False, 1, 0, 3, None),
        "AlertId": (16, 8, False, 1, 0, 255, None),
        "AlertDistance": (24, 10, True, 0.2, -102.2, 102.2, -512),
        "AlertTimeToArrival": (34, 10, True, 0.02, -10.22, 10.22, -512),
        "AlertHeight": (44, 9, True, 2, -510, 510, -256),
        "AlertLength": (53, 6, False, 0.1, 0, 6.2, 63),
        "AlertConfidence": (59, 5, False, 4, 0, 100, 31),
    },
    RP_ALERT_DETAIL: {
        "DetailDetector": (12, 2, False, 1, 0, 1, None),
        "AlertState": (14, 2, False, 1, 0, 1, None),  # version 2
        "AlertId": (16, 8, False, 1, 0, 255, None),
        "AlertHeightStd": (24, 6, False, 2, 0, 124, 63),
        "AlertScore": (30, 8, False, 0.2, 0, 50.8, 255),
        "AlertLeadSpeed": (38, 8, False, 0.5, 0, 127, 255),
        "AlertCrossingAge": (46, 8, False, 0.1, 0, 25.4, 255),
    },
    RP_ALERT_END: {
        "EndReason": (12, 2, False, 1, 0, 1, None),
        "EndCause": (14, 2, False, 1, 0, 3, None),
        "EndAlertId": (16, 8, False, 1, 0, 255, None),
        "EndAlertSends": (24, 8, False, 1, 0, 255, None),
        "EndDistance": (32, 10, True, 0.2, -102.2, 102.2, -512),
        "EndCauseEx": (42, 3, False, 1, 0, 4, None),  # version 2
    },
    RP_CONFIRM: {
        "ConfirmOutcome": (12, 2, False, 1, 0, 2, None),
        "ConfirmAlertId": (16, 8, False, 1, 0, 255, None),
        "ConfirmPeakAccel": (24, 10, False, 0.02, 0, 20.44, 1023),
        "ConfirmBackgroundAccel": (34, 8, False, 0.02, 0, 5.08, 255),
        "ConfirmArrivalAge": (42, 8, False, 0.02, 0, 5.08, 255),
        "ConfirmPrecision": (50, 7, False, 1, 0, 100, 127),
    },
    RP_ROAD_STATUS: {
        "RoadClass": (12, 4, False, 1, 0, 8, None),
        "RoadClassEgo": (16, 4, False, 1, 0, 8, None),
        "RoadClassLead": (20, 4, False, 1, 0, 8, None),
        "RoadGdEgo": (24, 8, False, 0.25, 0, 63.5, 255),
        "RoadGdLead": (32, 8, False, 0.25, 0, 63.5, 255),
        "OnlinePrecision": (40, 7, False, 1, 0, 100, 127),
        "ConfirmedCount": (47, 8, False, 1, 0, 255, None),
        "NotFeltCount": (55, 8, False, 1, 0, 255, None),
    },
}


@pytest.mark.parametrize("name", sorted(OUTPUT_LAYOUTS))
def test_output_layouts_are_as_specified(db: Database, name: str) -> None:
    m = db.get_message_by_name(name)
    e2e = {s.name for s in m.signals if s.name.endswith(("_CRC", "_Counter"))}
    assert len(e2e) == 2
    assert {s.name for s in m.signals} - e2e == set(OUTPUT_LAYOUTS[name])
    for signal, (start, length, signed, scale, lo, hi, na) in OUTPUT_LAYOUTS[name].items():
        s = m.get_signal_by_name(signal)
        got = (s.start, s.length, s.is_signed, s.scale, s.minimum, s.maximum)
        assert got == pytest.approx((start, length, signed, scale, lo, hi)), signal
        named = {int(k): str(v) for k, v in (s.choices or {}).items()}
        if na is None:
            assert "SignalNotAvailable" not in named.values(), signal
        else:
            assert named.get(na) == "SignalNotAvailable", signal
            assert na not in range(round(lo / scale), round(hi / scale) + 1), signal


def test_every_message_and_signal_is_in_the_interface_doc(db: Database) -> None:
    """Each message has its section, whose table has a row per signal with its layout."""
    doc = (ROOT / "docs" / "can-interface.md").read_text(encoding="utf-8")
    for m in db.messages:
        assert m.name in doc
        heading = f"### 0x{m.frame_id:03X} `{m.name}`"
        assert heading in doc, heading
        section = doc.split(heading, 1)[1].split("\n### ", 1)[0]
        for s in m.signals:
            row = f"| `{s.name}` | {s.start} | {s.length} | "
            assert row in section, f"{m.name}.{s.name}: no row {row!r} in its section"


def test_pitch_rate_sign_is_documented_in_the_dbc(db: Database) -> None:
    comment = db.get_message_by_name(IMU_RATES).get_signal_by_name("PitchRate").comment
    assert comment is not None
    assert "NOSE RISES" in comment
    assert "MINUS omega_y" in comment


def test_a_broken_dbc_is_reported_with_its_path(tmp_path: Path) -> None:
    bad = tmp_path / "bad.dbc"
    bad.write_text(REPO_DBC.read_text().replace("SG_ PitchRate : 32|16", "SG_ PitchRate : 30|16"))
    with pytest.raises(InputDataError, match=r"bad\.dbc"):
        load_database(bad)


# --- E2E ------------------------------------------------------------------------------------


def test_e2e_crc_matches_an_independent_j1850(db: Database) -> None:
    m = db.get_message_by_name(IMU_RATES)
    data = encode_protected(m, {"RollRate": 1.0, "PitchRate": -2.5, "YawRate": 10.0}, 7)
    assert data[0] == _p01_crc(0x130, data)
    assert data[1] & 0x0F == 7
    # the helper itself: CRC-8/SAE-J1850 (init 0xFF, xorout 0xFF) has the check value 0x4B
    assert _crc8_j1850(b"123456789", 0xFF) ^ 0xFF == 0x4B


def test_a_corrupted_byte_or_wrong_message_fails_the_check(db: Database) -> None:
    m = db.get_message_by_name(VEHICLE_SPEED)
    data = encode_protected(m, {"VehicleSpeed": 50.0, "MovingDirection": 1}, 3)
    assert check_protected(m, data)
    for i in range(8):
        for bit in (0x01, 0x80):
            broken = bytearray(data)
            broken[i] ^= bit
            assert not check_protected(m, broken), (i, bit)
    # the same bytes claimed by another message (different data ID) fail as well
    assert not check_protected(db.get_message_by_name(WHEEL_SPEEDS), data)


# --- the simulator's frames -----------------------------------------------------------------


def _signals(decoded: DecodeResultType) -> SignalDictType:
    """cantools decodes a plain (non-container) message to a signal dict: narrow to it."""
    assert isinstance(decoded, dict)
    return decoded


def _decode_all(db: Database, frames: list[can.Message], name: str) -> list[SignalDictType]:
    msg = db.get_message_by_name(name)
    out = []
    for f in frames:
        if f.arbitration_id != msg.frame_id:
            continue
        assert check_protected(msg, f.data), f"{name}: bad CRC"
        out.append(_signals(msg.decode(bytes(f.data), decode_choices=False)))
    return out


def _assert_counters(decoded: list[SignalDictType], signal: str) -> None:
    counters = np.array([d[signal] for d in decoded])
    assert counters.max() == E2E_COUNTER_MODULUS - 1
    np.testing.assert_array_equal(np.diff(counters) % E2E_COUNTER_MODULUS, 1)
    assert counters[0] == 0


def test_imu_frames_decode_to_the_samples(db: Database, imu_samples: ImuSamples) -> None:
    frames = imu_to_messages(imu_samples, db)
    assert len(frames) == 2 * len(imu_samples)
    assert all(f.channel == 0 and not f.is_extended_id and f.dlc == 8 for f in frames)
    rates = _decode_all(db, frames, IMU_RATES)
    accel = _decode_all(db, frames, IMU_ACCEL)
    assert len(rates) == len(accel) == len(imu_samples)
    got = np.array([[d["RollRate"], d["PitchRate"], d["YawRate"]] for d in rates], dtype=float)
    want = imu_samples.rates_rad_s / DEG
    assert np.abs(want).max() > 20  # real dynamics, not zeros
    np.testing.assert_allclose(got, want, rtol=0, atol=0.005)  # one LSB
    # nose-up pitch is positive on the bus: the sensor's y rate with its sign flipped
    np.testing.assert_allclose(got[:, 1], -imu_samples.gyro_rad_s[:, 1] / DEG, atol=0.005)
    got_a = np.array([[d["AccelX"], d["AccelY"], d["AccelZ"]] for d in accel], dtype=float)
    np.testing.assert_allclose(got_a, imu_samples.accel_m_s2, rtol=0, atol=0.001)
    _assert_counters(rates, "ImuRates_Counter")
    _assert_counters(accel, "ImuAccel_Counter")
    times = np.array([f.timestamp for f in frames[::2]])
    np.testing.assert_allclose(times - DEFAULT_T0_UNIX_S, imu_samples.t_stamp_s, atol=1e-6)


def test_speed_frames_decode_to_the_samples(db: Database, speed_samples: SpeedSamples) -> None:
    frames = speed_to_messages(speed_samples, db)
    speed = _decode_all(db, frames, VEHICLE_SPEED)
    wheels = _decode_all(db, frames, WHEEL_SPEEDS)
    assert len(speed) == len(wheels) == len(speed_samples)
    kmh = np.array([d["VehicleSpeed"] for d in speed], dtype=float)
    np.testing.assert_allclose(kmh, speed_samples.speed_m_s / KMH, rtol=0, atol=0.01)
    assert [d["MovingDirection"] for d in speed] == list(speed_samples.direction)
    assert {0, 1} <= set(speed_samples.direction.tolist())
    got_w = np.array(
        [[d[f"WheelSpeed{w}"] for w in ("FL", "FR", "RL", "RR")] for d in wheels], dtype=float
    )
    np.testing.assert_allclose(got_w, speed_samples.wheel_speeds_m_s / KMH, rtol=0, atol=0.03125)
    assert got_w.max() > 240
    _assert_counters(speed, "VehicleSpeed_Counter")
    _assert_counters(wheels, "WheelSpeeds_Counter")


def test_out_of_range_values_are_clipped_and_nan_is_signal_not_available(db: Database) -> None:
    m = db.get_message_by_name(IMU_RATES)
    t = np.arange(3, dtype=np.float64) * 0.01
    gyro = np.array([[400 * DEG, 0, 0], [0, np.nan, 0], [-400 * DEG, 0, 0]])
    frames = imu_to_messages(ImuMeasurements(t, gyro, np.zeros((3, 3))), db)
    decoded = [_signals(m.decode(bytes(f.data))) for f in frames if f.arbitration_id == m.frame_id]
    assert decoded[0]["RollRate"] == pytest.approx(163.835)
    assert decoded[2]["RollRate"] == pytest.approx(-163.835)
    assert str(decoded[1]["PitchRate"]) == "SignalNotAvailable"


def test_bus_merge_orders_and_spaces_frames(
    db: Database, imu_samples: ImuSamples, speed_samples: SpeedSamples
) -> None:
    imu = imu_to_messages(imu_samples, db)
    spd = speed_to_messages(speed_samples, db)
    queued = {id(f): f.timestamp for f in imu + spd}
    merged = merge_on_bus([imu, spd], bitrate=500_000)
    assert len(merged) == len(imu) + len(spd)
    t = np.array([f.timestamp for f in merged])
    frame_s = 111 / 500_000
    assert np.all(np.diff(t) >= frame_s - 1e-6)  # one frame at a time on the wire (float µs)
    delay = np.array([f.timestamp - queued[id(f)] for f in merged])
    assert delay.min() == pytest.approx(frame_s, abs=1e-6)
    assert delay.max() < 5 * frame_s
