"""Camera-IMU time offset by cross-correlation: sub-sample resolution, confidence, refusal."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.fusion.config import AlignmentConfig, GyroConfig
from roadpreview.fusion.gyro import GyroHistory
from roadpreview.fusion.timesync import (
    OffsetEstimate,
    TimeOffsetEstimator,
    VisualRateTrack,
    _median,
)

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
) -> tuple[TimeOffsetEstimator, OffsetEstimate | None, GyroHistory]:
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
    return est, est.estimate(gyro), gyro


@pytest.mark.parametrize("offset_ms", [0.0, 4.3, 23.7, 61.1, 80.0, -12.5])
def test_offset_recovered_below_one_imu_sample(offset_ms: float) -> None:
    """Resolution better than one IMU sample (9.6 ms): within 1 ms, confidence high."""
    _, r, _ = _estimate(offset_ms / 1e3)
    assert r is not None
    assert abs(r.offset_s * 1e3 - offset_ms) < 1.0
    assert r.correlation > 0.95
    assert 0 < r.std_s < 0.002


def test_flat_road_gives_no_estimate() -> None:
    """No excitation (the pitch hardly moves): no estimate rather than a guess."""
    _, r, _ = _estimate(0.03, amp=0.002)
    assert r is None


def test_too_few_visual_increments_give_no_estimate() -> None:
    est, _, _ = _estimate(0.03)
    est.track.reset()
    gyro = GyroHistory(GyroConfig())
    assert est.estimate(gyro) is None


def test_visual_chain_across_key_frames_gives_frame_to_frame_increments() -> None:
    est, _, _ = _estimate(0.0, noise_deg=0.0)
    ta, tb, d = (np.array(x) for x in (est.track.ta, est.track.tb, est.track.d))
    assert np.allclose(tb - ta, 1 / 30.0)
    assert np.allclose(d, _pitch(tb) - _pitch(ta), atol=1e-12)


def test_queued_measurements_are_chained_as_added_one_by_one() -> None:
    """`add` queues a measurement and the track chains the queue when it is read: the same
    increments as reading it after every measurement, with chains broken by new key frames,
    a gap and out-of-order frames, the window sliding and the chain pruned; the queue stays
    bounded when the track is never read."""
    rng = np.random.default_rng(3)
    frames = np.arange(0, 30.0, 1 / 30.0)
    p = _pitch(frames)
    meas: list[tuple[float, float, float]] = []
    key = 0
    for i in range(1, frames.size):
        if 12.0 <= frames[i] < 12.5:
            key = -1
            continue
        if key < 0 or frames[i] - frames[key] >= 2.0:
            key = i - 1
        j = i - 1 if i % 97 == 0 and key < i - 1 else i  # now and then a frame out of order
        meas.append((float(frames[key]), float(frames[j]), float(p[j] - p[key] + rng.normal())))
    eager, lazy = VisualRateTrack(10.0), VisualRateTrack(10.0)
    seen = []
    for n, m in enumerate(meas, 1):
        eager.add(*m)
        seen.append((len(eager), eager.ta, eager.tb, eager.d))  # read: chained at once
        lazy.add(*m)
        assert len(lazy._queue) < 256
        if n in (400, len(meas)):  # (in between, the queue runs full and is chained)
            assert (len(lazy), lazy.ta, lazy.tb, lazy.d) == seen[-1]
    for a, b in zip(lazy.arrays(), seen[-1][1:], strict=True):
        assert np.array_equal(a, np.array(b))


def _plain_estimate(est: TimeOffsetEstimator, gyro: GyroHistory) -> tuple[float, float] | None:
    """The cross-correlation written plainly (np.median, np.clip, np.std, the integral read
    at both ends of every increment for every lag): what `estimate` computes faster."""
    cfg = est.cfg
    ta, tb, d = (np.array(x) for x in (est.track.ta, est.track.tb, est.track.d))
    newest = gyro.newest
    assert newest is not None
    ok = tb + cfg.max_offset_s <= newest
    ta, tb, d = ta[ok], tb[ok], d[ok]
    span = tb - ta
    v = d / span
    med = float(np.median(v))
    mad = float(np.median(np.abs(v - med))) * 1.4826 + 1e-12
    v = np.clip(v, med - 6 * mad, med + 6 * mad)
    if float(np.std(v)) < cfg.min_rate_std_rad_s:
        return None
    vc = v - v.mean()
    since = float(ta[0]) + cfg.min_offset_s

    def corr(lags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g_b = [gyro.integral_at(tb + g, since) for g in lags]
        g_a = [gyro.integral_at(ta + g, since) for g in lags]
        rates = np.array([(b - a) / span for b, a in zip(g_b, g_a, strict=True)])
        gc = rates - rates.mean(axis=1, keepdims=True)
        return (gc @ vc) / np.sqrt((gc**2).sum(axis=1) * (vc**2).sum()), rates

    ic = 4 * int(np.argmax(corr(est.lags[::4])[0]))
    lags = est.lags[max(ic - 6, 0) : ic + 7]
    r, _ = corr(lags)
    j = int(np.argmax(r))
    if j in (0, r.size - 1):
        return None
    curv = r[j - 1] - 2 * r[j] + r[j + 1]
    delta = min(max(0.5 * (r[j - 1] - r[j + 1]) / curv if curv < 0 else 0.0, -0.5), 0.5)
    return float(lags[j] + delta * cfg.step_s), float(r[j])


@pytest.mark.parametrize("offset_ms", [4.3, 61.1])
def test_estimate_equals_the_plain_computation(offset_ms: float) -> None:
    """The estimate (read once per distinct frame time, numpy's statistics written out) is
    the plain computation's, also with chains broken by new key frames and a gap."""
    est, r, gyro = _estimate(offset_ms / 1e3)
    assert r is not None
    ref = _plain_estimate(est, gyro)
    assert ref is not None
    assert abs(r.offset_s - ref[0]) < 1e-12
    assert abs(r.correlation - ref[1]) < 1e-12
    # a track with a gap (no increments across it) and a chain restarted at a new key
    est.track.reset()
    frames = np.arange(0, 11.5, 1 / 30.0)
    p = _pitch(frames)
    for i in range(1, frames.size):
        if 5.0 <= frames[i] < 5.5:
            continue
        key = i - 1 if frames[i] < 5.5 or frames[i] >= 5.6 else i - 2
        est.track.add(float(frames[key]), float(frames[i]), float(p[i] - p[key]))
    r2, ref2 = est.estimate(gyro), _plain_estimate(est, gyro)
    assert r2 is not None
    assert ref2 is not None
    assert abs(r2.offset_s - ref2[0]) < 1e-12
    assert abs(r2.correlation - ref2[1]) < 1e-12


def test_median_is_numpys() -> None:
    rng = np.random.default_rng(1)
    for n in (1, 2, 3, 10, 45, 46, 301):
        v = rng.standard_normal(n)
        v[: n // 3] = v[0]  # ties
        assert _median(v) == float(np.median(v))
