"""IMU and speed-sensor models (kinematics, signs, noise, bias, range, stamps); the IMU CSV."""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from roadpreview.canbus.samples import ImuMeasurements
from roadpreview.configtools import from_mapping, to_mapping
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.sim.canlog import IMU_CSV_COLUMNS, read_imu_csv, write_imu_csv
from roadpreview.sim.imu import (
    DEG,
    FORWARD,
    IMU_PRESETS,
    KMH,
    REVERSE,
    STANDARD_GRAVITY_M_S2,
    STANDSTILL,
    ImuConfig,
    SpeedSensorConfig,
    body_rates_from_euler,
    rotation_body_to_world,
    simulate_imu,
    simulate_speed,
)

FINE_DT = 1e-3  # truth grid, 1 kHz


def _grid(duration_s: float) -> np.ndarray:
    return np.arange(0.0, duration_s + FINE_DT / 2, FINE_DT)


def _at_rest(
    t: np.ndarray, roll: float = 0.0, pitch: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = len(t)
    att = np.tile([roll, pitch, 0.0], (n, 1))
    return np.zeros((n, 3)), np.zeros((n, 3)), att


def _pitch_trajectory(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A bumpy pitch history (rad) and its exact derivative."""
    pitch = (
        0.03 * np.sin(2 * np.pi * 1.7 * t) + 0.01 * np.sin(2 * np.pi * 0.31 * t + 0.4) + 0.002 * t
    )
    dpitch = (
        0.03 * 2 * np.pi * 1.7 * np.cos(2 * np.pi * 1.7 * t)
        + 0.01 * 2 * np.pi * 0.31 * np.cos(2 * np.pi * 0.31 * t + 0.4)
        + 0.002
    )
    return pitch, dpitch


# --- kinematics and signs -------------------------------------------------------------------


def test_integrated_pitch_rate_equals_true_pitch_change() -> None:
    t = _grid(10.0)
    pitch, dpitch = _pitch_trajectory(t)
    zeros = np.zeros_like(t)
    omega = np.column_stack([zeros, dpitch, zeros])
    att = np.column_stack([zeros, pitch, zeros])
    s = simulate_imu(t, omega, np.zeros((len(t), 3)), att, ImuConfig.ideal(),
                     np.random.default_rng(0))
    assert len(s) == 1000
    integrated = np.cumsum(s.rates_rad_s[:, 1]) / s.rate_hz
    truth = np.interp(s.t_true_s, t, pitch) - pitch[0]
    assert np.max(np.abs(integrated - truth)) < 1e-4
    # the silicon's y axis points left: nose-up pitching is a NEGATIVE gyro_y
    np.testing.assert_allclose(s.gyro_rad_s[:, 1], -s.rates_rad_s[:, 1])
    rising = np.interp(s.t_true_s - 0.005, t, dpitch) > 0.05
    assert np.all(s.gyro_rad_s[rising, 1] < 0)


def test_body_rates_agree_with_the_rotation_matrices() -> None:
    # omega_x = R^T dR/dt (skew part), in ISO axes; our rates are [wx, -wy, wz]
    t = _grid(2.0)
    att = np.column_stack([
        0.1 * np.sin(2.1 * t), 0.2 * np.sin(1.3 * t + 0.3), 0.5 * np.sin(0.7 * t),
    ])
    rates = body_rates_from_euler(t, att)
    r = rotation_body_to_world(att)
    i = np.arange(100, len(t) - 100, 50)
    dr = (r[i + 1] - r[i - 1]) / (2 * FINE_DT)
    skew = np.einsum("nji,njk->nik", r[i], dr)
    wx, wy, wz = skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]
    np.testing.assert_allclose(rates[i], np.column_stack([wx, -wy, wz]), atol=1e-5)


def test_integrated_error_grows_as_bias_times_time() -> None:
    b = 0.1 * DEG
    cfg = dataclasses.replace(
        ImuConfig.automotive(), gyro_bias=(0.0, b, 0.0), gyro_bias_std=0.0,
        gyro_bias_random_walk=0.0, timestamp_jitter_s=0.0,
    )
    t = _grid(10.0)
    s = simulate_imu(t, *_at_rest(t), cfg, np.random.default_rng(1))
    assert np.all(s.gyro_bias_rad_s[:, 1] == b)
    err = np.cumsum(s.gyro_rad_s[:, 1] - s.true_gyro_rad_s[:, 1]) / s.rate_hz
    elapsed = s.t_true_s - t[0]
    # white noise integrates to an angle random walk of N * sqrt(t / 2) = 0.011 deg at 10 s,
    # against b * t = 1 deg
    np.testing.assert_allclose(err, b * elapsed, atol=0.04 * DEG)
    slope = np.polyfit(elapsed, err, 1)[0]
    assert slope == pytest.approx(b, rel=0.03)


def test_accelerometer_at_rest_level_reads_plus_g_on_z() -> None:
    cfg = dataclasses.replace(
        ImuConfig.automotive(), accel_bias_std=0.0, accel_bias_random_walk=0.0
    )
    t = _grid(10.0)
    s = simulate_imu(t, *_at_rest(t), cfg, np.random.default_rng(2))
    sigma = cfg.accel_noise_std
    expected = np.array([0.0, 0.0, STANDARD_GRAVITY_M_S2])
    assert np.all(np.abs(s.accel_m_s2 - expected) < 5 * sigma + cfg.accel_lsb)
    np.testing.assert_allclose(s.accel_m_s2.mean(axis=0), expected,
                               atol=5 * sigma / math.sqrt(len(s)) + cfg.accel_lsb / 2)
    assert s.accel_m_s2[:, 2].mean() == pytest.approx(9.81, abs=0.01)


@pytest.mark.parametrize(("roll", "pitch", "axis", "sign"), [
    (0.0, 5 * DEG, 0, +1),   # nose up: gravity's reaction points forward-up, +x
    (5 * DEG, 0.0, 1, +1),   # left side up: +y (y points left)
    (-5 * DEG, 0.0, 1, -1),
])
def test_accelerometer_sign_when_tilted(roll: float, pitch: float, axis: int, sign: int) -> None:
    t = _grid(0.2)
    s = simulate_imu(t, *_at_rest(t, roll, pitch), ImuConfig.ideal(), np.random.default_rng(0))
    g = STANDARD_GRAVITY_M_S2
    np.testing.assert_allclose(s.accel_m_s2[:, axis], sign * g * math.sin(5 * DEG), rtol=1e-9)
    np.testing.assert_allclose(s.accel_m_s2[:, 2], g * math.cos(5 * DEG), rtol=1e-9)


def test_forward_acceleration_reads_positive_x() -> None:
    t = _grid(1.0)
    omega, acc, att = _at_rest(t)
    acc[:, 0] = 2.0
    s = simulate_imu(t, omega, acc, att, ImuConfig.ideal(), np.random.default_rng(0))
    np.testing.assert_allclose(s.accel_m_s2[:, 0], 2.0)


# --- time stamps ----------------------------------------------------------------------------


def test_time_offset_shifts_stamps_exactly() -> None:
    t = _grid(3.0) + 100.0
    cfg = dataclasses.replace(ImuConfig.ideal(rate_hz=125.0), time_offset_s=0.037)
    s = simulate_imu(t, *_at_rest(t), cfg, np.random.default_rng(0))
    np.testing.assert_allclose(s.t_stamp_s - s.t_true_s, 0.037, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.diff(s.t_true_s), 1 / 125.0, rtol=0, atol=1e-9)
    assert s.t_true_s[0] == pytest.approx(100.0 + 1 / 125.0)


def test_timestamp_jitter_std() -> None:
    t = _grid(20.0)
    cfg = dataclasses.replace(ImuConfig.ideal(), timestamp_jitter_s=2e-4, time_offset_s=-0.01)
    s = simulate_imu(t, *_at_rest(t), cfg, np.random.default_rng(3))
    d = s.t_stamp_s - s.t_true_s + 0.01
    assert d.std() == pytest.approx(2e-4, rel=0.1)
    assert abs(d.mean()) < 3 * 2e-4 / math.sqrt(len(d))


# --- noise, resolution, range ---------------------------------------------------------------


@pytest.mark.parametrize("rate_hz", [100.0, 200.0])
def test_white_noise_std_is_density_times_sqrt_half_rate(rate_hz: float) -> None:
    cfg = dataclasses.replace(
        ImuConfig.ideal(rate_hz), gyro_noise_density=0.01 * DEG, accel_noise_density=0.002
    )
    t = _grid(20.0)
    s = simulate_imu(t, *_at_rest(t), cfg, np.random.default_rng(4))
    gyro_std = s.gyro_rad_s.std(axis=0)
    accel_std = (s.accel_m_s2 - s.true_accel_m_s2).std(axis=0)
    np.testing.assert_allclose(gyro_std, 0.01 * DEG * math.sqrt(rate_hz / 2), rtol=0.1)
    np.testing.assert_allclose(accel_std, 0.002 * math.sqrt(rate_hz / 2), rtol=0.1)


def test_bias_random_walk_spreads_as_sqrt_time() -> None:
    cfg = dataclasses.replace(ImuConfig.ideal(), gyro_bias_random_walk=1e-3)
    t = _grid(4.0)
    ends = [simulate_imu(t, *_at_rest(t), cfg, np.random.default_rng(k)).gyro_bias_rad_s[-1, 0]
            for k in range(200)]
    # 399 steps of 1e-3 * sqrt(0.01)
    assert np.std(ends) == pytest.approx(1e-3 * math.sqrt(399 * 0.01), rel=0.15)


def test_quantisation_lsb_respected() -> None:
    cfg = ImuConfig.smartphone()
    t = _grid(5.0)
    pitch, dpitch = _pitch_trajectory(t)
    zeros = np.zeros_like(t)
    s = simulate_imu(t, np.column_stack([zeros, dpitch, zeros]), np.zeros((len(t), 3)),
                     np.column_stack([zeros, pitch, zeros]), cfg, np.random.default_rng(5))
    for values, lsb in ((s.gyro_rad_s, cfg.gyro_lsb), (s.accel_m_s2, cfg.accel_lsb)):
        steps = values / lsb
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
        assert len(np.unique(values[:, 1])) > 10


def test_saturation_clips_at_full_scale() -> None:
    cfg = ImuConfig.automotive()  # ±125 deg/s, ±3 g
    t = _grid(2.0)
    omega, acc, att = _at_rest(t)
    omega[:, 2] = 300 * DEG * np.sin(2 * np.pi * t)
    acc[:, 2] = 50.0 * np.sin(2 * np.pi * t)
    s = simulate_imu(t, omega, acc, att, cfg, np.random.default_rng(6))
    assert np.max(np.abs(s.gyro_rad_s)) <= cfg.gyro_range
    assert np.max(s.gyro_rad_s[:, 2]) == pytest.approx(cfg.gyro_range, abs=cfg.gyro_lsb)
    assert np.min(s.gyro_rad_s[:, 2]) == pytest.approx(-cfg.gyro_range, abs=cfg.gyro_lsb)
    assert np.mean(np.abs(s.gyro_rad_s[:, 2]) >= cfg.gyro_range - cfg.gyro_lsb) > 0.3
    assert np.max(s.accel_m_s2[:, 2]) <= cfg.accel_range
    assert np.max(s.true_accel_m_s2[:, 2]) > cfg.accel_range  # the truth is not clipped


def test_same_seed_same_samples_and_noise_level_does_not_change_bias() -> None:
    t = _grid(2.0)
    a = simulate_imu(t, *_at_rest(t), ImuConfig.automotive(), np.random.default_rng(7))
    b = simulate_imu(t, *_at_rest(t), ImuConfig.automotive(), np.random.default_rng(7))
    np.testing.assert_array_equal(a.gyro_rad_s, b.gyro_rad_s)
    quiet = dataclasses.replace(ImuConfig.automotive(), gyro_noise_density=0.0)
    c = simulate_imu(t, *_at_rest(t), quiet, np.random.default_rng(7))
    np.testing.assert_array_equal(a.gyro_bias_rad_s, c.gyro_bias_rad_s)


# --- configuration and input checks ---------------------------------------------------------


def test_presets_are_valid_and_ordered() -> None:
    auto, phone = IMU_PRESETS["automotive"](), IMU_PRESETS["smartphone"]()
    auto.validate()
    phone.validate()
    assert auto.gyro_noise_density < phone.gyro_noise_density
    assert auto.gyro_bias_std <= 0.1 * DEG < phone.gyro_bias_std
    assert auto.gyro_noise_density * 1.0001 >= 0.005 * DEG
    assert 0.01 * DEG <= phone.gyro_noise_density <= 0.02 * DEG
    # TOML round trip through configtools
    assert from_mapping(ImuConfig, to_mapping(phone)) == phone


@pytest.mark.parametrize(("field", "value"), [
    ("rate_hz", 50.0), ("time_offset_s", 0.1), ("gyro_lsb", 10.0), ("timestamp_jitter_s", 0.01),
    ("sampling", "median"),
])
def test_bad_config_is_rejected_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=field):
        from_mapping(ImuConfig, {field: value}, source="imu.toml")


def test_bad_truth_arrays_are_rejected() -> None:
    t = _grid(1.0)
    omega, acc, att = _at_rest(t)
    with pytest.raises(InputDataError, match="omega_body"):
        simulate_imu(t, omega[:, :2], acc, att, ImuConfig.ideal(), np.random.default_rng(0))
    acc[10, 1] = np.nan
    with pytest.raises(InputDataError, match="accel_world"):
        simulate_imu(t, omega, acc, att, ImuConfig.ideal(), np.random.default_rng(0))
    with pytest.raises(InputDataError, match="t_truth"):
        simulate_imu(t[::-1], omega, acc, att, ImuConfig.ideal(), np.random.default_rng(0))


# --- speed sensors --------------------------------------------------------------------------


def test_speed_is_quantised_and_has_a_direction() -> None:
    t = _grid(6.0)
    v = np.interp(t, [0, 1, 2, 3, 4, 6], [0, 0, -1.5, -1.5, 8.123456, 8.123456])
    cfg = SpeedSensorConfig()
    s = simulate_speed(t, v, cfg, np.random.default_rng(8))
    assert len(s) == 300
    assert np.diff(s.t_true_s) == pytest.approx(0.02)
    kmh = s.speed_m_s / KMH
    np.testing.assert_allclose(kmh / 0.01, np.round(kmh / 0.01), atol=1e-9)
    moving = np.abs(s.true_speed_m_s) >= cfg.standstill_below_kmh * KMH
    assert 0 < np.count_nonzero(~moving) < len(s)
    np.testing.assert_allclose(s.speed_m_s[moving], np.abs(s.true_speed_m_s[moving]),
                               rtol=0, atol=0.005 * KMH + 1e-12)
    assert np.all(s.speed_m_s[~moving] == 0)
    assert np.all(s.direction[~moving] == STANDSTILL)
    wheel_steps = s.wheel_speeds_m_s / KMH / 0.03125
    np.testing.assert_allclose(wheel_steps, np.round(wheel_steps), atol=1e-9)
    at = np.searchsorted(s.t_true_s, [0.5, 2.5, 5.0])
    assert list(s.direction[at]) == [STANDSTILL, REVERSE, FORWARD]
    assert s.speed_m_s[at[0]] == 0.0
    assert s.speed_m_s[at[2]] / KMH == pytest.approx(8.123456 / KMH, abs=0.005)
    assert np.all(s.wheel_speeds_m_s >= 0)


# --- IMU CSV --------------------------------------------------------------------------------


def _phone_samples() -> ImuMeasurements:
    t = _grid(3.0)
    pitch, dpitch = _pitch_trajectory(t)
    zeros = np.zeros_like(t)
    s = simulate_imu(t, np.column_stack([zeros, dpitch, zeros]), np.zeros((len(t), 3)),
                     np.column_stack([zeros, pitch, zeros]), ImuConfig.smartphone(),
                     np.random.default_rng(9))
    return s.measurements()


def test_imu_csv_round_trip(tmp_path: Path) -> None:
    m = _phone_samples()
    path = tmp_path / "imu.csv"
    assert write_imu_csv(path, m) == len(m)
    lines = path.read_text().splitlines()
    assert lines[1] == ",".join(IMU_CSV_COLUMNS)
    assert "rad_s" in lines[1]
    assert "m_s2" in lines[1]
    back = read_imu_csv(path)
    np.testing.assert_allclose(back.t_s, m.t_s, rtol=0, atol=1e-6)
    np.testing.assert_allclose(back.gyro_rad_s, m.gyro_rad_s, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(back.accel_m_s2, m.accel_m_s2, rtol=1e-8, atol=1e-12)


def test_imu_csv_bad_rows_are_skipped_with_their_line_number(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    m = _phone_samples()
    path = tmp_path / "imu.csv"
    write_imu_csv(path, m)
    lines = path.read_text().splitlines()
    # lines[0] comment, lines[1] header, lines[2 + i] sample i (file line 3 + i)
    lines[12] = lines[12].rsplit(",", 1)[0]  # 6 columns: file line 13
    lines[20] = lines[20].replace(lines[20].split(",")[3], "nan", 1)  # file line 21
    lines[30] = "1.0,abc,0,0,0,0,0"  # file line 31
    path.write_text("\n".join(lines) + "\n")
    with caplog.at_level(logging.WARNING, logger="roadpreview.sim.canlog"):
        back = read_imu_csv(path)
    assert len(back) == len(m) - 3
    text = caplog.text
    for line_no in (13, 21, 31):
        assert f"{path}:{line_no}:" in text
    assert "columns" in text
    assert "non-finite" in text
    assert "not a number" in text
    keep = np.ones(len(m), bool)
    keep[[10, 18, 28]] = False
    np.testing.assert_allclose(back.t_s, m.t_s[keep], atol=1e-6)


def test_imu_csv_wrong_header_names_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "phone.csv"
    path.write_text("time,gx,gy,gz,ax,ay,az\n0.0,0,0,0,0,0,9.8\n")
    with pytest.raises(InputDataError, match=r"phone\.csv:1: header"):
        read_imu_csv(path)
    with pytest.raises(InputDataError, match="not found"):
        read_imu_csv(tmp_path / "missing.csv")
