"""Ego confirmation on synthetic ego IMU traces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.anomaly.confirm import ConfirmConfig, EgoConfirmer
from roadpreview.types import Confirmation, ConfirmationResult, Side


def _drive(
    confirmer: EgoConfirmer,
    *,
    speed: float = 10.0,
    spikes: tuple[float, ...] = (),
    duration_s: float = 30.0,
    imu: bool = True,
    seed: int = 0,
) -> list[ConfirmationResult]:
    """Frames at 30 fps, the ego's per-frame acceleration peak: background ~0.3 m/s², a
    4 m/s² jolt over 0.1 s at each time in ``spikes``."""
    rng = np.random.default_rng(seed)
    out: list[ConfirmationResult] = []
    for t in np.arange(0.0, duration_s, 1 / 30):
        peak = abs(rng.normal(0.0, 0.3))
        if any(0.0 <= t - s < 0.1 for s in spikes):
            peak = 4.0
        out += confirmer.push(float(t), speed, peak if imu else math.nan)
    return out


def test_a_felt_anomaly_is_confirmed_where_the_odometry_puts_it() -> None:
    c = EgoConfirmer()
    c.add(1, t_s=10.0, distance_m=20.0, side=Side.BOTH)
    # the front axle is 0.2 m ahead of the camera: it reaches the spot after 19.8 m
    arrival = 10.0 + 19.8 / 10.0
    [r] = _drive(c, spikes=(arrival + 0.05,))
    assert r.outcome is Confirmation.CONFIRMED
    assert r.alert_id == 1
    assert r.t_arrival_s == pytest.approx(arrival, abs=1 / 30 + 1e-9)
    assert r.peak_mps2 == pytest.approx(4.0)
    assert r.background_mps2 < 0.5
    assert c.precision() == pytest.approx(2 / 3)  # (1 + 1) / (1 + 2)


def test_an_alert_made_after_its_crossing_counts_the_distance_driven_since() -> None:
    """Alerts are made a second or more after the lead's crossing: the ego's odometry from
    the crossing, not from the alert, places the spot."""
    c = EgoConfirmer()
    arrival = 10.0 + 19.8 / 10.0
    out = []
    rng = np.random.default_rng(0)
    for t in np.arange(0.0, 30.0, 1 / 30):
        if abs(t - 11.3) < 1 / 60:  # the alert about the crossing at 10 s, made at 11.3 s
            c.add(1, t_s=10.0, distance_m=20.0, side=Side.BOTH)
        peak = 4.0 if 0.0 <= t - (arrival + 0.05) < 0.1 else abs(rng.normal(0.0, 0.3))
        out += c.push(float(t), 10.0, peak)
    [r] = out
    assert r.outcome is Confirmation.CONFIRMED
    assert r.t_arrival_s == pytest.approx(arrival, abs=1 / 30 + 1e-9)


def test_nothing_felt_is_not_felt_unless_one_sided_or_without_imu() -> None:
    c = EgoConfirmer()
    c.add(1, t_s=10.0, distance_m=20.0, side=Side.BOTH)
    c.add(2, t_s=12.0, distance_m=15.0, side=Side.LEFT)  # may pass beside the ego's wheels
    out = {r.alert_id: r.outcome for r in _drive(c)}
    assert out == {1: Confirmation.NOT_FELT, 2: Confirmation.UNKNOWN}
    assert c.precision() == pytest.approx(1 / 3)  # (0 + 1) / (1 + 2)
    blind = EgoConfirmer()
    blind.add(3, t_s=10.0, distance_m=20.0, side=Side.BOTH)
    assert [r.outcome for r in _drive(blind, imu=False)] == [Confirmation.UNKNOWN]


def test_a_jolt_elsewhere_confirms_nothing() -> None:
    c = EgoConfirmer()
    c.add(1, t_s=10.0, distance_m=20.0, side=Side.BOTH)
    [r] = _drive(c, spikes=(16.0,))  # 4 s after the spot
    assert r.outcome is Confirmation.NOT_FELT


def test_a_spot_never_reached_is_unknown() -> None:
    c = EgoConfirmer(ConfirmConfig(max_wait_s=5.0))
    c.add(1, t_s=10.0, distance_m=20.0, side=Side.BOTH)
    [r] = _drive(c, speed=0.0)
    assert r.outcome is Confirmation.UNKNOWN
    assert math.isnan(r.t_arrival_s)
    assert c.pending == 0


def test_the_precision_follows_the_outcomes() -> None:
    c = EgoConfirmer()
    spikes = []
    for i, t in enumerate((5.0, 9.0, 13.0, 17.0)):
        c.add(i, t_s=t, distance_m=10.0, side=Side.BOTH)
        if i < 3:
            spikes.append(t + 9.8 / 10.0 + 0.05)
    out = _drive(c, spikes=tuple(spikes), duration_s=25.0)
    assert [r.outcome for r in out] == [Confirmation.CONFIRMED] * 3 + [Confirmation.NOT_FELT]
    assert c.precision() == pytest.approx((3 + 1) / (4 + 2))
    assert c.counts[Confirmation.CONFIRMED] == 3
