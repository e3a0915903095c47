"""The real comma2k19 RAV4 minute: Toyota DBC + mapping, real rates and signs, BLF/ASC copies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from roadpreview.canbus import (
    CanInputDecoder,
    CanLogReader,
    FrameProblem,
    decode_log,
    load_database,
    load_mapping,
    split_samples,
    write_can_log,
)
from roadpreview.types import ImuSample, SpeedSample

pytestmark = pytest.mark.shared

#: the `decoded` fixture: the decoder and the log's IMU and speed samples
Decoded = tuple[CanInputDecoder, list[ImuSample], list[SpeedSample]]

#: measured on this log: KINEMATICS (yaw rate, accelerations) 4914 good 8-byte frames in 60 s
KINEMATICS_HZ = 81.9
#: SPEED: 2480 good frames
SPEED_HZ = 41.3


def _rate(t: np.ndarray) -> float:
    rate: float = (len(t) - 1) / (t[-1] - t[0])
    return rate


@pytest.fixture(scope="module")
def decoded(comma_dir: Path) -> Decoded:
    db = load_database(comma_dir / "dbc" / "toyota_new_mc_pt_generated.dbc", strict=False)
    dec = CanInputDecoder(db, load_mapping("toyota_rav4"), db_name="toyota_new_mc_pt_generated")
    imu, speed = split_samples(decode_log(comma_dir / "derived" / "raw_can.candump.log", dec))
    return dec, imu, speed


def test_yaw_rate_and_accelerations_at_their_real_rates(decoded: Decoded) -> None:
    dec, imu, speed = decoded
    t = np.array([s.t_s for s in imu])
    rates = np.array([s.rates_rad_s for s in imu])
    accel = np.array([s.accel_m_s2 for s in imu])
    assert np.all(np.diff(t) > 0)  # monotonic
    assert _rate(t) == pytest.approx(KINEMATICS_HZ, rel=0.10)
    assert 55 < t[-1] - t[0] < 65  # the minute
    assert np.isfinite(rates[:, 2]).all()  # yaw rate in every sample
    assert np.isfinite(accel[:, :2]).all()  # accel x and y too
    assert np.isnan(rates[:, :2]).all()  # roll and pitch: declared missing
    assert np.isnan(accel[:, 2]).all()
    assert "pitch_rate" in dec.missing
    assert "no pitch rate" in dec.missing["pitch_rate"]
    ts = np.array([s.t_s for s in speed])
    assert np.all(np.diff(ts) > 0)
    assert _rate(ts) == pytest.approx(SPEED_HZ, rel=0.10)
    v = np.array([s.speed_mps for s in speed])
    assert 7.5 < v.min() < v.max() < 21.0  # 29-73 km/h in this minute
    # the log's real defects: truncated frames (7 bytes) are counted and skipped;
    # every SPEED frame passes the Toyota checksum
    assert dec.stats.problems == {FrameProblem.WRONG_LENGTH: 67}
    assert dec.stats.used == len(imu) + len(speed) == 4914 + 2480


def test_signs_agree_with_the_recorded_imu(decoded: Decoded, comma_dir: Path) -> None:
    """The mapping's signs against the phone IMU (axes forward, right, down) of the same drive."""
    _, imu, speed = decoded
    t = np.array([s.t_s for s in imu])
    yaw = np.array([s.rates_rad_s[2] for s in imu])
    ax = np.array([s.accel_m_s2[0] for s in imu])
    ay = np.array([s.accel_m_s2[1] for s in imu])
    base = comma_dir / "processed_log" / "IMU"
    gt, gyro = np.load(base / "gyro" / "t"), np.load(base / "gyro" / "value")
    at, acc = np.load(base / "accelerometer" / "t"), np.load(base / "accelerometer" / "value")
    yaw_left_imu = -gyro[:, 2]  # about "down": turning left is negative
    assert np.corrcoef(np.interp(gt, t, yaw), yaw_left_imu)[0, 1] > 0.7
    assert np.corrcoef(np.interp(at, t, ax), acc[:, 0])[0, 1] > 0.7
    # lateral: centripetal acceleration v * yaw rate (left +), smoothed over ~1 s
    ts = np.array([s.t_s for s in speed])
    v = np.array([s.speed_mps for s in speed])
    centripetal = np.interp(t, ts, v) * uniform_filter1d(yaw, 81)
    assert np.corrcoef(uniform_filter1d(ay, 81), centripetal)[0, 1] > 0.7


def test_the_log_written_to_blf_and_asc_reads_back_identical(
    comma_dir: Path, tmp_path: Path
) -> None:
    """All 135 468 frames on 4 buses. The log's clock is boot time; BLF stores calendar dates,
    so the copy is shifted to 2025 (an exact float addition undone on reading)."""
    shift = 1735689600.0
    frames = list(CanLogReader(comma_dir / "derived" / "raw_can.candump.log", errors="raise"))
    for m in frames:
        m.timestamp += shift
    assert len(frames) == 135_468
    for suffix in (".blf", ".asc"):
        path = tmp_path / f"rav4{suffix}"
        assert write_can_log(path, frames) == len(frames)
        reader = CanLogReader(path, errors="raise")
        back = list(reader)
        assert reader.problems == []
        assert len(back) == len(frames)
        got = np.array([(b.arbitration_id, b.dlc, b.channel, b.is_extended_id) for b in back])
        want = np.array([(m.arbitration_id, m.dlc, m.channel, m.is_extended_id) for m in frames])
        np.testing.assert_array_equal(got, want)
        assert [bytes(b.data) for b in back] == [bytes(m.data) for m in frames]
        dt = np.array([b.timestamp for b in back]) - np.array([m.timestamp for m in frames])
        assert np.abs(dt).max() < 1e-6, suffix  # candump's resolution is 1 µs
