"""The vision's horizon pitch: the fused pitch without its slow part (road grade)."""

from __future__ import annotations

import math

import pytest

from roadpreview.camera import CameraModel
from roadpreview.pipeline.pipeline import Pipeline


def test_grade_is_removed_and_bump_pitching_kept() -> None:
    pipe = Pipeline(CameraModel.from_fov(1280, 720, 54.0))
    tau = pipe.config.fusion.horizon_highpass_s
    dt = 1 / 30
    grade = math.radians(1.5)  # a hill: the ego and the lead both pitch by it
    horizon = []
    for k in range(int(10 * tau / dt)):
        pipe._horizon.update(k * dt, grade)
        horizon.append(pipe.pitch_rad)
    assert horizon[0] == 0.0  # the first frame is the reference
    assert abs(horizon[-1]) < 1e-4 * grade  # after 10 time constants: gone
    # a 1 Hz pitch oscillation of 0.5 deg (a bump) passes with at most 10 % loss
    t0 = len(horizon) * dt
    amp = math.radians(0.5)
    out = []
    for k in range(int(5 / dt)):
        t = t0 + k * dt
        pipe._horizon.update(t, grade + amp * math.sin(2 * math.pi * t))
        out.append(pipe.pitch_rad)
    peak = max(abs(v) for v in out[len(out) // 2 :])
    assert peak == pytest.approx(amp, rel=0.1)
