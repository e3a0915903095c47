"""Drive motion: event timing and sides, the hard flag, braking, camera, traffic, config."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from roadpreview.configtools import from_mapping, to_mapping
from roadpreview.errors import ConfigError
from roadpreview.sim.motion import (
    GapKnot,
    LeadEvent,
    MotionConfig,
    SpeedKnot,
    TrafficVehicle,
    camera_pose_at,
    camera_track,
    simulate_motion,
)
from roadpreview.sim.road import Anomaly, RoadConfig, paper_speed_bump
from roadpreview.sim.vehicle import VehicleModel

V = 10.0  # m/s = 36 km/h


def flat_config(anomalies: list[Anomaly] | None = None, **kw: Any) -> MotionConfig:
    """A level, smooth road with only the given anomalies; constant 36 km/h; no traffic."""
    road = RoadConfig(iso_class="off", hill_grade_pct=0.0, cross_slope_pct=0.0,
                      anomaly_density_per_km=0.0, anomalies=anomalies or [], length_m=400.0)
    base: dict[str, Any] = dict(road=road, ego_speed_kmh=V * 3.6, duration_s=15.0,
                                oncoming_per_minute=0.0, ego_start_x_m=20.0, gap_m=12.0)
    base.update(kw)
    return MotionConfig(**base)


def lead_start_x(cfg: MotionConfig) -> float:
    return cfg.ego_start_x_m + cfg.ego.shape.cg_to_front_m + cfg.gap_m + cfg.lead.shape.cg_to_rear_m


def test_axle_crossing_times_and_lead_distance_at_constant_speed() -> None:
    bump = paper_speed_bump(120.0)
    cfg = flat_config([bump])
    drive = simulate_motion(cfg, np.random.default_rng(0))
    (ev,) = drive.events
    x_lead, x_ego = lead_start_x(cfg), cfg.ego_start_x_m
    assert ev.kind == "bump"
    assert ev.lead_front_t_s == pytest.approx((bump.apex_x_m - x_lead - cfg.lead.cg_to_front_axle_m)
                                              / V, abs=cfg.dt_s)
    assert ev.lead_rear_t_s == pytest.approx((bump.apex_x_m - x_lead + cfg.lead.cg_to_rear_axle_m)
                                             / V, abs=cfg.dt_s)
    assert ev.ego_front_t_s == pytest.approx((bump.apex_x_m - x_ego - cfg.ego.cg_to_front_axle_m)
                                             / V, abs=cfg.dt_s)
    assert ev.ego_rear_t_s == pytest.approx((bump.apex_x_m - x_ego + cfg.ego.cg_to_rear_axle_m)
                                            / V, abs=cfg.dt_s)
    assert ev.lead_side == ev.ego_side == "both"
    assert ev.lead_hits
    assert ev.ego_hits
    assert not ev.hard
    # camera to lead rear = gap + (ego CG to front face - camera ahead of CG); ego still level
    expected = cfg.gap_m + cfg.ego.shape.cg_to_front_m - cfg.camera_forward_m
    assert ev.lead_distance_m == pytest.approx(expected, abs=1e-3)
    np.testing.assert_allclose(drive.lead_distance([0.0, 3.0]), expected, atol=1e-3)
    np.testing.assert_allclose(drive.gap, cfg.gap_m, atol=1e-9)
    # the lead rises on the bump right after its front axle reaches it
    i = drive.t.searchsorted(ev.lead_front_t_s)
    assert drive.lead.heave[i: i + 400].max() > 0.02
    assert np.abs(drive.lead.heave[: i - 200]).max() < 1e-9


def test_anomaly_beyond_the_drive_has_nan_times() -> None:
    cfg = flat_config([paper_speed_bump(380.0)], duration_s=5.0)
    (ev,) = simulate_motion(cfg, np.random.default_rng(0)).events
    assert math.isnan(ev.lead_front_t_s)
    assert math.isnan(ev.ego_rear_t_s)
    assert not ev.lead_hits
    assert not ev.ego_hits
    assert math.isnan(ev.lead_distance_m)


def test_left_track_pothole_hit_by_centred_lead_missed_by_offset_ego() -> None:
    track = 1.55
    hole = Anomaly(kind="pothole", start_x_m=100.0, length_m=0.8, height_m=-0.06,
                   center_y_m=track / 2, width_m=0.5)
    cfg = flat_config([hole], ego_lateral_m=-track)
    drive = simulate_motion(cfg, np.random.default_rng(0))
    (ev,) = drive.events
    assert ev.lead_side == "left"
    assert ev.lead_hits
    assert ev.ego_side == "none"
    assert not ev.ego_hits
    assert not math.isnan(ev.ego_front_t_s)  # the ego does pass it, beside its wheels
    # the lead's left wheels drop in: left side down (negative roll); the right ones stay level
    assert drive.lead.wheel_road[:, 0].min() < -0.03
    assert np.abs(drive.lead.wheel_road[:, 1]).max() == 0.0
    assert drive.lead.roll.min() < -1e-3
    assert np.abs(drive.ego.roll).max() < 1e-9
    assert np.abs(drive.ego.heave).max() < 1e-9
    # an ego offset to the left by a track runs its right wheels through it
    left = simulate_motion(dataclasses.replace(cfg, ego_lateral_m=track),
                           np.random.default_rng(0))
    assert left.events[0].ego_side == "right"
    assert left.ego.roll.max() > 1e-3  # right side down: positive roll


def test_hard_flag_when_the_ego_hits_another_anomaly_at_the_same_time() -> None:
    cfg = flat_config()
    x_lead, x_ego = lead_start_x(cfg), cfg.ego_start_x_m
    # the ego's front axle is this far behind the lead's
    spacing = (x_lead + cfg.lead.cg_to_front_axle_m) - (x_ego + cfg.ego.cg_to_front_axle_m)
    first = paper_speed_bump(150.0)
    second = paper_speed_bump(150.0 - spacing + 0.3 * V)  # ego crosses 0.3 s after the lead
    far = Anomaly(kind="pothole", start_x_m=250.0, length_m=0.5, height_m=-0.04, width_m=3.0)
    drive = simulate_motion(dataclasses.replace(
        cfg, road=dataclasses.replace(cfg.road, anomalies=[first, second, far])),
        np.random.default_rng(0))
    by_x = {round(e.apex_x_m): e for e in drive.events}
    hard = by_x[round(first.apex_x_m)]
    assert hard.hard
    assert by_x[round(second.apex_x_m)].ego_front_t_s == pytest.approx(
        hard.lead_front_t_s + 0.3, abs=2 * cfg.dt_s)
    assert not by_x[round(second.apex_x_m)].hard
    assert not by_x[round(far.apex_x_m)].hard


def test_lead_braking_dives_the_lead_then_the_ego() -> None:
    brake = LeadEvent(t_s=3.0, accel_mps2=-3.0, duration_s=2.0, ramp_s=0.3)
    cfg = flat_config(duration_s=10.0, lead_events=[brake], reaction_s=1.0)
    drive = simulate_motion(cfg, np.random.default_rng(0))
    p = cfg.lead
    rates = VehicleModel(p).rates
    kt = p.tyre_stiffness_npm
    kf = rates.front_spring_npm * kt / (rates.front_spring_npm + kt)
    kr = rates.rear_spring_npm * kt / (rates.rear_spring_npm + kt)
    k_zz, k_zt = 2 * (kf + kr), 2 * (kf * p.cg_to_front_axle_m - kr * p.cg_to_rear_axle_m)
    k_tt = 2 * (kf * p.cg_to_front_axle_m**2 + kr * p.cg_to_rear_axle_m**2)
    static = p.sprung_mass_kg * brake.accel_mps2 * p.shape.cg_height_m / (k_tt - k_zt**2 / k_zz)
    during = (drive.t > 4.2) & (drive.t < 4.6)  # settled while braking
    assert drive.lead.pitch[during].mean() == pytest.approx(static, rel=0.1)
    assert np.abs(drive.lead.pitch[drive.t < 3.0]).max() < 1e-9
    # the ego repeats it one reaction time later
    t_lead = drive.t[np.argmin(drive.lead.pitch)]
    t_ego = drive.t[np.argmin(drive.ego.pitch)]
    assert t_ego - t_lead == pytest.approx(1.0, abs=0.01)
    # both lose 3 m/s^2 * (2 - 0.3) s; the gap shrinks by that times the reaction time
    assert drive.lead.v[-1] == pytest.approx(V - 3.0 * 1.7, abs=1e-6)
    assert drive.gap[-1] == pytest.approx(cfg.gap_m - 3.0 * 1.7 * 1.0, abs=1e-3)
    assert drive.lead.accel_world[:, 0].min() == pytest.approx(-3.0)


def test_camera_rides_on_the_ego_body() -> None:
    cfg = flat_config([paper_speed_bump(60.0)])
    drive = simulate_motion(cfg, np.random.default_rng(0))
    ego = drive.ego
    rest = camera_pose_at(ego, cfg.camera_forward_m, cfg.camera_height_m, 0.5)
    assert rest.z_m == pytest.approx(cfg.camera_height_m, abs=1e-12)
    assert rest.x_m == pytest.approx(cfg.ego_start_x_m + V * 0.5 + cfg.camera_forward_m)
    assert rest.pitch_rad == pytest.approx(0.0, abs=1e-12)
    times = drive.t[::250]
    track = camera_track(ego, cfg.camera_forward_m, cfg.camera_height_m, times)
    np.testing.assert_allclose(track.pitch, ego.pitch[::250], atol=1e-15)
    i = int(np.argmax(np.abs(track.pitch)))
    assert abs(track.pitch[i]) > 0.005
    assert drive.camera_pose_at(float(times[i])) == track.pose(i)
    # small-angle form of docs/method.md: z_cam = z_cg + a sin(pitch) + (h - h_cg) cos(pitch)
    s = ego.sample([times[i]])
    up = cfg.camera_height_m - cfg.ego.shape.cg_height_m
    expected_z = s.z[0] + cfg.camera_forward_m * math.sin(s.pitch[0]) + up * math.cos(s.pitch[0])
    assert track.position[i, 2] == pytest.approx(expected_z, abs=1e-12)


def test_traffic_poses() -> None:
    car = TrafficVehicle(direction="oncoming", start_x_m=300.0, lateral_m=3.5, speed_kmh=54.0)
    cfg = flat_config(traffic=[car], oncoming_per_minute=0.0)
    drive = simulate_motion(cfg, np.random.default_rng(0))
    (traj,) = drive.traffic
    pose = traj.pose_at(4.0)
    assert pose.x_m == pytest.approx(300.0 - 15.0 * 4.0)
    assert pose.yaw_rad == pytest.approx(math.pi)
    assert pose.z_m == pytest.approx(car.shape.cg_height_m)
    assert [v.vehicle_id for v in drive.vehicles_at(1.0)] == [1, 2]
    busy = simulate_motion(dataclasses.replace(cfg, traffic=[], oncoming_per_minute=30.0,
                                               duration_s=20.0), np.random.default_rng(3))
    assert 5 <= len(busy.traffic) <= 30  # Poisson, mean 15
    assert all(tr.velocity_mps < 0 for tr in busy.traffic)


def test_same_seed_same_drive() -> None:
    cfg = MotionConfig(duration_s=8.0, gap_knots=[GapKnot(0.0, 10.0), GapKnot(6.0, 25.0)],
                       ego_speed_knots=[SpeedKnot(0.0, 30.0), SpeedKnot(5.0, 45.0)],
                       lead_events=[LeadEvent(t_s=2.0)])
    a = simulate_motion(cfg, np.random.default_rng(42))
    b = simulate_motion(cfg, np.random.default_rng(42))
    c = simulate_motion(cfg, np.random.default_rng(43))
    for name in ("z", "pitch", "roll", "accel_world", "x"):
        np.testing.assert_array_equal(getattr(a.ego, name), getattr(b.ego, name))
        np.testing.assert_array_equal(getattr(a.lead, name), getattr(b.lead, name))
    assert a.events == b.events
    assert [t.start_x_m for t in a.traffic] == [t.start_x_m for t in b.traffic]
    assert not np.array_equal(a.ego.z, c.ego.z)
    # the gap follows its knots smoothly: the quintic has no jumps in its second derivative
    # (jerk <= 15 m * 60 / (6 s)^3 = 4.2 m/s^3), the lead's and the ego's brake ramps change
    # their accelerations by 10 m/s^3 each, so lead.a - ego.a moves < 0.025 m/s^2 a step ...
    assert a.gap[0] == pytest.approx(10.0, abs=1e-9)
    assert np.abs(np.diff(a.lead.a - a.ego.a)).max() < 0.025
    # ... and ends 3 m/s^2 * 1.2 s * 1 s reaction short of the last knot after the braking
    assert a.gap[-1] == pytest.approx(25.0 - 3.0 * 1.2 * 1.0, abs=1e-3)


@pytest.mark.parametrize(
    ("data", "field"),
    [
        ({"ego": {"wheelz": 4}}, r"motion\.ego\.wheelz"),
        ({"ego_speed_kmh": -20.0}, r"motion\.ego_speed_kmh"),
        ({"ego_speed_knots": [{"t_s": 0.0, "speed_kmh": -5.0}]},
         r"motion\.ego_speed_knots\[0\]\.speed_kmh"),
        ({"gap_m": 1.0}, r"motion\.gap_m"),  # below the 2 m least gap (and the car length)
        ({"gap_knots": [{"t_s": 0.0, "gap_m": 20.0}, {"t_s": 5.0, "gap_m": 0.5}]},
         r"motion\.gap_knots\[1\]\.gap_m"),
        ({"gap_knots": [{"t_s": 0.0, "gap_m": 40.0}, {"t_s": 0.5, "gap_m": 3.0}]},
         r"motion\.gap_knots: the gap shrinks"),
        ({"lead_events": [{"t_s": 1.0, "accel_mps2": -8.0, "duration_s": 3.0}],
          "ego_follows_lead_events": False}, r"motion\.lead_events: the lead would reverse"),
        ({"lead_events": [{"t_s": 1.0, "accel_mps2": -7.0, "duration_s": 1.2}],
          "reaction_s": 3.0}, r"motion\.lead_events: the gap falls"),
        ({"duration_s": 200.0, "ego_speed_kmh": 60.0}, r"motion\.road\.length_m"),
        ({"ego_speed_knots": [{"t_s": 2.0}, {"t_s": 1.0}]}, r"ego_speed_knots\[1\]\.t_s"),
    ],
)
def test_bad_config_names_the_field(data: dict[str, Any], field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        from_mapping(MotionConfig, data, where="motion")


def test_config_round_trip_from_mapping() -> None:
    cfg = from_mapping(MotionConfig, {
        "duration_s": 5.0, "ego_lateral_m": 0.5,
        "road": {"iso_class": "A", "anomalies": [{"kind": "step", "height_m": -0.02,
                                                   "length_m": 0.0, "start_x_m": 80.0}]},
        "lead": {"model": "3dof", "front_ride_freq_hz": 1.5},
        "traffic": [{"direction": "same", "lateral_m": -3.5, "start_x_m": 60.0,
                     "shape": {"length_m": 9.0, "cg_to_front_m": 4.0, "height_m": 3.4}}],
    })
    assert cfg.lead.model == "3dof"
    assert cfg.traffic[0].shape.length_m == 9.0
    assert from_mapping(MotionConfig, to_mapping(cfg)) == cfg
    drive = simulate_motion(cfg, np.random.default_rng(0))
    assert drive.events[0].kind == "step"
