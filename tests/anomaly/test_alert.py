"""Alerts: distance, time to arrival, height from f δ / d, side, confidence, suppression."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from roadpreview.anomaly import (
    AlertBuilder,
    AlertConfig,
    AnomalyEvent,
    DetectorConfig,
    SignalModel,
    WindowedStdDetector,
)
from roadpreview.errors import ConfigError
from roadpreview.types import FusionMode, Side, SuppressionReason


def _event(**changes: Any) -> AnomalyEvent:
    base = AnomalyEvent(
        t_s=10.0,
        t_peak_s=10.5,
        t_emit_s=11.5,
        s_px=2.0,
        s_left_px=2.0,
        s_right_px=2.0,
        threshold_px=1.0,
        side=Side.BOTH,
        lead_distance_m=25.0,
        lead_distance_std_m=0.5,
        ego_speed_mps=12.5,
        mode=FusionMode.FUSED,
        valid_fraction=1.0,
        suppressed=SuppressionReason.NONE,
    )
    return replace(base, **changes)


def test_a_bump_of_known_height_at_known_distance(make_trajectory: Any) -> None:
    """The lead rises by δ = 6 cm at d = 20 m, f = 1000 px: a step of f δ / d = 3 px.

    With the paper's s (eq. 1, ``detrend=False``) s peaks at half the step (1.5 px), so
    α = 0.5 (the calibration of a step) recovers δ exactly; α = 1 gives half of it.
    """
    f, delta, d, v = 1000.0, 0.06, 20.0, 10.0
    t = np.arange(180) / 30.0
    y = np.where(t >= 2.0, 380.0 - f * delta / d, 380.0)
    det = WindowedStdDetector(DetectorConfig(detrend=False, emit="peak"))
    run = det.run(make_trajectory(t, y, distance_m=d, speed_mps=v))
    [event] = run.alerts
    alert = AlertBuilder(signal=SignalModel(focal_px=f, alpha=0.5)).build(event)
    assert alert is not None
    assert alert.severity_px == pytest.approx(1.5, rel=1e-9)
    assert alert.height_mm == pytest.approx(60.0, rel=1e-9)
    assert alert.distance_m == pytest.approx(20.0)
    # 20 m at 10 m/s, less the 0.2 m the ego's front axle is ahead of its camera
    assert alert.time_to_arrival_s == pytest.approx(1.98)
    assert alert.t_s == pytest.approx(2.0)
    assert alert.arrival_t_s == pytest.approx(3.98)
    assert alert.time_left_s(alert.t_emit_s) == pytest.approx(3.98 - alert.t_emit_s)
    assert alert.side == Side.BOTH
    assert alert.mode == FusionMode.FUSED
    plain = AlertBuilder(signal=SignalModel(focal_px=f)).build(event)
    assert plain is not None
    assert plain.height_mm == pytest.approx(30.0, rel=1e-9)


def test_beta_is_the_noise_floor_of_the_height_model() -> None:
    signal = SignalModel(focal_px=1000.0, alpha=1.0, beta_px=0.5)
    alert = AlertBuilder(signal=signal).build(_event(s_px=2.0, lead_distance_m=25.0))
    assert alert is not None
    assert alert.height_mm == pytest.approx((2.0 - 0.5) * 25.0 / 1000.0 * 1000.0)


def test_unknowns_stay_unknown() -> None:
    builder = AlertBuilder()  # no focal length: no height
    a = builder.build(_event(ego_speed_mps=None))
    assert a is not None
    assert a.height_mm is None
    assert a.time_to_arrival_s is None
    assert a.arrival_t_s is None
    assert a.time_left_s(12.0) is None
    b = builder.build(_event(lead_distance_m=float("nan")))
    assert b is not None
    assert b.distance_m is None
    assert b.time_to_arrival_s is None
    c = builder.build(_event(ego_speed_mps=0.1))  # standstill
    assert c is not None
    assert c.time_to_arrival_s is None


def test_suppressed_events_give_no_alert() -> None:
    builder = AlertBuilder()
    assert builder.build(_event(suppressed=SuppressionReason.LEAD_ACCEL)) is None
    events = [_event(), _event(suppressed=SuppressionReason.DEGRADED), _event(t_s=20.0)]
    assert [a.t_s for a in builder.build_all(events)] == [10.0, 20.0]


def test_confidence() -> None:
    builder = AlertBuilder()
    at_threshold = builder.confidence(_event(s_px=1.0))
    twice = builder.confidence(_event(s_px=2.0))
    strong = builder.confidence(_event(s_px=10.0))
    assert at_threshold == 0.0
    assert twice == pytest.approx(0.75)
    assert at_threshold < twice < strong <= 1.0
    assert builder.confidence(_event(s_px=2.0, valid_fraction=0.5)) == pytest.approx(0.375)
    assert builder.confidence(_event(mode=FusionMode.IMU_ONLY)) == pytest.approx(0.75 * 0.6)
    assert builder.confidence(_event(mode=FusionMode.DEGRADED)) == 0.0
    with pytest.raises(ConfigError, match="mode_confidence"):
        AlertBuilder(AlertConfig(mode_confidence=(1.0, 1.0, 1.0, 2.0)))
