"""Camera-IMU time offset by cross-correlation: sub-sample resolution, confidence, refusal."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.fusion.config import AlignmentConfig, GyroConfig
from roadpreview.fusion.gyro import GyroHistory
from roadpreview.fusion.timesync import TimeOffsetEstimator

DEG = math.pi / 180.0


def _pitch(t: np.ndarray, amp: float = 1.0) -> np.ndarray:
    return (
        amp
        * DEG
        * (
            0.4 * np.sin(2 * np.pi * 1.7 * t)
            + 0.3 * np.sin(2 * np.pi * 0.9 * t + 1)
            + 0.2 * np.sin(2 * np.pi * 3.1 * t + 2)
        )
    )


def _estimate(
    offset_s: float, *, amp: float = 1.0, noise_deg: float = 0.005, seed: int = 0
) -> tuple[TimeOffsetEstimator, object]:
    """12 s of a 104 Hz gyro (interval means, 0.4 deg/s bias, stamps late by ``offset_s``)
    and 30 Hz visual pitch relative to 2 s key frames."""
    rng = np.random.default_rng(seed)
    tt = np.arange(1, 12 * 104) / 104.0
    rate = (_pitch(tt, amp) - _pitch(tt - 1 / 104.0, amp)) * 104.0 + 0.4 * DEG
    rate += 0.1 * DEG * rng.standard_normal(tt.size)
    gyro = GyroHistory(GyroConfig())
    for t, w in zip(tt + offset_s, rate, strict=True):
        gyro.push(float(t), float(w))
    est = TimeOffsetEstimator(AlignmentConfig())
    frames = np.arange(0, 11.5, 1 / 30.0)
    p = _pitch(frames, amp) + noise_deg * DEG * rng.standard_normal(frames.size)
    key = 0
    for i in range(1, frames.size):
        est.track.add(float(frames[key]), float(frames[i]), float(p[i] - p[key]))
        if frames[i] - frames[key] >= 2.0:
            key = i
    return est, est.estimate(gyro)


@pytest.mark.parametrize("offset_ms", [0.0, 4.3, 23.7, 61.1, 80.0, -12.5])
def test_offset_recovered_below_one_imu_sample(offset_ms: float) -> None:
    """Resolution better than one IMU sample (9.6 ms): within 1 ms, confidence high."""
    _, r = _estimate(offset_ms / 1e3)
    assert r is not None
    assert abs(r.offset_s * 1e3 - offset_ms) < 1.0
    assert r.correlation > 0.95
    assert 0 < r.std_s < 0.002


def test_flat_road_gives_no_estimate() -> None:
    """No excitation (the pitch hardly moves): no estimate rather than a guess."""
    _, r = _estimate(0.03, amp=0.002)
    assert r is None


def test_too_few_visual_increments_give_no_estimate() -> None:
    est, _ = _estimate(0.03)
    est.track.reset()
    gyro = GyroHistory(GyroConfig())
    assert est.estimate(gyro) is None


def test_visual_chain_across_key_frames_gives_frame_to_frame_increments() -> None:
    est, _ = _estimate(0.0, noise_deg=0.0)
    ta, tb, d = (np.array(x) for x in (est.track.ta, est.track.tb, est.track.d))
    assert np.allclose(tb - ta, 1 / 30.0)
    assert np.allclose(d, _pitch(tb) - _pitch(ta), atol=1e-12)
