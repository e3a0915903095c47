"""Named scenarios: the paper's controlled experiment, random ``wild`` drives,
``texture-loss`` drives, the ``demo`` drive and the ``generalization`` suite.

A preset is a function ``seed -> ScenarioConfig``. Everything random about the
scenario itself (speed plan, gap plan, manoeuvres, lines) is drawn here from the
seed and written out explicitly in ``scenario.toml``; everything random inside
the simulation (road roughness, random anomalies, traffic, sensor noise) is
drawn from the same seed by the simulator. Either way the drive regenerates bit
for bit.

The generalization suite (`generalization`, `generalization_drive`) is a fixed set of
named drives whose cameras, speeds, lead vehicles (`LEAD_TYPES`), roads and anomalies
differ from the ``wild`` set's; no detector is tuned on them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from roadpreview.errors import ConfigError
from roadpreview.sim.imu import ImuConfig
from roadpreview.sim.motion import GapKnot, LeadEvent, MotionConfig, SpeedKnot, _kinematics
from roadpreview.sim.road import Anomaly, RoadConfig, paper_speed_bump
from roadpreview.sim.scenario import CameraSpec, ConditionSegment, ScenarioConfig
from roadpreview.sim.types import VehicleShape
from roadpreview.sim.vehicle import VehicleParams

#: the ego starts here (m); the road begins at X = 0
_EGO_START_M = 30.0


def _road_length(duration_s: float, max_speed_kmh: float) -> float:
    """Road long enough for the drive plus the lead ahead and a margin."""
    return _EGO_START_M + duration_s * max_speed_kmh / 3.6 + 120.0


def controlled(seed: int = 0, *, gap_m: float = 10.0, speed_kmh: float = 20.0) -> ScenarioConfig:
    """The paper's controlled experiment: two cars over three 6 cm speed bumps
    (2 m long, 7 deg ramps) at about 20 km/h on a smooth road, at a fixed gap."""
    bumps = [paper_speed_bump(x) for x in (70.0, 130.0, 190.0)]
    duration = (195.0 - _EGO_START_M + 8.0) / (speed_kmh / 3.6)
    motion = MotionConfig(
        road=RoadConfig(
            iso_class="A",
            length_m=400.0,
            hill_grade_pct=0.5,
            anomalies=bumps,
            anomaly_density_per_km=0.0,
        ),
        duration_s=round(duration, 1),
        ego_speed_kmh=speed_kmh,
        ego_start_x_m=_EGO_START_M,
        gap_m=gap_m,
        oncoming_per_minute=0.0,
    )
    return ScenarioConfig(name="controlled", seed=seed, motion=motion)


def wild(seed: int = 0, *, duration_s: float = 60.0) -> ScenarioConfig:
    """A random drive: rough road, random anomalies, varying speed and gap, lead
    manoeuvres, oncoming traffic; the ego on its own line."""
    rng = np.random.default_rng([seed, 0x57])
    n_knots = max(2, int(duration_s // 15) + 1)
    speed_knots = [
        SpeedKnot(t_s=round(float(t), 2), speed_kmh=round(float(rng.uniform(20.0, 60.0)), 1))
        for t in np.linspace(0.0, duration_s, n_knots)
    ]
    gap_knots = [
        GapKnot(t_s=round(float(t), 2), gap_m=round(float(rng.uniform(5.0, 35.0)), 1))
        for t in np.linspace(0.0, duration_s, max(2, int(duration_s // 10) + 1))
    ]
    knot_t = [k.t_s for k in speed_knots]
    knot_v = [k.speed_kmh / 3.6 for k in speed_knots]
    events = []
    shed = 0.0  # speed already taken off by earlier manoeuvres (it is not given back)
    for t in np.sort(rng.uniform(5.0, duration_s - 5.0, rng.integers(0, 3))):
        accel = float(rng.uniform(-4.0, -1.5))
        # a manoeuvre, not a stop: shed at most 40 % of the slowest planned speed still to
        # come (ramps 0.3 s), so that neither car ever reverses
        later = np.linspace(t, duration_s, 50)
        v_floor = float(np.min(np.interp(later, knot_t, knot_v))) - shed
        duration = min(float(rng.uniform(1.0, 2.5)), 0.3 + 0.4 * v_floor / abs(accel))
        if duration <= 0.7:
            continue
        shed += abs(accel) * (duration - 0.3)
        events.append(
            LeadEvent(
                t_s=round(float(t), 2),
                accel_mps2=round(accel, 2),
                duration_s=round(duration, 2),
            )
        )
    motion = MotionConfig(
        road=RoadConfig(
            iso_class=str(rng.choice(["B", "C", "C", "D"])),
            length_m=_road_length(duration_s, 60.0),
            anomaly_density_per_km=30.0,
            anomaly_min_spacing_m=12.0,
        ),
        duration_s=duration_s,
        ego_speed_knots=speed_knots,
        ego_start_x_m=_EGO_START_M,
        gap_knots=gap_knots,
        ego_lateral_m=round(float(np.clip(rng.normal(0.0, 0.3), -0.6, 0.6)), 2),
        lead_lateral_m=round(float(np.clip(rng.normal(0.0, 0.2), -0.4, 0.4)), 2),
        lead_events=events,
        oncoming_per_minute=3.0,
    )
    # a manoeuvre that would close the gap below the minimum (the ego repeats it after
    # its reaction time) is dropped, latest first: deterministic for the seed
    while motion.lead_events:
        try:
            motion.validate("motion")
            break
        except ConfigError:
            motion = replace(motion, lead_events=motion.lead_events[:-1])
    # a smartphone-grade IMU whose clock is off by an unknown 0-80 ms (CAN / app latency)
    imu = replace(ImuConfig.smartphone(), time_offset_s=round(float(rng.uniform(0.0, 0.08)), 4))
    return ScenarioConfig(name="wild", seed=seed, motion=motion, imu_preset="custom", imu=imu)


def mounted_imu(seed: int = 0, *, duration_s: float = 60.0) -> ScenarioConfig:
    """A ``wild`` drive for self-calibration (``roadpreview calibrate``): the phone IMU lies
    rotated in its holder (90 deg yaw, 5 deg pitch) with its clock 60 ms late, and the
    camera looks 2 deg down and 1 deg to the left of the direction of travel."""
    cfg = wild(seed, duration_s=duration_s)
    imu = replace(ImuConfig.smartphone(), time_offset_s=0.060, mount_ypr_deg=(90.0, 5.0, 0.0))
    t = np.array([math.tan(math.radians(1.0)), -math.tan(math.radians(2.0)), 1.0])
    t /= np.linalg.norm(t)
    camera = replace(cfg.camera, forward=(float(t[0]), float(t[1]), float(t[2])))
    return replace(cfg, name="mounted-imu", imu=imu, camera=camera)


def texture_loss(seed: int = 0, *, duration_s: float = 60.0) -> ScenarioConfig:
    """A ``wild`` drive with a fog bank, a tunnel and a night stretch, each about 10 s."""
    base = wild(seed, duration_s=duration_s)
    d = duration_s
    conditions = [
        ConditionSegment(kind="fog", start_s=0.12 * d, end_s=0.32 * d),
        ConditionSegment(kind="tunnel", start_s=0.45 * d, end_s=0.62 * d, ramp_s=0.0),
        ConditionSegment(kind="night", start_s=0.75 * d, end_s=0.93 * d),
    ]
    return replace(base, name="texture-loss", conditions=conditions)


def demo(seed: int = 0) -> ScenarioConfig:
    """About 60 s at 720p that shows everything: the lead over bumps, a pothole and a
    cushion, the ego pitching over the same bumps on an ISO class B road with hills, a fog
    bank (the IMU has to carry the pitch). On class C the lead's own bouncing rivals the
    bumps in s(t) at the default threshold (docs/pipeline.md)."""
    anomalies = [
        paper_speed_bump(95.0),
        paper_speed_bump(175.0),
        Anomaly(
            kind="pothole",
            start_x_m=250.0,
            length_m=0.8,
            height_m=-0.06,
            center_y_m=0.8,
            width_m=0.7,
            ramp_m=0.05,
        ),
        paper_speed_bump(330.0),
        Anomaly(
            kind="cushion",
            start_x_m=405.0,
            length_m=3.0,
            height_m=0.07,
            center_y_m=0.0,
            width_m=1.9,
            ramp_m=0.8,
        ),
        paper_speed_bump(480.0),
    ]
    motion = MotionConfig(
        road=RoadConfig(
            iso_class="B",
            length_m=700.0,
            hill_grade_pct=2.0,
            anomalies=anomalies,
            anomaly_density_per_km=0.0,
        ),
        duration_s=60.0,
        ego_speed_kmh=30.0,
        ego_start_x_m=_EGO_START_M,
        gap_knots=[
            GapKnot(t_s=0.0, gap_m=9.0),
            GapKnot(t_s=20.0, gap_m=14.0),
            GapKnot(t_s=40.0, gap_m=18.0),
            GapKnot(t_s=60.0, gap_m=10.0),
        ],
        oncoming_per_minute=3.0,
    )
    return ScenarioConfig(
        name="demo",
        seed=seed,
        motion=motion,
        camera=CameraSpec(width=1280, height=720),
        conditions=[
            ConditionSegment(
                kind="fog", start_s=34.5, end_s=40.5, fog_density_per_m=0.2, ramp_s=1.0
            )
        ],
    )


# -- the generalization suite -----------------------------------------------------------

#: lead vehicle types of the generalization suite (name -> parameters).
#:
#: Rounded typical values, not one model's data sheet: overall sizes, wheelbases and
#: tracks as published for B-segment hatchbacks (VW Polo / Toyota Yaris class), large
#: crossover SUVs (Audi Q5 / Toyota Highlander class) and mid-size vans (Renault Trafic /
#: Ford Transit Custom L2H1 class); sprung mass = kerb mass + driver - unsprung masses;
#: front/rear static load 60/40 (small car), 54/46 (SUV), 55/45 (unladen van); pitch
#: inertia = dynamic index x m a b with an index of 0.95 (cars) to 1.05 (the van's long
#: overhangs); ride frequencies as in the vehicle-dynamics textbooks (Gillespie,
#: *Fundamentals of Vehicle Dynamics*: cars 1.0-1.5 Hz, the rear a little higher, light
#: commercials stiffer, most of all at the rear that carries the payload); wheel radius
#: from the tyre size (185/65 R15, 235/55 R19, 215/65 R16C); tyre rates 200-350 kN/m
#: (commercial "C" tyres stiffest). "mid-size" is the simulator's default car.
LEAD_TYPES: dict[str, VehicleParams] = {
    "small-car": VehicleParams(
        sprung_mass_kg=1000.0,  # ~1120 kg kerb + driver - 4 corners
        pitch_inertia_kgm2=1370.0,  # 0.95 * m * a * b
        roll_inertia_kgm2=330.0,
        cg_to_front_axle_m=0.98,  # wheelbase 2.45 m, 60 % on the front axle
        cg_to_rear_axle_m=1.47,
        track_m=1.48,
        front_ride_freq_hz=1.3,  # short, light cars ride a little stiffer
        rear_ride_freq_hz=1.5,
        front_damping_ratio=0.3,
        rear_damping_ratio=0.3,
        front_unsprung_kg=32.0,
        rear_unsprung_kg=27.0,
        tyre_stiffness_npm=200e3,  # 185/65 R15
        wheel_radius_m=0.31,
        contact_length_m=0.13,
        shape=VehicleShape(
            length_m=4.05,  # overhangs 0.85 m front, 0.75 m rear
            width_m=1.75,
            height_m=1.46,
            ground_clearance_m=0.14,
            cg_to_front_m=1.83,
            cg_height_m=0.52,
        ),
    ),
    "mid-size": VehicleParams(),
    "suv": VehicleParams(
        sprung_mass_kg=1800.0,  # ~1950 kg kerb + driver - 4 corners
        pitch_inertia_kgm2=3450.0,  # 0.95 * m * a * b
        roll_inertia_kgm2=850.0,
        cg_to_front_axle_m=1.31,  # wheelbase 2.85 m, 54 % on the front axle
        cg_to_rear_axle_m=1.54,
        track_m=1.64,
        front_ride_freq_hz=1.25,  # a little stiffer than the mid-size car (roll, load)
        rear_ride_freq_hz=1.45,
        front_damping_ratio=0.3,
        rear_damping_ratio=0.3,
        front_unsprung_kg=55.0,
        rear_unsprung_kg=50.0,
        tyre_stiffness_npm=300e3,  # 235/55 R19
        wheel_radius_m=0.37,
        contact_length_m=0.17,
        shape=VehicleShape(
            length_m=4.85,  # overhangs 0.95 m front, 1.05 m rear
            width_m=1.93,
            height_m=1.75,
            ground_clearance_m=0.20,
            cg_to_front_m=2.26,
            cg_height_m=0.70,
        ),
    ),
    "van": VehicleParams(
        sprung_mass_kg=2050.0,  # ~1950 kg kerb + driver + a light load - 4 corners
        pitch_inertia_kgm2=6200.0,  # 1.05 * m * a * b
        roll_inertia_kgm2=1300.0,
        cg_to_front_axle_m=1.53,  # wheelbase 3.40 m, 55 % on the front axle (unladen)
        cg_to_rear_axle_m=1.87,
        track_m=1.62,
        front_ride_freq_hz=1.4,  # light commercial: stiff, the rear sprung for the payload
        rear_ride_freq_hz=1.8,
        front_damping_ratio=0.3,
        rear_damping_ratio=0.25,  # an unladen rear is under-damped
        front_unsprung_kg=55.0,
        rear_unsprung_kg=65.0,
        tyre_stiffness_npm=350e3,  # 215/65 R16C
        wheel_radius_m=0.34,
        contact_length_m=0.18,
        shape=VehicleShape(
            length_m=5.30,  # overhangs 0.95 m front and rear
            width_m=2.00,
            height_m=2.00,
            ground_clearance_m=0.18,
            cg_to_front_m=2.48,
            cg_height_m=0.85,
        ),
    ),
}

#: the lane width every suite drive uses (the `RoadConfig` default), m
_LANE_WIDTH_M = RoadConfig().lane_width_m
#: length of every suite drive, s
GENERALIZATION_DURATION_S = 60.0


def expansion_joint(
    start_x_m: float,
    *,
    style: str = "raised",
    length_m: float | None = None,
    height_m: float | None = None,
    lane_width_m: float = _LANE_WIDTH_M,
) -> Anomaly:
    """A transverse expansion joint across the whole lane, from the existing anomaly kinds.

    The simulator has no joint kind; a joint is a narrow feature spanning the lane (both
    wheel tracks of any vehicle hit it at once), either

    * ``style="raised"``: a ``bump`` ``length_m`` = 0.15 m long (0.10-0.20: the width of a
      steel or elastomer joint or an asphaltic plug) standing ``height_m`` = 2 cm
      (1.5-2.5 cm) proud of the surface, with 2 cm bevelled edges; or
    * ``style="gap"``: an open gap, a full-width shallow ``pothole`` 0.10 m long and 2 cm
      deep with vertical walls.

    ``height_m`` is a magnitude (the gap's sign is applied here). The tyre envelope of the
    vehicle model bridges much of either, as a real wheel does.
    """
    if style == "raised":
        length = 0.15 if length_m is None else length_m
        height = 0.02 if height_m is None else abs(height_m)
        return Anomaly(
            kind="bump",
            start_x_m=start_x_m,
            length_m=length,
            height_m=height,
            width_m=lane_width_m,
            ramp_m=min(0.02, 0.25 * length),
        )
    if style == "gap":
        length = 0.10 if length_m is None else length_m
        depth = 0.02 if height_m is None else abs(height_m)
        return Anomaly(
            kind="pothole",
            start_x_m=start_x_m,
            length_m=length,
            height_m=-depth,
            width_m=lane_width_m,
            ramp_m=0.0,
        )
    raise ConfigError(f"expansion_joint style = {style!r}: choose 'raised' or 'gap'")


@dataclass(frozen=True)
class _WheelPothole:
    """A pothole under one wheel line of the lead (resolved against the drive's lead)."""

    side: str  #: "left" or "right"
    depth_m: float
    length_m: float
    width_m: float = 0.55


#: an anomaly of a suite drive, placed where the lead's front axle is at a given time
_Feature = tuple[float, Anomaly | _WheelPothole]


@dataclass(frozen=True)
class _SuiteDrive:
    """One drive of the suite; anomalies are given at the lead's front-axle crossing time."""

    number: int
    topic: str  #: the drive's subject, the last part of its name
    lead: str  #: a key of LEAD_TYPES
    iso_class: str
    camera: CameraSpec
    speed_knots: tuple[tuple[float, float], ...]  #: (t s, ego speed km/h)
    gap_knots: tuple[tuple[float, float], ...]  #: (t s, bumper-to-bumper gap m)
    features: tuple[_Feature, ...] = ()
    lead_lateral_m: float = 0.0
    ego_lateral_m: float = 0.0
    hill_grade_pct: float = 2.0
    oncoming_per_minute: float = 2.0
    lead_events: tuple[LeadEvent, ...] = ()
    conditions: tuple[ConditionSegment, ...] = ()

    @property
    def name(self) -> str:
        c = self.camera
        size = f"{c.width}x{c.height}" + ("" if c.fps in (25.0, 30.0) else f"-{c.fps:g}fps")
        return f"g{self.number:02d}_{size}_{self.lead}_{self.iso_class}_{self.topic}"


def _joint(
    style: str = "raised", length_m: float | None = None, height_m: float | None = None
) -> Anomaly:
    return expansion_joint(0.0, style=style, length_m=length_m, height_m=height_m)


# anomaly templates (placed by `_place`), sizes within the ranges of `road._random_anomaly`
#: the paper's speed bump: 6 cm, 2 m, 7 deg ramps
_PAPER_BUMP = paper_speed_bump(0.0)
#: a round-top (Watts) road hump, 3.7 m long and 75 mm high, as a trapezoid
_WATTS_HUMP = Anomaly(kind="bump", start_x_m=0.0, length_m=3.7, height_m=0.075, ramp_m=1.2)
#: a bolted-down rubber speed bump, 0.6 m long and 5 cm high
_RUBBER_BUMP = Anomaly(kind="bump", start_x_m=0.0, length_m=0.6, height_m=0.05, ramp_m=0.25)
#: a flat asphalt hump, 3 m long and 4 cm high
_ASPHALT_HUMP = Anomaly(kind="bump", start_x_m=0.0, length_m=3.0, height_m=0.04, ramp_m=1.0)
#: a speed cushion 1.9 m wide, 3 m long, 7 cm high, 8 deg ramps: under both wheel lines of
#: every lead type (tracks 1.48-1.64 m)
_CUSHION = Anomaly(
    kind="cushion", start_x_m=0.0, length_m=3.0, height_m=0.07, width_m=1.9, ramp_m=0.5
)


def _left(depth_m: float, length_m: float) -> _WheelPothole:
    return _WheelPothole("left", depth_m, length_m)


def _right(depth_m: float, length_m: float) -> _WheelPothole:
    return _WheelPothole("right", depth_m, length_m)


#: a street-lit night (light 0.001 of daylight, the segment's default) for the whole drive
_NIGHT = ConditionSegment(kind="night", start_s=0.0, end_s=GENERALIZATION_DURATION_S, ramp_s=0.0)
#: a fog bank of about 50 m meteorological visibility (3 / 0.06 per m) for half the drive
_FOG = ConditionSegment(kind="fog", start_s=14.0, end_s=46.0, fog_density_per_m=0.06, ramp_s=2.0)

#: the drives, in order (drive i has seed ``seed + i`` in `generalization`). Anomalies are
#: given at the time the lead's front axle crosses them: >= 6 s into the drive, >= 3 s
#: apart (7-10 s here), the ego over the last one by 4 s before the end, and never an ego
#: crossing in the 0.5 s hard window of a lead crossing; one-sided potholes at gaps that
#: put the lead 15-23 m from the camera.
_SUITE: tuple[_SuiteDrive, ...] = (
    _SuiteDrive(
        number=1,
        topic="joints",
        lead="small-car",
        iso_class="B",
        camera=CameraSpec(width=640, height=360, vfov_deg=50.0, fps=30.0),
        speed_knots=((0, 40), (30, 50), (60, 45)),
        gap_knots=((0, 14), (20, 20), (40, 16), (60, 18)),
        features=(
            (8.0, _joint()),
            (16.0, _joint("gap")),
            (24.5, _joint("raised", 0.12, 0.015)),
            (33.0, _joint("raised", 0.20, 0.025)),
            (41.0, _right(0.06, 0.5)),
            (49.0, _joint("gap")),
        ),
        lead_lateral_m=0.1,
        oncoming_per_minute=3.0,
    ),
    _SuiteDrive(
        number=2,
        topic="potholes",
        lead="suv",
        iso_class="C",
        camera=CameraSpec(width=960, height=540, vfov_deg=60.0, fps=25.0),
        speed_knots=((0, 30), (20, 40), (40, 35), (60, 30)),
        gap_knots=((0, 12), (10, 17), (30, 19), (45, 16), (60, 14)),
        features=(
            (9.0, _left(0.07, 0.7)),
            (17.0, _joint()),
            (25.0, _right(0.06, 0.6)),
            (33.0, _CUSHION),
            (41.0, _left(0.08, 0.9)),
            (49.0, _joint("gap")),
        ),
        hill_grade_pct=2.5,
    ),
    _SuiteDrive(
        number=3,
        topic="speed-bumps",
        lead="van",
        iso_class="A",
        camera=CameraSpec(width=1920, height=1080, vfov_deg=45.0, fps=25.0),
        speed_knots=((0, 20), (60, 20)),
        gap_knots=((0, 9), (20, 12), (40, 10), (60, 11)),
        features=(
            (8.0, _PAPER_BUMP),
            (17.0, _WATTS_HUMP),
            (26.0, _joint()),
            (35.0, _RUBBER_BUMP),
            (44.0, _PAPER_BUMP),
        ),
        hill_grade_pct=1.0,
    ),
    _SuiteDrive(
        number=4,
        topic="cushions",
        lead="mid-size",
        iso_class="C",
        camera=CameraSpec(width=1280, height=720, vfov_deg=54.0, fps=60.0),
        speed_knots=((0, 25), (30, 35), (60, 30)),
        gap_knots=((0, 10), (20, 14), (40, 12), (60, 15)),
        features=(
            (8.0, _CUSHION),
            (18.0, _CUSHION),
            (28.0, _PAPER_BUMP),
            (38.0, _CUSHION),
            (48.0, _joint("gap")),
        ),
        oncoming_per_minute=3.0,
    ),
    _SuiteDrive(
        number=5,
        topic="clean",
        lead="van",
        iso_class="D",
        camera=CameraSpec(width=640, height=360, vfov_deg=60.0, fps=30.0),
        speed_knots=((0, 40), (20, 55), (40, 50), (60, 45)),
        gap_knots=((0, 15), (30, 22), (60, 18)),
        hill_grade_pct=3.0,
        oncoming_per_minute=3.0,
    ),
    _SuiteDrive(
        number=6,
        topic="clean",
        lead="small-car",
        iso_class="E",
        camera=CameraSpec(width=960, height=540, vfov_deg=45.0, fps=25.0),
        speed_knots=((0, 15), (20, 25), (40, 20), (60, 15)),
        gap_knots=((0, 8), (30, 12), (60, 10)),
        oncoming_per_minute=1.0,
    ),
    _SuiteDrive(
        number=7,
        topic="night",
        lead="suv",
        iso_class="B",
        camera=CameraSpec(width=1280, height=720, vfov_deg=48.0, fps=30.0),
        speed_knots=((0, 45), (30, 55), (60, 50)),
        gap_knots=((0, 16), (25, 22), (45, 18), (60, 22)),
        features=(
            (10.0, _right(0.07, 0.8)),
            (18.0, _joint()),
            (27.0, _joint("gap")),
            (36.0, _left(0.06, 0.6)),
            (45.0, _joint("raised", 0.18, 0.025)),
        ),
        oncoming_per_minute=4.0,
        conditions=(_NIGHT,),
    ),
    _SuiteDrive(
        number=8,
        topic="fog",
        lead="small-car",
        iso_class="C",
        camera=CameraSpec(width=1280, height=720, vfov_deg=60.0, fps=30.0),
        speed_knots=((0, 30), (20, 40), (40, 35), (60, 30)),
        gap_knots=((0, 12), (15, 17), (35, 15), (50, 17), (60, 13)),
        features=(
            (8.0, _CUSHION),
            (17.0, _left(0.07, 0.7)),
            (26.0, _joint()),
            (35.0, _ASPHALT_HUMP),
            (44.0, _right(0.065, 0.6)),
            (52.0, _joint("gap")),
        ),
        conditions=(_FOG,),
    ),
    _SuiteDrive(
        number=9,
        topic="potholes",
        lead="mid-size",
        iso_class="D",
        camera=CameraSpec(width=1920, height=1080, vfov_deg=60.0, fps=25.0),
        speed_knots=((0, 25), (30, 35), (60, 30)),
        gap_knots=((0, 14), (20, 18), (40, 16), (60, 14)),
        features=(
            (8.0, _left(0.08, 0.9)),
            (16.0, _right(0.06, 0.5)),
            (25.0, _joint()),
            (34.0, _left(0.07, 0.7)),
            (43.0, _right(0.075, 0.8)),
            (51.0, _CUSHION),
        ),
        lead_lateral_m=-0.1,
    ),
    _SuiteDrive(
        number=10,
        topic="joints-70kmh",
        lead="suv",
        iso_class="A",
        camera=CameraSpec(width=640, height=360, vfov_deg=45.0, fps=30.0),
        speed_knots=((0, 60), (20, 70), (40, 70), (60, 65)),
        gap_knots=((0, 25), (30, 30), (60, 28)),
        features=(
            (8.0, _joint()),  # the two ends of a 75 m bridge
            (12.0, _joint("gap")),
            (20.0, _joint("raised", 0.12, 0.015)),
            (25.0, _joint("gap")),
            (35.0, _joint("raised", 0.20, 0.025)),
            (45.0, _joint("gap")),
        ),
        hill_grade_pct=1.5,
        oncoming_per_minute=4.0,
    ),
    _SuiteDrive(
        number=11,
        topic="mixed",
        lead="van",
        iso_class="B",
        camera=CameraSpec(width=960, height=540, vfov_deg=50.0, fps=25.0),
        speed_knots=((0, 15), (15, 15), (30, 30), (60, 30)),
        gap_knots=((0, 8), (15, 10), (35, 16), (60, 18)),
        features=(
            (7.0, _PAPER_BUMP),
            (16.0, _CUSHION),
            (26.0, _joint()),
            (35.0, _right(0.07, 0.7)),
            (44.0, _joint("gap")),
            (52.0, _left(0.06, 0.6)),
        ),
        hill_grade_pct=3.0,
    ),
    _SuiteDrive(
        number=12,
        topic="braking",
        lead="small-car",
        iso_class="D",
        camera=CameraSpec(width=1280, height=720, vfov_deg=40.0, fps=30.0),
        speed_knots=((0, 35), (60, 35)),
        gap_knots=((0, 13), (30, 16), (60, 14)),
        features=(
            (8.0, _joint()),
            (16.0, _left(0.07, 0.6)),
            (24.0, _CUSHION),
            (38.0, _ASPHALT_HUMP),
            (47.0, _joint("gap")),
        ),
        lead_events=(LeadEvent(t_s=29.0, accel_mps2=-2.5, duration_s=1.5),),
    ),
)

#: names of the suite's drives, in order
GENERALIZATION_DRIVES: tuple[str, ...] = tuple(d.name for d in _SUITE)
_SUITE_BY_NAME = {d.name: d for d in _SUITE}


def _place(feature: Anomaly | _WheelPothole, apex_x_m: float, drive: _SuiteDrive) -> Anomaly:
    """The anomaly of ``feature`` with its apex (centre) at ``apex_x_m``; a wheel pothole
    centred on the lead's left or right wheel line."""
    if isinstance(feature, _WheelPothole):
        if feature.side not in ("left", "right"):
            raise ConfigError(f"{drive.name}: wheel pothole side {feature.side!r}")
        sign = 1.0 if feature.side == "left" else -1.0
        wheel_y = drive.lead_lateral_m + sign * 0.5 * LEAD_TYPES[drive.lead].track_m
        feature = Anomaly(
            kind="pothole",
            start_x_m=0.0,
            length_m=feature.length_m,
            height_m=-feature.depth_m,
            center_y_m=round(wheel_y, 3),
            width_m=feature.width_m,
            ramp_m=0.03,
        )
    return replace(feature, start_x_m=round(apex_x_m - 0.5 * feature.length_m, 2))


def generalization_drive(name: str, seed: int = 0) -> ScenarioConfig:
    """The suite drive ``name`` (one of `GENERALIZATION_DRIVES`) with ``seed``.

    The seed draws the road's roughness, the traffic, the sensor noise and the IMU's clock
    offset (0-80 ms, as in ``wild``); everything else is fixed by the drive. Each anomaly is
    put where the lead's front axle is at its planned time.
    """
    try:
        drive = _SUITE_BY_NAME[name]
    except KeyError:
        raise ConfigError(
            f"generalization drive {name!r}: unknown; choose one of {list(GENERALIZATION_DRIVES)}"
        ) from None
    lead = LEAD_TYPES[drive.lead]
    duration = GENERALIZATION_DURATION_S
    motion = MotionConfig(
        road=RoadConfig(
            iso_class=drive.iso_class,
            length_m=_road_length(duration, float(max(v for _, v in drive.speed_knots))),
            hill_grade_pct=drive.hill_grade_pct,
            anomalies=[],
            anomaly_density_per_km=0.0,
        ),
        lead=lead,
        duration_s=duration,
        ego_speed_knots=[SpeedKnot(t_s=float(t), speed_kmh=float(v)) for t, v in drive.speed_knots],
        ego_start_x_m=_EGO_START_M,
        gap_knots=[GapKnot(t_s=float(t), gap_m=float(g)) for t, g in drive.gap_knots],
        ego_lateral_m=drive.ego_lateral_m,
        lead_lateral_m=drive.lead_lateral_m,
        lead_events=list(drive.lead_events),
        oncoming_per_minute=drive.oncoming_per_minute,
    )
    if drive.features:
        # the same kinematics the simulator runs: the lead's CG on the 1 ms grid
        kin = _kinematics(motion, f"{name}.motion")
        anomalies = [
            _place(f, float(np.interp(t, kin.t, kin.x_lead)) + lead.cg_to_front_axle_m, drive)
            for t, f in drive.features
        ]
        motion = replace(motion, road=replace(motion.road, anomalies=anomalies))
    rng = np.random.default_rng([seed, 0x6E])
    # a smartphone-grade IMU whose clock is off by an unknown 0-80 ms (CAN / app latency)
    imu = replace(ImuConfig.smartphone(), time_offset_s=round(float(rng.uniform(0.0, 0.08)), 4))
    return ScenarioConfig(
        name=name,
        seed=seed,
        motion=motion,
        camera=drive.camera,
        imu_preset="custom",
        imu=imu,
        conditions=list(drive.conditions),
    )


def generalization(seed: int = 0) -> list[tuple[str, ScenarioConfig]]:
    """The generalization suite: (name, scenario) of every drive, drive i with seed
    ``seed + i``. Its parameters are never used to tune a detector."""
    return [
        (name, generalization_drive(name, seed + i)) for i, name in enumerate(GENERALIZATION_DRIVES)
    ]


#: preset name -> builder ``seed -> ScenarioConfig``
PRESETS: dict[str, Callable[[int], ScenarioConfig]] = {
    "controlled": controlled,
    "wild": wild,
    "texture-loss": texture_loss,
    "demo": demo,
    "mounted-imu": mounted_imu,
}


def preset(name: str, seed: int = 0) -> ScenarioConfig:
    """The scenario of preset ``name`` for ``seed``."""
    try:
        return PRESETS[name](seed)
    except KeyError:
        raise ConfigError(f"preset {name!r}: unknown; choose one of {sorted(PRESETS)}") from None
