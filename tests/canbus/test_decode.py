"""Input decoding through a DBC and a mapping: values, conventions, bad frames never stop it."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from cantools.database.can import Database

from roadpreview.canbus import (
    QUANTITIES,
    CanInputDecoder,
    FrameProblem,
    available_mappings,
    decode_log,
    encode_protected,
    load_database,
    load_mapping,
    split_samples,
)
from roadpreview.canbus.decode import toyota_checksum_ok
from roadpreview.canbus.mapping import parse_mapping, replace_quantity
from roadpreview.errors import ConfigError
from roadpreview.sim.canlog import imu_to_messages, speed_to_messages
from roadpreview.sim.imu import (
    DEG,
    ImuConfig,
    ImuSamples,
    SpeedSensorConfig,
    simulate_imu,
    simulate_speed,
)
from roadpreview.types import ImuSample, SpeedSample

FILES = Path(__file__).resolve().parents[1] / "files"


@pytest.fixture(scope="module")
def db() -> Database:
    database: Database = load_database()  # roadpreview.canbus exports lazily: Any to mypy
    return database


def _sim_imu(seconds: float = 2.0) -> ImuSamples:
    t = np.arange(0.0, seconds, 0.001)
    n = len(t)
    omega = np.column_stack([0.2 * np.sin(3 * t), 0.3 * np.sin(5 * t), 0.5 * np.cos(t)])
    acc = np.column_stack([1.5 * np.sin(t), -0.8 * np.cos(2 * t), np.zeros(n)])
    att = np.zeros((n, 3))
    return simulate_imu(t, omega, acc, att, ImuConfig.automotive(), np.random.default_rng(3))


def test_shipped_mappings_are_listed() -> None:
    assert {"roadpreview", "toyota_rav4"} <= set(available_mappings())
    with pytest.raises(ConfigError, match="no shipped mapping 'nonexistent'"):
        load_mapping("nonexistent")


def test_simulated_imu_and_speed_decode_to_the_samples(db: Database) -> None:
    """roadpreview's own frames: rates in rad/s, pitch nose up +, accel, speed in m/s."""
    imu = _sim_imu()
    t = np.arange(0.0, 2.0, 0.001)
    speed = simulate_speed(t, 10 + 2 * t, SpeedSensorConfig(), np.random.default_rng(4))
    frames = sorted(
        imu_to_messages(imu, db) + speed_to_messages(speed, db), key=lambda m: m.timestamp
    )
    dec = CanInputDecoder(db, load_mapping("roadpreview"))
    samples, speeds = split_samples(dec.decode_all(frames))
    rates = np.array([s.rates_rad_s for s in samples if s.has_rates])
    accel = np.array([s.accel_m_s2 for s in samples if s.has_accel])
    assert len(rates) == len(accel) == len(imu)
    # one LSB of 0.005 deg/s, and PitchRate's sign: nose up + = minus the chip's y rate
    np.testing.assert_allclose(rates, imu.rates_rad_s, atol=0.005 * DEG / 2 + 1e-12)
    np.testing.assert_allclose(rates[:, 1], -imu.gyro_rad_s[:, 1], atol=0.005 * DEG)
    np.testing.assert_allclose(accel, imu.accel_m_s2, atol=0.0005 + 1e-12)
    v = np.array([s.speed_mps for s in speeds])
    np.testing.assert_allclose(v, speed.speed_m_s, atol=0.005 / 3.6 + 1e-12)
    assert dec.stats.problems == {}
    assert dec.stats.used == len(frames) - len(speed)  # WHEEL_SPEEDS is not mapped
    assert dec.stats.ignored == len(speed)
    assert dec.stats.lost == 0


def _foreign_db() -> Database:
    """A made-up car: one IMU message in SAE J670 axes (y right, z down), speed in mph."""
    text = """VERSION ""
NS_ :
BS_:
BU_: XXX
BO_ 100 CAR_IMU: 8 XXX
 SG_ GyroY : 0|16@1- (0.01,0) [-300|300] "deg/s" XXX
 SG_ GyroZ : 16|16@1- (0.01,0) [-300|300] "deg/s" XXX
 SG_ AccY : 32|16@1- (0.001,0) [-30|30] "m/s2" XXX
 SG_ AccZ : 48|16@1- (0.001,0) [-30|30] "m/s2" XXX
BO_ 101 CAR_SPEED: 2 XXX
 SG_ Speed : 0|16@1+ (0.01,0) [0|200] "mph" XXX
VAL_ 101 Speed 65535 "SNA" ;
"""
    db = cantools.database.load_string(text, database_format="dbc", strict=True)
    assert isinstance(db, Database)
    return db


