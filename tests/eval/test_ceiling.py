"""The data set's ceiling: the true compensated trajectory removes exactly the camera's
pitch (f tan phi) and heave (f dz / d) and keeps the lead's own motion."""

from __future__ import annotations

import numpy as np
import pytest

from roadpreview.eval.experiments import ceiling_s, windowed_std

FPS = 30.0
F_PX = 707.0


def test_windowed_std_is_the_std_about_the_window_line() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(300) / FPS
    y = 0.8 * t + rng.normal(0.0, 0.5, t.size)
    s = windowed_std(t, y, 1.0, detrend=True)
    assert np.isnan(s[:29]).all()
    for i in (29, 150, 299):  # against numpy's polyfit on the same 30 frames
        tt, yy = t[i - 29 : i + 1], y[i - 29 : i + 1]
        resid = yy - np.polyval(np.polyfit(tt, yy, 1), tt)
        assert s[i] == pytest.approx(resid.std(), rel=1e-9)
    plain = windowed_std(t, y, 1.0, detrend=False)
    assert plain[150] == pytest.approx(y[121:151].std(), rel=1e-9)
    assert windowed_std(t, 2.0 * t + 1.0, 1.0, detrend=True)[100] == pytest.approx(0.0, abs=1e-9)


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
    got = ceiling_s(truth, F_PX, 1.0, detrend=True)
    want = windowed_std(t, lead, 1.0, detrend=True)
    inner = slice(int(2 * FPS), int(18 * FPS))  # away from the running mean's edges
    # the heave's running mean spans 91 frames (3.03 s), not whole periods of 1 Hz: it keeps
    # ~1 % of the 1 px heave signal, 0.02 px of s
    assert np.nanmax(np.abs(got[inner] - want[inner])) < 0.03  # px
    # and the camera's motion alone would have been a strong false signal
    camera_only = windowed_std(t, row - lead, 1.0, detrend=True)
    assert np.nanmedian(camera_only[inner]) > 2.0
    assert np.nanmax(got[inner]) == pytest.approx(np.nanmax(want[inner]), abs=0.03)
