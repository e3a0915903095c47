"""The road class estimate against the simulator's ISO 8608 roads."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.anomaly.roughness import RoadRoughness, RoughnessConfig, iso8608_class
from roadpreview.ego.vertical import EgoVerticalMonitor
from roadpreview.sim.road import RoadConfig, generate_road
from roadpreview.sim.vehicle import VehicleParams, simulate_vehicle
from roadpreview.types import RoadState


def test_class_boundaries_are_iso_8608() -> None:
    assert iso8608_class(16e-6) == "A"
    assert iso8608_class(33e-6) == "B"
    assert iso8608_class(256e-6) == "C"
    assert iso8608_class(1024e-6) == "D"
    assert iso8608_class(5000e-6) == "E"
    assert iso8608_class(1.0) == "H"
    assert iso8608_class(math.nan) is None
    assert iso8608_class(0.0) is None


def _ego_class(iso_class: str, speed_mps: float, anomalies_per_km: float = 0.0) -> RoadState:
    """The simulator's 7-DOF car (not the detector's nominal quarter car) on a random ISO
    road, 40 s: its IMU's vertical acceleration at 100 Hz through the ego monitor into the
    estimate, once per camera frame."""
    rng = np.random.default_rng(1)
    road = generate_road(
        RoadConfig(
            iso_class=iso_class,
            length_m=1200.0,
            hill_grade_pct=0.0,
            anomaly_density_per_km=anomalies_per_km,
        ),
        rng,
    )
    t = np.arange(0.0, 40.0, 0.002)
    car = simulate_vehicle(
        VehicleParams(), road, t, 50.0 + speed_mps * t, np.full_like(t, speed_mps), 0 * t, 0.0
    )
    t_imu = np.arange(0.0, 40.0, 0.01)
    accel_z = np.interp(t_imu, t, car.accel_world[:, 2]) + 9.81  # specific force, body up
    monitor, rough = EgoVerticalMonitor(), RoadRoughness()
    k = 0
    state = rough.state
    for tf in np.arange(0.0, 40.0, 1 / 30):  # camera frames
        while k < t_imu.size and t_imu[k] <= tf:
            monitor.push(float(t_imu[k]), float(accel_z[k]))
            k += 1
        ev = monitor.take()
        state = rough.push(
            float(tf),
            ego_speed_mps=speed_mps,
            ego_accel_rms_mps2=ev.rms_mps2,
            ego_accel_samples=ev.n_samples,
            lead_y_c_px=math.nan,
            lead_distance_m=math.nan,
            focal_px=math.nan,
            lead_valid=False,
        )
    return state


@pytest.mark.parametrize(("iso_class", "speed_mps"), [("B", 8.0), ("C", 20.0), ("E", 14.0)])
def test_the_ego_imu_gives_the_road_class(iso_class: str, speed_mps: float) -> None:
    state = _ego_class(iso_class, speed_mps)
    assert state.ego_class == iso_class
    assert state.iso_class == iso_class  # the ego's estimate is the one reported
    assert state.class_index == "ABCDEFGH".index(iso_class) + 1


def test_anomalies_on_the_road_do_not_raise_its_class() -> None:
    """A class B road with an anomaly every 60 m on average (bumps, potholes: each jolts a
    block or two of the last 20): the class is the road's, not the anomalies'."""
    with_anomalies = _ego_class("B", 10.0, anomalies_per_km=16.0)
    assert with_anomalies.ego_class == "B"
    clean = _ego_class("B", 10.0)
    assert with_anomalies.ego_gd_n0 < 2.0 * clean.ego_gd_n0


def test_no_speed_no_class() -> None:
    rough = RoadRoughness()
    for i in range(300):
        state = rough.push(
            i / 30,
            ego_speed_mps=None,
            ego_accel_rms_mps2=1.0,
            ego_accel_samples=3,
            lead_y_c_px=400.0,
            lead_distance_m=15.0,
            focal_px=1000.0,
            lead_valid=True,
        )
    assert state.iso_class is None
    assert state.class_index == 0


def test_the_lead_class_is_only_published_when_asked_for() -> None:
    """Off by default (its block variance is the compensation's residual, not the road):
    RoadClassLead stays UNKNOWN, whatever the lead does."""
    rng = np.random.default_rng(0)
    for enabled in (False, True):
        rough = RoadRoughness(RoughnessConfig(lead_estimate=enabled))
        for i in range(900):
            state = rough.push(
                i / 30,
                ego_speed_mps=10.0,
                ego_accel_rms_mps2=math.nan,
                ego_accel_samples=0,
                lead_y_c_px=400.0 + float(rng.normal(0.0, 2.0)),
                lead_distance_m=15.0,
                focal_px=1000.0,
                lead_valid=True,
            )
        assert (state.lead_class is not None) is enabled
        assert (state.iso_class is not None) is enabled  # no ego estimate: the lead's, if any