_FOREIGN_MAPPING = {
    "mapping": {"name": "car", "frame": "sae_j670"},
    "quantities": {
        "roll_rate": {"missing": "no roll rate"},
        "pitch_rate": {"message": "CAR_IMU", "signal": "GyroY", "unit": "deg/s", "axis": "y"},
        "yaw_rate": {"message": "CAR_IMU", "signal": "GyroZ", "unit": "deg/s", "axis": "z"},
        "accel_x": {"missing": "no longitudinal acceleration"},
        "accel_y": {"message": "CAR_IMU", "signal": "AccY", "unit": "m/s^2", "axis": "y"},
        "accel_z": {"message": "CAR_IMU", "signal": "AccZ", "unit": "m/s2", "axis": "z"},
        "speed": {"message": "CAR_SPEED", "signal": "Speed", "unit": "mph", "range": [0, 150]},
    },
}


def test_sae_frame_and_units_convert_to_roadpreview_conventions() -> None:
    """SAE J670: +ω_y raises the nose (pitch +), +ω_z turns right (yaw -); y, z flip for accel."""
    fdb = _foreign_db()
    dec = CanInputDecoder(fdb, parse_mapping(_FOREIGN_MAPPING, "car.toml"))
    imu_def = fdb.get_message_by_name("CAR_IMU")
    data = imu_def.encode({"GyroY": 2.0, "GyroZ": 10.0, "AccY": 1.5, "AccZ": -9.81})
    [s] = dec.decode(
        can.Message(timestamp=1.0, arbitration_id=100, data=data, is_extended_id=False)
    )
    assert isinstance(s, ImuSample)
    assert math.isnan(s.rates_rad_s[0])  # declared missing
    assert s.pitch_rate_rad_s == pytest.approx(2.0 * DEG)
    assert s.rates_rad_s[2] == pytest.approx(-10.0 * DEG)
    assert s.accel_m_s2[1] == pytest.approx(-1.5)
    assert s.accel_m_s2[2] == pytest.approx(9.81)  # specific force up: + on roadpreview's z
    spd_def = fdb.get_message_by_name("CAR_SPEED")
    [v] = dec.decode(
        can.Message(
            timestamp=1.0,
            arbitration_id=101,
            data=spd_def.encode({"Speed": 50.0}),
            is_extended_id=False,
        )
    )
    assert isinstance(v, SpeedSample)
    assert v.speed_mps == pytest.approx(50.0 * 0.44704)
    [sna] = dec.decode(
        can.Message(
            timestamp=1.1,
            arbitration_id=101,
            data=spd_def.encode({"Speed": "SNA"}),
            is_extended_id=False,
        )
    )
    assert isinstance(sna, SpeedSample)
    assert math.isnan(sna.speed_mps)
    assert dec.stats.not_available == 1
    assert dec.missing == {"roll_rate": "no roll rate", "accel_x": "no longitudinal acceleration"}


