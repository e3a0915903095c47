"""Real data: the comma2k19 RAV4 minute (phone gyro at 104 Hz, INS pitch per frame at 20 Hz).

The INS pitch of each frame stands in for the visual measurement: relative to key frames
renewed every 2 s, with a reported std of 0.02 deg. Skipped when ../shared is absent.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from roadpreview.fusion import FusedPitch, VisualPitch, make_fusion

DEG = math.pi / 180.0
pytestmark = pytest.mark.shared


def _load(comma_dir: Path, gyro: str) -> tuple[np.ndarray, ...]:
    log = comma_dir / "processed_log" / "IMU"
    t = np.load(log / "gyro" / "t")
    rate = np.load(log / gyro / "value")[:, 1]  # axes [forward, right, down]: nose up +
    phone_bias = np.load(log / "gyro_bias" / "value")[:, 1]
    pose = np.load(comma_dir / "derived" / "frame_pose_ned_euler.npz")
    return t, rate, phone_bias, pose["t"], pose["pitch"]


def _replay(
    name: str, t: np.ndarray, rate: np.ndarray, ft: np.ndarray, pitch: np.ndarray, **options: object
) -> list[FusedPitch]:
    f = (
        make_fusion(name, gyro={"rate_hz": 104.0}, **options)
        if name != "imu-only"
        else (make_fusion(name, **options))
    )
    out, j, key = [], 0, 0
    for i, tf in enumerate(ft):  # frames in order; the gyro up to 0.1 s after each
        while j < t.size and t[j] <= tf + 0.1:
            f.push_gyro(float(t[j]), float(rate[j]))
            j += 1
        if i > 0:
            f.push_visual(
                VisualPitch(
                    float(ft[key]), float(tf), float(pitch[i] - pitch[key]), 0.02 * DEG, 0.8, True
                )
            )
            if tf - ft[key] >= 2.0:
                key = i
        out.append(f.estimate(float(tf)))
    return out


def test_gyro_axis_one_is_the_pitch_rate_nose_up(comma_dir: Path) -> None:
    t, rate, _, ft, pitch = _load(comma_dir, "gyro")
    dpitch = np.gradient(pitch, ft)
    assert np.corrcoef(np.interp(ft, t, rate), dpitch)[0, 1] > 0.8


@pytest.mark.parametrize("gyro", ["gyro", "gyro_uncalibrated"])
def test_fused_pitch_tracks_the_ins_pitch(comma_dir: Path, gyro: str) -> None:
    """Calibrated gyro (residual bias ~0.03 deg/s) or the raw one (-2.0 deg/s bias, which the
    phone itself estimated): the fusion tracks the INS pitch and finds the bias."""
    t, rate, phone_bias, ft, pitch = _load(comma_dir, gyro)
    out = _replay("kalman", t, rate, ft, pitch)
    err = np.degrees(np.array([o.phi for o in out]) - (pitch - pitch[0]))
    bias = np.degrees(np.array([o.bias for o in out]))
    rms = float(np.sqrt(np.mean(err**2)))
    windows = [float(np.std(err[i : i + 20])) for i in range(0, err.size - 20, 20)]
    later = ft - ft[0] > 10.0
    expected = np.degrees(phone_bias.mean()) if gyro == "gyro_uncalibrated" else 0.0
    print(
        f"\ncomma2k19 {gyro}: error RMS {rms:.3f} deg (max {np.abs(err).max():.3f}), within"
        f" 1 s max {max(windows):.3f} deg; bias after 10 s {bias[later].min():.3f} to"
        f" {bias[later].max():.3f} deg/s (phone's own {np.degrees(phone_bias.mean()):.3f});"
        f" offset {out[-1].time_offset * 1e3:.1f} ms"
    )
    assert rms < 0.15
    assert max(windows) < 0.05
    assert np.all(np.abs(bias[later] - expected) < 0.1)
    imu = _replay("imu-only", t, rate, ft, pitch)
    drift = abs(np.degrees(imu[-1].phi) - np.degrees(pitch[-1] - pitch[0]))
    assert drift > 10 * rms  # the paper's drifting integrated gyro
