"""The data set's ceiling: the true compensated trajectory removes exactly the camera's
pitch (f tan phi) and heave (f dz / d) and keeps the lead's own motion; its s is the
product detector's own (`WindowedStdDetector`, window from `DetectorConfig`)."""

from __future__ import annotations

import numpy as np
import pytest

from roadpreview.anomaly import AnomalyConfig, DetectorConfig
from roadpreview.eval.experiments import ceiling_s, ceiling_scores, windowed_std

FPS = 30.0
F_PX = 707.0
DETRENDED = DetectorConfig(window_s=1.0, detrend=True)


def test_windowed_std_is_the_std_about_the_window_line() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(300) / FPS
    y = 0.8 * t + rng.normal(0.0, 0.5, t.size)
    s = windowed_std(t, y, DETRENDED)
    # the detector gives s once its window spans half of window_s (min_span_fraction)
    assert np.isnan(s[:15]).all()
    assert np.isfinite(s[15:]).all()
    for i in (29, 150, 299):  # against numpy's polyfit on the same 30 frames
        tt, yy = t[i - 29 : i + 1], y[i - 29 : i + 1]
        resid = yy - np.polyval(np.polyfit(tt, yy, 1), tt)
        assert s[i] == pytest.approx(resid.std(), rel=1e-9)
    plain = windowed_std(t, y, DetectorConfig(window_s=1.0, detrend=False))
    assert plain[150] == pytest.approx(y[121:151].std(), rel=1e-9)
    # a line has no spread about itself; the running moments leave ~1e-15 px² of round-off
    # in the residual variance, i.e. ~3e-8 px of s
    assert windowed_std(t, 2.0 * t + 1.0, DETRENDED)[100] == pytest.approx(0.0, abs=1e-6)


def test_windowed_std_follows_the_configured_window() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(300) / FPS
    y = rng.normal(0.0, 0.5, t.size)
    s = windowed_std(t, y, DetectorConfig(window_s=2.0, nms_window_s=2.0, detrend=False))
    assert s[150] == pytest.approx(y[91:151].std(), rel=1e-9)  # 60 frames at 30 fps


def test_windowed_std_skips_frames_without_a_lead() -> None:
    t = np.arange(90) / FPS
    y = np.sin(2 * np.pi * t)
    y[40:45] = np.nan  # five lost frames: the detector's s uses the 25 valid ones
    s = windowed_std(t, y, DetectorConfig(window_s=1.0, detrend=False))
    window = y[15:45]
    assert s[44] == pytest.approx(window[np.isfinite(window)].std(), rel=1e-9)


def test_ceiling_removes_camera_pitch_and_heave_and_keeps_the_lead_bump() -> None:
    t = np.arange(int(20 * FPS)) / FPS
    d = np.full(t.size, 15.0)
    # the lead over a 6 cm bump at 10 s, seen at 15 m: f delta / d = 2.8 px, a 0.4 s bump
    lead = F_PX * 0.06 / d * np.exp(-0.5 * ((t - 10.0) / 0.1) ** 2)
    # the camera: pitch oscillating 0.5 deg at 1.3 Hz, heave 2 cm at 1 Hz (its 3 s mean is 0)
    phi = np.radians(0.5) * np.sin(2 * np.pi * 1.3 * t + 0.4)
    z = 1.3 + 0.02 * np.sin(2 * np.pi * 1.0 * t)
    row = 380.0 + lead + F_PX * np.tan(phi) + F_PX * (z - 1.3) / d
    truth = {
        "frame_t_s": t,
        "lead_rear_px": np.column_stack([np.full(t.size, 640.0), row]),
        "cam_pitch_rad": phi,
        "cam_z_m": z,
        "lead_distance_m": d,
    }
    got = ceiling_s(truth, F_PX, DETRENDED)
    want = windowed_std(t, lead, DETRENDED)
    inner = slice(int(2 * FPS), int(18 * FPS))  # away from the running mean's edges
    # the heave's running mean spans 91 frames (3.03 s), not whole periods of 1 Hz: it keeps
    # ~1 % of the 1 px heave signal, 0.02 px of s
    assert np.nanmax(np.abs(got[inner] - want[inner])) < 0.03  # px
    # and the camera's motion alone would have been a strong false signal
    camera_only = windowed_std(t, row - lead, DETRENDED)
    assert np.nanmedian(camera_only[inner]) > 2.0
    assert np.nanmax(got[inner]) == pytest.approx(np.nanmax(want[inner]), abs=0.03)


def test_the_std_ceiling_score_is_the_configured_detectors_s() -> None:
    t = np.arange(int(10 * FPS)) / FPS
    d = np.full(t.size, 12.0)
    truth = {
        "frame_t_s": t,
        "lead_rear_px": np.column_stack([np.full(t.size, 640.0), 380.0 + np.sin(3 * t)]),
        "cam_pitch_rad": np.zeros(t.size),
        "cam_z_m": np.full(t.size, 1.3),
        "lead_distance_m": d,
        "ego_speed_m_s": np.full(t.size, 10.0),
    }
    std = DetectorConfig(window_s=0.5, nms_window_s=1.0, detrend=False)
    got = ceiling_scores(truth, F_PX, AnomalyConfig(std=std), "std")
    np.testing.assert_array_equal(got.t, t)
    np.testing.assert_allclose(got.s, ceiling_s(truth, F_PX, std), equal_nan=True)
    assert got.s[100] == pytest.approx(np.sin(3 * t[86:101]).std(), rel=1e-9)  # 15 frames
