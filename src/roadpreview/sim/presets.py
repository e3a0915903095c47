"""Named scenarios: the paper's controlled experiment, random ``wild`` drives,
``texture-loss`` drives and the ``demo`` drive.

A preset is a function ``seed -> ScenarioConfig``. Everything random about the
scenario itself (speed plan, gap plan, manoeuvres, lines) is drawn here from the
seed and written out explicitly in ``scenario.toml``; everything random inside
the simulation (road roughness, random anomalies, traffic, sensor noise) is
drawn from the same seed by the simulator. Either way the drive regenerates bit
for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from roadpreview.errors import ConfigError
from roadpreview.sim.imu import ImuConfig
from roadpreview.sim.motion import GapKnot, LeadEvent, MotionConfig, SpeedKnot
from roadpreview.sim.road import Anomaly, RoadConfig, paper_speed_bump
from roadpreview.sim.scenario import CameraSpec, ConditionSegment, ScenarioConfig

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


#: preset name -> builder ``seed -> ScenarioConfig``
PRESETS: dict[str, Callable[[int], ScenarioConfig]] = {
    "controlled": controlled,
    "wild": wild,
    "texture-loss": texture_loss,
    "demo": demo,
}


def preset(name: str, seed: int = 0) -> ScenarioConfig:
    """The scenario of preset ``name`` for ``seed``."""
    try:
        return PRESETS[name](seed)
    except KeyError:
        raise ConfigError(f"preset {name!r}: unknown; choose one of {sorted(PRESETS)}") from None