def test_every_bad_frame_is_counted_logged_once_and_skipped(
    db: Database, caplog: pytest.LogCaptureFixture
) -> None:
    """Unknown ID, wrong length, bad CRC, repeated counter, old time, out of range, error frame.

    Each bad frame sits between good ones; every good frame still decodes.
    """
    mapping = replace_quantity(load_mapping("roadpreview"), "yaw_rate", range=(-100.0, 100.0))
    rates = db.get_message_by_name("IMU_RATES")
    good_values = {"RollRate": 1.0, "PitchRate": 2.0, "YawRate": 3.0}

    def frame(t: float, counter: int, **values: float) -> can.Message:
        data = encode_protected(rates, {**good_values, **values}, counter)
        return can.Message(timestamp=t, arbitration_id=0x130, data=data, is_extended_id=False)

    bad_crc = frame(0.03, 3)
    bad_crc.data = bytearray(bad_crc.data)
    bad_crc.data[5] ^= 0x04
    stream = [
        frame(0.00, 0),
        can.Message(timestamp=0.005, arbitration_id=0x555, data=b"\x00" * 8),  # unknown ID
        frame(0.01, 1),
        can.Message(
            timestamp=0.015, arbitration_id=0x130, data=b"\x00" * 6, is_extended_id=False
        ),  # 6 bytes
        frame(0.02, 2),
        bad_crc,
        frame(0.04, 4),
        frame(0.045, 4),  # counter repeated
        frame(0.05, 5),
        frame(0.049, 6),  # time goes back
        frame(0.06, 7, YawRate=150.0),  # outside the mapping's plausible range
        frame(0.07, 8),
        can.Message(timestamp=0.075, arbitration_id=0x130, is_error_frame=True),
        frame(0.08, 9),
        frame(0.09, 12),  # two frames lost on the way: a counter jump, counted, not skipped
        frame(0.10, 13, YawRate=120.0),  # a second out-of-range frame: counted, not logged
    ]
    dec = CanInputDecoder(db, mapping)
    with caplog.at_level(logging.WARNING, logger="roadpreview.canbus.decode"):
        samples = list(dec.decode_all(stream))
    assert [round(s.t_s, 3) for s in samples] == [0.0, 0.01, 0.02, 0.04, 0.05, 0.07, 0.08, 0.09]
    assert all(isinstance(s, ImuSample) for s in samples)
    assert all(
        s.rates_rad_s[1] == pytest.approx(2.0 * DEG) for s in samples if isinstance(s, ImuSample)
    )
    assert dec.stats.problems == {
        FrameProblem.UNKNOWN_ID: 1,
        FrameProblem.WRONG_LENGTH: 1,
        FrameProblem.INTEGRITY: 1,
        FrameProblem.COUNTER_REPEATED: 1,
        FrameProblem.TIME_NOT_INCREASING: 1,
        FrameProblem.OUT_OF_RANGE: 2,
        FrameProblem.NOT_DATA_FRAME: 1,
    }
    # counters 3 (CRC), 6 (time) and 10, 11 (never came); 7 came intact with a value out of
    # range: skipped, but its counter is the new reference
    assert dec.stats.lost == 4
    assert dec.stats.frames == len(stream)
    assert dec.stats.used == len(samples)
    warnings = [r for r in caplog.records if r.name == "roadpreview.canbus.decode"]
    assert len(warnings) == 8  # once per kind, and once for the counter jump 9 -> 12 (taken)
    assert dec.notes == {"e2e_counter_jump": 1}
    assert dec.problems["e2e_counter_jump"] == 1
    assert dec.problems["rejected_range"] == 2
    text = caplog.text
    assert "0x555" in text
    assert "IMU_RATES.YawRate = 150" in text
    assert "E2E P01 CRC" in text
    assert "6 bytes, the DBC says 8" in text
    assert "skipped" in dec.stats.summary()


def test_channel_filter_and_ignored_unknown_ids(db: Database) -> None:
    data = {"mapping": {"channel": 0, "ignore_unknown_ids": True, "integrity": "e2e_p01"}}
    base = load_mapping("roadpreview")
    mapping = parse_mapping(
        {**data, "quantities": {q: vars(s) for q, s in base.quantities.items()}}, "m.toml"
    )
    rates = db.get_message_by_name("IMU_RATES")
    payload = encode_protected(rates, {"RollRate": 0, "PitchRate": 0, "YawRate": 0}, 0)
    dec = CanInputDecoder(db, mapping)
    assert dec.decode(can.Message(timestamp=1, arbitration_id=0x130, data=payload, channel=1)) == []
    assert dec.decode(can.Message(timestamp=2, arbitration_id=0x7AB, data=payload, channel=0)) == []
    assert (
        len(
            dec.decode(
                can.Message(
                    timestamp=3,
                    arbitration_id=0x130,
                    data=payload,
                    channel="can0",
                    is_extended_id=False,
                )
            )
        )
        == 1
    )
    assert dec.stats.ignored == 2
    assert dec.stats.problems == {}


def test_toyota_checksum() -> None:
    """A real RAV4 SPEED frame from the comma2k19 log (0xB4), and the same with one bit flipped."""
    data = bytes.fromhex("000000001D0B7A5E")
    assert toyota_checksum_ok(0xB4, data)
    assert not toyota_checksum_ok(0xB4, data[:-1] + bytes([data[-1] ^ 1]))
    assert not toyota_checksum_ok(0xB5, data)


