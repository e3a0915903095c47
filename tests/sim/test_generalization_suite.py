"""The generalization suite: every drive is valid and the suite spans the promised ranges
(cameras, speeds, lead types, road classes, clean rough roads, one-sided potholes at
15-23 m, joints, night and fog). Configurations and kinematics only; one rendered frame."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from roadpreview.errors import ConfigError
from roadpreview.sim.imu import ImuConfig
from roadpreview.sim.motion import DriveMotion, simulate_motion
from roadpreview.sim.presets import (
    GENERALIZATION_DRIVES,
    GENERALIZATION_DURATION_S,
    LEAD_TYPES,
    expansion_joint,
    generalization,
    generalization_drive,
)
from roadpreview.sim.render import SceneRenderer
from roadpreview.sim.road import Anomaly, generate_road
from roadpreview.sim.scenario import ScenarioConfig
from roadpreview.sim.scene import generate_scene
from roadpreview.sim.types import Conditions
from roadpreview.sim.vehicle import VehicleParams

SUITE = generalization(seed=0)
BY_NAME = dict(SUITE)
#: joints are the only anomalies this short (potholes 0.5-0.9 m, bumps from 0.6 m)
JOINT_MAX_LENGTH_M = 0.25


def lead_type(name: str) -> str:
    """The lead type from a drive name ``gNN_<camera>_<lead>_<class>_<topic>``."""
    return name.split("_")[2]


def is_joint(a: Anomaly) -> bool:
    return a.length_m <= JOINT_MAX_LENGTH_M


def is_wheel_pothole(a: Anomaly, cfg: ScenarioConfig) -> bool:
    """A pothole under one lead wheel line only."""
    m = cfg.motion
    return a.kind == "pothole" and a.side(m.lead_lateral_m, m.lead.track_m) in ("left", "right")


@pytest.fixture(scope="module")
def drives() -> dict[str, DriveMotion]:
    """Each drive with anomalies, simulated without rendering. The crossings are kinematic:
    a 10 ms step gives the same sides, times and distances as the drive's 1 ms one
    (checked: within 1e-6 s and 1e-4 m) at a tenth of the cost."""
    return {
        name: simulate_motion(replace(cfg.motion, dt_s=0.01), np.random.default_rng(cfg.seed))
        for name, cfg in SUITE
        if cfg.motion.road.anomalies
    }


# -- lead types ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(LEAD_TYPES))
def test_lead_type_validates_and_is_plausible(name: str) -> None:
    p = LEAD_TYPES[name]
    p.validate(name)
    s = p.shape
    assert s.cg_to_front_m > p.cg_to_front_axle_m > 0.0
    assert s.cg_to_rear_m > p.cg_to_rear_axle_m > 0.0
    assert 1.4 <= p.track_m < s.width_m
    # overhangs of real cars and vans: 0.6-1.2 m
    assert 0.6 <= s.cg_to_front_m - p.cg_to_front_axle_m <= 1.2
    assert 0.6 <= s.cg_to_rear_m - p.cg_to_rear_axle_m <= 1.2
    # pitch inertia: dynamic index I / (m a b) of 0.8-1.2
    index = p.pitch_inertia_kgm2 / (p.sprung_mass_kg * p.cg_to_front_axle_m * p.cg_to_rear_axle_m)
    assert 0.8 <= index <= 1.2
    # the rates give back the ride frequencies: k_ride = k k_t / (k + k_t) = m_c (2 pi f)^2
    rates = p.rates()
    m_front = 0.5 * p.sprung_mass_kg * p.cg_to_rear_axle_m / p.wheelbase_m
    k, kt = rates.front_spring_npm, p.tyre_stiffness_npm
    f = math.sqrt(k * kt / (k + kt) / m_front) / (2 * math.pi)
    assert f == pytest.approx(p.front_ride_freq_hz, rel=1e-9)
    assert 1.0 <= p.front_ride_freq_hz <= p.rear_ride_freq_hz <= 2.0


def test_lead_types_span_small_car_to_van() -> None:
    assert set(LEAD_TYPES) == {"small-car", "mid-size", "suv", "van"}
    assert LEAD_TYPES["mid-size"] == VehicleParams()
    wheelbase = {k: p.wheelbase_m for k, p in LEAD_TYPES.items()}
    assert wheelbase["small-car"] == pytest.approx(2.45, abs=0.1)
    assert wheelbase["suv"] == pytest.approx(2.85, abs=0.1)
    assert wheelbase["van"] == pytest.approx(3.4, abs=0.1)
    order = ["small-car", "mid-size", "suv", "van"]
    for a, b in itertools.pairwise(order):
        pa, pb = LEAD_TYPES[a], LEAD_TYPES[b]
        assert pa.sprung_mass_kg < pb.sprung_mass_kg
        assert pa.wheelbase_m < pb.wheelbase_m
        assert pa.shape.length_m < pb.shape.length_m
        assert pa.shape.height_m < pb.shape.height_m
    van = LEAD_TYPES["van"].shape
    assert van.length_m >= 5.2
    assert van.width_m >= 1.95
    assert van.height_m >= 2.0


# -- joints -------------------------------------------------------------------------------------


@pytest.mark.parametrize("style", ["raised", "gap"])
def test_expansion_joint_spans_the_lane(style: str) -> None:
    a = expansion_joint(100.0, style=style)
    a.validate("joint")
    assert a.kind == ("bump" if style == "raised" else "pothole")
    assert 0.10 <= a.length_m <= 0.20
    assert 0.015 <= abs(a.height_m) <= 0.025
    assert (a.height_m > 0) == (style == "raised")
    # full width: the same height at the lane centre and just inside both lane edges
    h = a.height(a.apex_x_m, np.array([-1.7, 0.0, 1.7]))
    np.testing.assert_allclose(h, a.height_m)
    assert a.side(0.0, 1.55) == "both"
    assert a.height(a.apex_x_m, 1.8) == 0.0  # and not beyond the lane


def test_expansion_joint_rejects_an_unknown_style() -> None:
    with pytest.raises(ConfigError, match="style"):
        expansion_joint(10.0, style="finger")


def test_joints_in_the_suite_are_full_width() -> None:
    joints = [
        (name, cfg, a) for name, cfg in SUITE for a in cfg.motion.road.anomalies if is_joint(a)
    ]
    assert len(joints) >= 15
    assert {a.kind for _, _, a in joints} == {"bump", "pothole"}  # raised and open joints
    for name, cfg, a in joints:
        assert a.width_m == cfg.motion.road.lane_width_m, name
        assert a.center_y_m == 0.0, name
        assert 0.015 <= abs(a.height_m) <= 0.025, name
    for name, cfg in SUITE:
        if "joints" in name:
            assert sum(is_joint(a) for a in cfg.motion.road.anomalies) >= 5, name


# -- the drives ---------------------------------------------------------------------------------


def test_suite_names_and_seeds() -> None:
    assert len(SUITE) >= 10
    assert [n for n, _ in SUITE] == list(GENERALIZATION_DRIVES)
    assert len(set(GENERALIZATION_DRIVES)) == len(GENERALIZATION_DRIVES)
    for i, (name, cfg) in enumerate(SUITE):
        assert name.startswith(f"g{i + 1:02d}_{cfg.camera.width}x{cfg.camera.height}")
        assert cfg.name == name
        assert cfg.seed == i
    # the seed draws the roughness and the IMU clock, never the anomalies or the plan
    a, b = generalization_drive(SUITE[1][0], 0), generalization_drive(SUITE[1][0], 7)
    assert a.motion == b.motion
    assert a.imu != b.imu
    with pytest.raises(ConfigError, match="unknown"):
        generalization_drive("g99_nothing")


@pytest.mark.parametrize("name", GENERALIZATION_DRIVES)
def test_drive_validates_and_round_trips(name: str, tmp_path: Path) -> None:
    cfg = BY_NAME[name]
    cfg.validate()
    cfg.motion.road.validate("road")
    cfg.motion.lead.validate("lead")
    assert cfg.motion.duration_s == GENERALIZATION_DURATION_S == 60.0
    path = tmp_path / "scenario.toml"
    cfg.save(path)
    assert ScenarioConfig.load(path) == cfg


def test_cameras_differ_from_the_wild_set() -> None:
    cams = [(cfg.camera.width, cfg.camera.height, cfg.camera.fps) for _, cfg in SUITE]
    assert {(640, 360, 30.0), (960, 540, 25.0), (1920, 1080, 25.0)} <= set(cams)
    assert sum(fps == 60.0 for *_, fps in cams) <= 1
    assert all((w, h) == (1280, 720) for w, h, fps in cams if fps == 60.0)
    assert {fps for *_, fps in cams} <= {25.0, 30.0, 60.0}
    vfovs = {cfg.camera.vfov_deg for _, cfg in SUITE}
    assert len(vfovs - {54.0}) >= 3
    assert min(vfovs) <= 45.0
    assert max(vfovs) >= 60.0
    wild_cam = (1280, 720, 54.0, 30.0)
    for name, cfg in SUITE:
        c = cfg.camera
        assert (c.width, c.height, c.vfov_deg, c.fps) != wild_cam, name


def test_speeds_gaps_leads_and_classes() -> None:
    speeds = [k.speed_kmh for _, cfg in SUITE for k in cfg.motion.ego_speed_knots]
    assert min(speeds) == 15.0
    assert max(speeds) == 70.0
    gaps = [k.gap_m for _, cfg in SUITE for k in cfg.motion.gap_knots]
    assert min(gaps) >= 8.0
    assert max(gaps) <= 30.0
    assert {lead_type(n) for n, _ in SUITE} == set(LEAD_TYPES)
    for name, cfg in SUITE:
        assert cfg.motion.lead == LEAD_TYPES[lead_type(name)], name
        assert cfg.motion.road.iso_class == name.split("_")[3], name
        assert cfg.motion.oncoming_per_minute > 0, name
        assert abs(cfg.motion.ego_lateral_m) <= 0.2, name
        assert abs(cfg.motion.lead_lateral_m) <= 0.2, name
        # a smartphone IMU whose clock is 0-80 ms off, as in the wild preset
        assert cfg.imu_preset == "custom"
        assert cfg.imu is not None
        assert 0.0 <= cfg.imu.time_offset_s <= 0.08
        assert replace(cfg.imu, time_offset_s=0.0) == replace(
            ImuConfig.smartphone(), time_offset_s=0.0
        )
    assert {cfg.motion.road.iso_class for _, cfg in SUITE} == {"A", "B", "C", "D", "E"}


def test_clean_rough_roads_have_no_anomaly() -> None:
    clean = {cfg.motion.road.iso_class: cfg for _, cfg in SUITE if not cfg.motion.road.anomalies}
    assert set(clean) == {"D", "E"}
    for cfg in clean.values():
        assert cfg.motion.road.anomaly_density_per_km == 0.0
        road = generate_road(cfg.motion.road, np.random.default_rng(cfg.seed))
        assert road.anomalies == ()


def test_other_drives_have_four_to_seven_anomalies() -> None:
    for name, cfg in SUITE:
        n = len(cfg.motion.road.anomalies)
        assert n == 0 or 4 <= n <= 7, name
    kinds = {a.kind for _, cfg in SUITE for a in cfg.motion.road.anomalies}
    assert kinds == {"bump", "cushion", "pothole"}


def test_one_night_and_one_fog_drive() -> None:
    night = [(n, c) for n, c in SUITE if any(s.kind == "night" for s in c.conditions)]
    fog = [(n, c) for n, c in SUITE if any(s.kind == "fog" for s in c.conditions)]
    assert len(night) == 1
    assert len(fog) == 1
    _, cfg = night[0]
    t = cfg.frame_times()
    _, light, _ = cfg.visibility(t)
    np.testing.assert_allclose(light, 0.001)  # street-lit, the whole drive
    _, cfg = fog[0]
    density, _, _ = cfg.visibility(t := cfg.frame_times())
    assert 0.05 <= density.max() <= 0.075  # 40-60 m visibility (3 / density)
    foggy = density > 0
    assert 0.3 < foggy.mean() < 0.8  # part of the drive
    assert not foggy[0]
    assert not foggy[-1]


# -- ground truth of the crossings ------------------------------------------------------------


def test_every_anomaly_is_crossed_by_both_cars_in_the_open(drives: dict[str, DriveMotion]) -> None:
    assert len(drives) >= 8
    for name, drive in drives.items():
        d = drive.config.duration_s
        events = sorted(drive.events, key=lambda e: e.lead_front_t_s)
        assert len(events) == len(drive.config.road.anomalies)
        for e in events:
            times = (e.lead_front_t_s, e.lead_rear_t_s, e.ego_front_t_s, e.ego_rear_t_s)
            assert all(6.0 <= t <= d - 4.0 for t in times), (name, e.index, times)
            assert e.lead_hits, (name, e.index)
            assert e.ego_hits, (name, e.index)
            assert e.lead_side == e.ego_side, (name, e.index)
            assert not e.hard, (name, e.index)
        lead_t = np.array([e.lead_front_t_s for e in events])
        assert np.diff(lead_t).min() >= 3.0, name
        # the lead's distance stays realistic (the gap 8-30 m, the camera 1.2 m behind)
        dist = np.array([e.lead_distance_m for e in events])
        assert dist.min() >= 9.0, name
        assert dist.max() <= 32.0, name


def test_one_sided_potholes_under_one_lead_wheel(drives: dict[str, DriveMotion]) -> None:
    sides: list[str] = []
    for name, drive in drives.items():
        cfg = BY_NAME[name]
        m = cfg.motion
        for a, e in zip(drive.config.road.anomalies, drive.events, strict=True):
            assert e.apex_x_m == a.apex_x_m
            if not is_wheel_pothole(a, cfg):
                assert e.lead_side == "both", (name, e.index)
                continue
            half = 0.5 * m.lead.track_m
            wheels = (m.lead_lateral_m + half, m.lead_lateral_m - half)
            assert sum(bool(a.covers_y(y)) for y in wheels) == 1, (name, e.index)
            assert e.lead_side in ("left", "right")
            assert 0.06 <= -a.height_m <= 0.08
            assert 0.5 <= a.length_m <= 0.9
            assert 15.0 <= e.lead_distance_m <= 23.0, (name, e.index, e.lead_distance_m)
            sides.append(e.lead_side)
    assert sides.count("left") >= 2
    assert sides.count("right") >= 2


# -- one rendered frame -------------------------------------------------------------------------


def test_van_lead_renders_at_its_size() -> None:
    """One 640x360 frame of the van drive: the lead's box from the road to the roof is
    f * height / d pixels tall (d: camera to the van's rear face)."""
    name = next(n for n in GENERALIZATION_DRIVES if lead_type(n) == "van" and "640x360" in n)
    cfg = BY_NAME[name]
    t = 10.0
    motion = replace(cfg.motion, dt_s=0.01, duration_s=t + 1.0)
    drive = simulate_motion(motion, np.random.default_rng(cfg.seed))
    camera = cfg.camera_model()
    # the roadside up to the renderer's 300 m range past the camera, not the whole road, and
    # a shorter asphalt texture period (the texture costs most of the test's time)
    x_cam = drive.camera_pose_at(t).x_m
    scene = generate_scene(
        replace(cfg.scene, texture_period_m=24.0),
        seed=cfg.seed,
        length_m=x_cam + 300.0,
        road_height=lambda x, y: float(drive.road.slow_height(x, y)),
    )
    fog, light, tunnel = cfg.visibility(t)
    conditions = Conditions(
        fog_density_per_m=float(fog[0]), light=float(light[0]), tunnel=bool(tunnel[0])
    )
    frame = SceneRenderer(camera, scene, cfg.render).render(
        drive.camera_pose_at(t), drive.vehicles_at(t), conditions, np.random.default_rng(0)
    )
    assert frame.image.shape == (360, 640, 3)
    assert frame.lead_box is not None
    d = float(drive.lead_distance([t])[0])
    expected = camera.fy * LEAD_TYPES["van"].shape.height_m / d
    _, y0, _, y1 = frame.lead_box
    # tolerance: the road's roughness and the bodies' pitch move the ends by a few pixels
    assert y1 - y0 == pytest.approx(expected, rel=0.1)
    assert (frame.vehicle_mask == 1).sum() > 0.5 * expected**2


# -- the evaluation plan ------------------------------------------------------------------------


def test_full_plan_records_the_whole_suite_for_e6(tmp_path: Path) -> None:
    from roadpreview.eval.plan import EXPERIMENTS, EvalPlan

    plan = EvalPlan.full(seed=5)
    plan.validate()
    assert plan.generalization_drives == GENERALIZATION_DRIVES
    jobs = plan.jobs(tmp_path, ("e6",))
    assert list(jobs) == ["wild", "generalization"]
    gen = jobs["generalization"]
    assert [j.name for j in gen] == list(GENERALIZATION_DRIVES)
    for i, job in enumerate(gen):
        assert job.dataset == "generalization"
        assert job.folder == tmp_path / "data" / "generalization" / job.name
        assert job.scenario == generalization_drive(job.name, 5 + 2000 + i)
        assert job.n_frames == round(60.0 * job.scenario.camera.fps)
    # only E4 records the suite (fewer wild drives: the same logic, less to build)
    small = replace(plan, wild_drives=5, range_drives=5, range_sizes=((640, 360),))
    assert "generalization" not in small.jobs(tmp_path, ("e1", "e2", "e3", "e5"))
    assert "generalization" in small.jobs(tmp_path, EXPERIMENTS)


def test_quick_plan_has_no_generalization_drive(tmp_path: Path) -> None:
    from roadpreview.eval.plan import EXPERIMENTS, EvalPlan

    plan = EvalPlan.quick()
    plan.validate()
    assert plan.generalization_drives == ()
    assert "generalization" not in plan.jobs(tmp_path, EXPERIMENTS)


def test_plan_selects_drives_by_name_and_keeps_their_seeds(tmp_path: Path) -> None:
    import json

    from roadpreview.eval.plan import EvalPlan

    name = GENERALIZATION_DRIVES[3]
    plan = replace(EvalPlan.quick(), generalization_drives=(name,))
    plan.validate()
    (job,) = plan.jobs(tmp_path, ("e6",))["generalization"]
    assert job.scenario.seed == 2003
    report = json.loads(json.dumps(plan.as_dict()))
    assert report["generalization_drives"] == [name]
    with pytest.raises(ConfigError, match="g99_nothing"):
        replace(plan, generalization_drives=("g99_nothing",)).validate()