# --- mapping errors ------------------------------------------------------------------------------


def test_a_mapping_naming_a_missing_signal_names_file_and_signal(db: Database) -> None:
    path = FILES / "mapping_missing_signal.toml"
    mapping = load_mapping(path)
    with pytest.raises(ConfigError) as err:
        CanInputDecoder(db, mapping, db_name="roadpreview.dbc")
    msg = str(err.value)
    assert "mapping_missing_signal.toml" in msg
    assert "quantities.pitch_rate" in msg
    assert "'PitchRat'" in msg
    assert "IMU_RATES" in msg
    assert "close: PitchRate" in msg


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"message": "IMU_RATE"}, r"message 'IMU_RATE' is not in the DBC \(close: IMU_RATES"),
        ({"unit": "rad/s"}, r"unit = 'rad/s', but IMU_RATES.YawRate is in 'deg/s'"),
    ],
)
def test_mapping_errors_against_the_dbc(db: Database, change: dict[str, str], match: str) -> None:
    mapping = replace_quantity(load_mapping("roadpreview"), "yaw_rate", **change)
    with pytest.raises(ConfigError, match=match):
        CanInputDecoder(db, mapping)


@pytest.mark.parametrize(
    ("quantities", "match"),
    [
        ({"pitch_rate": {"missing": "x"}}, "quantity roll_rate is not in the mapping"),
        ({"pitch_rat": {"missing": "x"}}, r"unknown quantity \[quantities.pitch_rat\]"),
        (
            {
                **{q: {"missing": "-"} for q in QUANTITIES},
                "yaw_rate": {"message": "M", "signal": "S", "unit": "deg/s", "axis": "y"},
            },
            "yaw_rate is about / along the z axis",
        ),
        (
            {
                **{q: {"missing": "-"} for q in QUANTITIES},
                "speed": {"message": "M", "signal": "S", "unit": "furlong/s"},
            },
            r"speed.unit = 'furlong/s'",
        ),
        (
            {
                **{q: {"missing": "-"} for q in QUANTITIES},
                "speed": {"message": "M", "unit": "km/h"},
            },
            r"quantities.speed.signal is not set",
        ),
        (
            {
                **{q: {"missing": "-"} for q in QUANTITIES},
                "speed": {"message": "M", "signal": "S", "unit": "km/h", "sign": 2},
            },
            r"quantities.speed.sign = 2",
        ),
    ],
)
def test_mapping_file_errors_name_the_file_and_key(
    tmp_path: Path, quantities: dict[str, dict[str, object]], match: str
) -> None:
    with pytest.raises(ConfigError, match=match) as err:
        parse_mapping({"quantities": quantities}, source="car.toml")
    assert "car.toml" in str(err.value)


def test_mapping_table_typo_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"unknown table \[quantity\]"):
        parse_mapping({"quantity": {}}, source="car.toml")


# --- logs ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["garbled.log", "imu_drive.asc", "imu_drive.blf"])
def test_a_bad_frame_in_the_middle_of_a_log_does_not_lose_the_frames_after_it(
    db: Database, name: str
) -> None:
    """garbled.log: 3 unparsable lines, a frame with a bad CRC, a short frame, an unknown ID."""
    dec = CanInputDecoder(db, load_mapping("roadpreview"))
    imu, speed = split_samples(decode_log(FILES / name, dec))
    pitch = [round(s.rates_rad_s[1] / DEG, 3) for s in imu if s.has_rates]
    expected = [round(2.0 + 0.1 * k, 3) for k in range(20)]
    if name == "garbled.log":
        expected.remove(2.4)  # the IMU_RATES frame of 0.04 s has its CRC byte flipped
        assert dec.stats.problems == {
            FrameProblem.INTEGRITY: 1,
            FrameProblem.WRONG_LENGTH: 1,
            FrameProblem.UNKNOWN_ID: 1,
        }
    else:
        assert dec.stats.problems == {}
    assert pitch == expected  # everything after the bad frames is there
    assert len([s for s in imu if s.has_accel]) == 20
    assert [s.speed_mps for s in speed] == pytest.approx([20.0] * 10)
