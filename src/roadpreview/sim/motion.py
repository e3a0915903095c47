"""A drive: the ego following a lead vehicle over a simulated road, other traffic, ground truth.

``simulate_motion`` turns a `MotionConfig` into the road, the ego's and the lead's
body motion (``vehicle.simulate_vehicle``), poses of the other traffic, and one
`AnomalyEvent` per road anomaly: when each axle of each vehicle crosses it, which
wheels hit it, the lead distance then, and the paper's *hard* flag. Camera poses
follow from the ego motion (``camera_pose_at``, ``camera_track``). Models and
parameters: ``docs/simulator-physics.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError
from roadpreview.sim.road import Road, RoadConfig, generate_road
from roadpreview.sim.types import CameraPose, VehiclePose, VehicleShape
from roadpreview.sim.vehicle import BodyMotion, VehicleParams, simulate_vehicle

FloatArray = NDArray[np.float64]

#: smallest bumper-to-bumper gap between the ego and the lead, m
MIN_GAP_M = 2.0
KMH = 1.0 / 3.6


# -- configuration ----------------------------------------------------------------------


@dataclass(frozen=True)
class SpeedKnot:
    """The ego's planned speed at one time; the plan is linear between knots."""

    t_s: float = param(0.0, unit="s", ge=0, help="time of the knot")
    speed_kmh: float = param(30.0, unit="km/h", ge=0, le=200, help="planned ego speed then")


@dataclass(frozen=True)
class GapKnot:
    """The planned lead gap at one time; between knots it changes along a quintic smoothstep."""

    t_s: float = param(0.0, unit="s", ge=0, help="time of the knot")
    gap_m: float = param(
        15.0, unit="m", ge=MIN_GAP_M, le=500, help="lead rear to ego front (bumper to bumper)"
    )


@dataclass(frozen=True)
class LeadEvent:
    """A braking (negative) or accelerating (positive) manoeuvre of the lead, on top of the plan.

    The acceleration ramps linearly to ``accel_mps2`` over ``ramp_s``, holds, and ramps back to
    zero, ``duration_s`` after ``t_s``; the speed changes by accel * (duration - ramp).
    """

    t_s: float = param(5.0, unit="s", ge=0, help="start of the manoeuvre")
    accel_mps2: float = param(
        -3.0, unit="m/s^2", ge=-10, le=5, help="signed: negative brakes (the body dives)"
    )
    duration_s: float = param(1.5, unit="s", gt=0, le=60, help="ramps included")
    ramp_s: float = param(
        0.3, unit="s", ge=0, le=5, help="brake build-up / release time (jerk limit)"
    )

    def validate(self, where: str) -> None:
        if 2 * self.ramp_s > self.duration_s:
            prefix = f"{where}." if where else ""
            raise ConfigError(
                f"{prefix}ramp_s = {self.ramp_s} s: two ramps exceed duration_s ="
                f" {self.duration_s} s"
            )

    def accel(self, t: ArrayLike) -> FloatArray:
        """The event's acceleration (m/s^2) at times ``t``."""
        t_arr = np.asarray(t, dtype=float) - self.t_s
        d, r = self.duration_s, self.ramp_s
        if r > 0:
            shape = np.clip(np.minimum(t_arr, d - t_arr) / r, 0.0, 1.0)
        else:
            shape = ((t_arr >= 0) & (t_arr < d)).astype(float)
        return self.accel_mps2 * shape


@dataclass(frozen=True)
class TrafficVehicle:
    """Another vehicle, at constant speed along a lane line; kinematics only."""

    direction: str = param(
        "oncoming",
        choices=("oncoming", "same"),
        help="oncoming drives towards -X; same drives towards +X",
    )
    start_x_m: float = param(200.0, unit="m", help="X of its CG at t = 0")
    lateral_m: float = param(3.5, unit="m", help="Y of its line (3.5: the oncoming lane centre)")
    speed_kmh: float = param(50.0, unit="km/h", ge=0, le=200, help="its speed (positive)")
    # param() returns dataclasses.field(default_factory=...), which RUF009 cannot see
    shape: VehicleShape = param(  # noqa: RUF009
        default_factory=VehicleShape, help="its body box"
    )
    appearance: int = param(0, ge=0, help="appearance seed for the renderer")


@dataclass(frozen=True)
class MotionConfig:
    """A drive: road, both vehicles, the ego's speed, the lead's gap and manoeuvres, traffic."""

    # param() returns dataclasses.field(default_factory=...), which RUF009 cannot see
    road: RoadConfig = param(default_factory=RoadConfig, help="the road")  # noqa: RUF009
    ego: VehicleParams = param(default_factory=VehicleParams, help="ego vehicle")  # noqa: RUF009
    lead: VehicleParams = param(default_factory=VehicleParams, help="lead vehicle")  # noqa: RUF009
    duration_s: float = param(20.0, unit="s", gt=0, le=3600, help="length of the drive")
    dt_s: float = param(
        0.001,
        unit="s",
        ge=1e-4,
        le=0.01,
        help="simulation step; 1 ms resolves the ~14 Hz wheel hop",
    )
    ego_speed_kmh: float = param(
        30.0, unit="km/h", gt=0, le=200, help="constant ego speed when ego_speed_knots is empty"
    )
    ego_speed_knots: list[SpeedKnot] = param(  # noqa: RUF009
        default_factory=list, help="piecewise-linear ego speed plan; replaces ego_speed_kmh"
    )
    ego_start_x_m: float = param(30.0, unit="m", ge=0, help="X of the ego CG at t = 0")
    gap_m: float = param(
        15.0,
        unit="m",
        ge=MIN_GAP_M,
        le=500,
        help="constant lead gap (bumper to bumper) when gap_knots is empty",
    )
    gap_knots: list[GapKnot] = param(  # noqa: RUF009
        default_factory=list, help="smoothly varying gap plan; replaces gap_m"
    )
    ego_lateral_m: float = param(
        0.0, unit="m", ge=-10, le=10, help="Y of the ego's line (0 = lane centre, left +)"
    )
    lead_lateral_m: float = param(0.0, unit="m", ge=-10, le=10, help="Y of the lead's line")
    lead_events: list[LeadEvent] = param(  # noqa: RUF009
        default_factory=list, help="lead braking / acceleration manoeuvres"
    )
    ego_follows_lead_events: bool = param(True, help="the ego repeats each lead manoeuvre")
    reaction_s: float = param(1.0, unit="s", ge=0, le=5, help="delay of the ego's repetition")
    traffic: list[TrafficVehicle] = param(  # noqa: RUF009
        default_factory=list, help="explicit other vehicles"
    )
    oncoming_per_minute: float = param(
        2.0, unit="1/min", ge=0, le=60, help="mean rate of random oncoming vehicles"
    )
    camera_forward_m: float = param(
        1.0, unit="m", ge=-5, le=5, help="camera ahead of the ego CG (windscreen)"
    )
    camera_height_m: float = param(1.3, unit="m", gt=0, le=4, help="camera above the road at rest")
    hard_window_s: float = param(
        0.5, unit="s", ge=0, le=5, help="ego hits another anomaly this close to the lead's: hard"
    )

    def validate(self, where: str) -> None:
        """Cross-field checks: knots, events and traffic in range, a feasible drive."""
        prefix = f"{where}." if where else ""
        for name in ("ego_speed_knots", "gap_knots", "lead_events", "traffic"):
            items = getattr(self, name)
            for i, item in enumerate(items):
                check_ranges(item, f"{prefix}{name}[{i}]")
                validate = getattr(item, "validate", None)
                if callable(validate):
                    validate(f"{prefix}{name}[{i}]")
        for name in ("ego_speed_knots", "gap_knots"):
            times = [k.t_s for k in getattr(self, name)]
            for i in range(1, len(times)):
                if times[i] <= times[i - 1]:
                    raise ConfigError(
                        f"{prefix}{name}[{i}].t_s = {times[i]} s: knot times must increase"
                    )
        _kinematics(self, where)


# -- kinematics -------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Kinematics:
    t: FloatArray
    x_ego: FloatArray
    v_ego: FloatArray
    a_ego: FloatArray
    x_lead: FloatArray
    v_lead: FloatArray
    a_lead: FloatArray
    gap: FloatArray


def _cumtrapz(y: FloatArray, dt: float) -> FloatArray:
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1])) * dt
    return out


def _speed_plan(cfg: MotionConfig, t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Planned ego speed and acceleration (piecewise linear / constant)."""
    if not cfg.ego_speed_knots:
        v = np.full(t.size, cfg.ego_speed_kmh * KMH)
        return v, np.zeros(t.size)
    kt = np.array([k.t_s for k in cfg.ego_speed_knots])
    kv = np.array([k.speed_kmh for k in cfg.ego_speed_knots]) * KMH
    v = np.interp(t, kt, kv)
    slopes = np.zeros(kt.size + 1)
    if kt.size > 1:
        slopes[1:-1] = np.diff(kv) / np.diff(kt)
    seg = np.searchsorted(kt, t, side="right")
    return v, slopes[seg]


def _gap_plan(cfg: MotionConfig, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Planned gap and its first two time derivatives (quintic smoothstep between knots)."""
    if not cfg.gap_knots:
        return np.full(t.size, cfg.gap_m), np.zeros(t.size), np.zeros(t.size)
    kt = np.array([k.t_s for k in cfg.gap_knots])
    kg = np.array([k.gap_m for k in cfg.gap_knots])
    gap = np.interp(t, kt, kg)  # holds before the first / after the last knot
    gd = np.zeros(t.size)
    gdd = np.zeros(t.size)
    for i in range(kt.size - 1):
        span = kt[i + 1] - kt[i]
        m = (t >= kt[i]) & (t < kt[i + 1])
        s = (t[m] - kt[i]) / span
        dg = kg[i + 1] - kg[i]
        gap[m] = kg[i] + dg * (10 * s**3 - 15 * s**4 + 6 * s**5)
        gd[m] = dg * (30 * s**2 - 60 * s**3 + 30 * s**4) / span
        gdd[m] = dg * (60 * s - 180 * s**2 + 120 * s**3) / span**2
    return gap, gd, gdd


def _kinematics(cfg: MotionConfig, where: str = "") -> _Kinematics:
    """Positions, speeds and accelerations of ego and lead; ConfigError if infeasible."""
    prefix = f"{where}." if where else ""
    dt = cfg.dt_s
    n = round(cfg.duration_s / dt) + 1
    t: FloatArray = np.arange(n, dtype=np.float64) * dt
    v_plan, a_plan = _speed_plan(cfg, t)
    gap_plan, gap_d, gap_dd = _gap_plan(cfg, t)
    a_lead_ev = np.zeros(n)
    a_ego_ev = np.zeros(n)
    for ev in cfg.lead_events:
        a_lead_ev += ev.accel(t)
        if cfg.ego_follows_lead_events:
            a_ego_ev += ev.accel(t - cfg.reaction_s)
    dv_lead = _cumtrapz(a_lead_ev, dt)
    dv_ego = _cumtrapz(a_ego_ev, dt)
    v_ego = v_plan + dv_ego
    v_lead = v_plan + gap_d + dv_lead
    tol = -1e-9
    speed_field = "ego_speed_knots" if cfg.ego_speed_knots else "ego_speed_kmh"
    gap_field = "gap_knots" if cfg.gap_knots else "gap_m"
    if v_plan.min() < tol:
        raise ConfigError(f"{prefix}{speed_field}: the planned ego speed goes negative")
    if v_ego.min() < tol:
        i = int(np.argmin(v_ego))
        raise ConfigError(
            f"{prefix}lead_events: the ego, repeating them, would reverse"
            f" (speed {v_ego[i]:.2f} m/s at t = {t[i]:.2f} s)"
        )
    if (v_plan + gap_d).min() < tol:
        raise ConfigError(
            f"{prefix}{gap_field}: the gap shrinks faster than the ego drives;"
            " the lead would reverse"
        )
    if v_lead.min() < tol:
        i = int(np.argmin(v_lead))
        raise ConfigError(
            f"{prefix}lead_events: the lead would reverse (speed {v_lead[i]:.2f}"
            f" m/s at t = {t[i]:.2f} s)"
        )
    x_ego = cfg.ego_start_x_m + _cumtrapz(v_ego, dt)
    gap = gap_plan + _cumtrapz(dv_lead, dt) - _cumtrapz(dv_ego, dt)
    if gap.min() < MIN_GAP_M - 1e-9:
        i = int(np.argmin(gap))
        raise ConfigError(
            f"{prefix}lead_events: the gap falls to {gap[i]:.2f} m at t ="
            f" {t[i]:.2f} s (must stay >= {MIN_GAP_M} m)"
        )
    x_lead = x_ego + cfg.ego.shape.cg_to_front_m + gap + cfg.lead.shape.cg_to_rear_m
    lead_front = float(x_lead[-1]) + cfg.lead.cg_to_front_axle_m + cfg.lead.wheel_radius_m
    if lead_front > cfg.road.length_m:
        raise ConfigError(
            f"{prefix}road.length_m = {cfg.road.length_m} m: too short, the lead's"
            f" front wheels reach X = {lead_front:.1f} m"
        )
    return _Kinematics(
        t=t,
        x_ego=x_ego,
        v_ego=v_ego,
        a_ego=a_plan + a_ego_ev,
        x_lead=x_lead,
        v_lead=v_lead,
        a_lead=a_plan + gap_dd + a_lead_ev,
        gap=gap,
    )


# -- other traffic ----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class TrafficTrajectory:
    """A vehicle at constant speed along a line; its pose rests rigidly on the road (the
    mean road height under four virtual wheels; pitch and roll from their differences)."""

    vehicle_id: int
    shape: VehicleShape
    appearance: int
    start_x_m: float
    #: signed velocity along X (negative for oncoming)
    velocity_mps: float
    lateral_m: float
    road: Road

    @property
    def yaw_rad(self) -> float:
        return math.pi if self.velocity_mps < 0 else 0.0

    def states(self, times: ArrayLike) -> dict[str, FloatArray]:
        """CG ``x, y, z`` and ``pitch, roll, yaw`` (arrays) at ``times``."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        x = self.start_x_m + self.velocity_mps * t
        heading = -1.0 if self.velocity_mps < 0 else 1.0
        half_wb = 0.3 * self.shape.length_m
        half_tr = 0.42 * self.shape.width_m
        fwd = np.array([1.0, 1.0, -1.0, -1.0]) * half_wb * heading
        left = np.array([1.0, -1.0, 1.0, -1.0]) * half_tr * heading
        h = self.road.height(x[:, None] + fwd[None, :], self.lateral_m + left[None, :])
        pitch = np.arctan((h[:, :2].mean(1) - h[:, 2:].mean(1)) / (2 * half_wb))
        roll = np.arctan((h[:, [0, 2]].mean(1) - h[:, [1, 3]].mean(1)) / (2 * half_tr))
        return {
            "x": x,
            "y": np.full(t.size, self.lateral_m),
            "z": h.mean(1) + self.shape.cg_height_m,
            "pitch": pitch,
            "roll": roll,
            "yaw": np.full(t.size, self.yaw_rad),
        }

    def pose_at(self, t: float) -> VehiclePose:
        s = self.states([t])
        return VehiclePose(
            vehicle_id=self.vehicle_id,
            x_m=float(s["x"][0]),
            y_m=float(s["y"][0]),
            z_m=float(s["z"][0]),
            pitch_rad=float(s["pitch"][0]),
            roll_rad=float(s["roll"][0]),
            yaw_rad=float(s["yaw"][0]),
            shape=self.shape,
            appearance=self.appearance,
        )


#: body boxes of random traffic (car, SUV, van, truck) and their relative frequency
_TRAFFIC_SHAPES = (
    (VehicleShape(4.5, 1.8, 1.5, 0.15, 2.2, 0.55), 0.5),
    (VehicleShape(4.8, 1.9, 1.75, 0.2, 2.35, 0.65), 0.25),
    (VehicleShape(5.4, 2.0, 2.3, 0.2, 2.6, 0.8), 0.15),
    (VehicleShape(9.0, 2.5, 3.4, 0.35, 4.0, 1.1), 0.1),
)


def _traffic(
    cfg: MotionConfig, road: Road, kin: _Kinematics, rng: np.random.Generator
) -> tuple[TrafficTrajectory, ...]:
    out: list[TrafficTrajectory] = []
    for tv in cfg.traffic:
        sign = -1.0 if tv.direction == "oncoming" else 1.0
        out.append(
            TrafficTrajectory(
                vehicle_id=2 + len(out),
                shape=tv.shape,
                appearance=tv.appearance,
                start_x_m=tv.start_x_m,
                velocity_mps=sign * tv.speed_kmh * KMH,
                lateral_m=tv.lateral_m,
                road=road,
            )
        )
    count = int(rng.poisson(cfg.oncoming_per_minute * (cfg.duration_s + 10.0) / 60.0))
    shapes = [s for s, _ in _TRAFFIC_SHAPES]
    weights = np.array([w for _, w in _TRAFFIC_SHAPES])
    for _ in range(count):
        t_pass = rng.uniform(0.0, cfg.duration_s + 10.0)  # when it passes the ego
        speed = rng.uniform(40.0, 70.0) * KMH
        shape = shapes[int(rng.choice(len(shapes), p=weights / weights.sum()))]
        x_pass = float(
            np.interp(
                t_pass, kin.t, kin.x_ego, right=kin.x_ego[-1] + kin.v_ego[-1] * (t_pass - kin.t[-1])
            )
        )
        out.append(
            TrafficTrajectory(
                vehicle_id=2 + len(out),
                shape=shape,
                appearance=int(rng.integers(0, 2**31 - 1)),
                start_x_m=x_pass + speed * t_pass,
                velocity_mps=-speed,
                lateral_m=road.lane_width_m + rng.uniform(-0.3, 0.3),
                road=road,
            )
        )
    return tuple(out)


# -- camera -----------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class CameraTrack:
    """Camera poses at many times: optical-centre positions (n, 3) and angles (n,)."""

    t: FloatArray
    position: FloatArray
    pitch: FloatArray
    roll: FloatArray
    yaw: FloatArray

    def __len__(self) -> int:
        return int(self.t.size)

    def pose(self, i: int) -> CameraPose:
        x, y, z = (float(v) for v in self.position[i])
        return CameraPose(
            x_m=x,
            y_m=y,
            z_m=z,
            pitch_rad=float(self.pitch[i]),
            roll_rad=float(self.roll[i]),
            yaw_rad=float(self.yaw[i]),
        )


def camera_track(
    ego: BodyMotion, mount_forward_m: float, mount_height_m: float, times: ArrayLike
) -> CameraTrack:
    """Poses at ``times`` of a camera fixed to the ego body ``mount_forward_m`` ahead of the
    CG and ``mount_height_m`` above the road at rest; its axes are the body's (pitch, roll and
    yaw equal the ego's; a fixed mounting pitch belongs to the calibrated forward direction)."""
    t = np.atleast_1d(np.asarray(times, dtype=float))
    offset = np.array([[mount_forward_m, 0.0, mount_height_m - ego.shape.cg_height_m]])
    pos = ego.points_world(t, offset)[:, 0, :]
    s = ego.sample(t)
    return CameraTrack(t=t, position=pos, pitch=s.pitch, roll=s.roll, yaw=s.yaw)


def camera_pose_at(
    ego: BodyMotion, mount_forward_m: float, mount_height_m: float, t: float
) -> CameraPose:
    """The camera pose at time ``t`` (see `camera_track`)."""
    return camera_track(ego, mount_forward_m, mount_height_m, [t]).pose(0)


def lead_distance(
    ego: BodyMotion,
    lead: BodyMotion,
    mount_forward_m: float,
    mount_height_m: float,
    times: ArrayLike,
) -> FloatArray:
    """Distance along X from the camera to the lead's rear face at ``times``."""
    t = np.atleast_1d(np.asarray(times, dtype=float))
    cam = camera_track(ego, mount_forward_m, mount_height_m, t)
    rear = lead.sample(t).x - lead.shape.cg_to_rear_m
    return np.asarray(rear - cam.position[:, 0])


# -- events -----------------------------------------------------------------------------


@dataclass(frozen=True)
class AnomalyEvent:
    """Ground truth for one anomaly during a drive. Times are when an axle passes the
    anomaly's apex X (NaN if not within the drive); sides say which wheels run over it."""

    index: int
    kind: str
    apex_x_m: float
    height_m: float
    length_m: float
    lead_side: str
    ego_side: str
    lead_front_t_s: float
    lead_rear_t_s: float
    ego_front_t_s: float
    ego_rear_t_s: float
    lead_hits: bool
    ego_hits: bool
    #: camera to lead rear face when the lead's front axle crosses (NaN if it does not)
    lead_distance_m: float
    #: the ego crosses another anomaly within the hard window of the lead's crossing
    hard: bool


def _crossing_time(t: FloatArray, axle_x: FloatArray, target: float) -> float:
    """First time the (non-decreasing) ``axle_x`` reaches ``target``; NaN if outside."""
    if not axle_x[0] <= target <= axle_x[-1]:
        return math.nan
    i = int(np.searchsorted(axle_x, target, side="left"))
    if i == 0:
        return float(t[0])
    x0, x1 = axle_x[i - 1], axle_x[i]
    frac = (target - x0) / (x1 - x0) if x1 > x0 else 1.0
    return float(t[i - 1] + frac * (t[i] - t[i - 1]))


def _events(
    cfg: MotionConfig, road: Road, ego: BodyMotion, lead: BodyMotion
) -> tuple[AnomalyEvent, ...]:
    rows = []
    for i, a in enumerate(road.anomalies):
        apex = a.apex_x_m
        lead_side = a.side(cfg.lead_lateral_m, cfg.lead.track_m)
        ego_side = a.side(cfg.ego_lateral_m, cfg.ego.track_m)
        times = {
            "lf": _crossing_time(lead.t, lead.x + cfg.lead.cg_to_front_axle_m, apex),
            "lr": _crossing_time(lead.t, lead.x - cfg.lead.cg_to_rear_axle_m, apex),
            "ef": _crossing_time(ego.t, ego.x + cfg.ego.cg_to_front_axle_m, apex),
            "er": _crossing_time(ego.t, ego.x - cfg.ego.cg_to_rear_axle_m, apex),
        }
        lead_crosses = not (math.isnan(times["lf"]) and math.isnan(times["lr"]))
        ego_crosses = not (math.isnan(times["ef"]) and math.isnan(times["er"]))
        lead_hits = lead_side != "none" and lead_crosses
        ego_hits = ego_side != "none" and ego_crosses
        dist = math.nan
        if not math.isnan(times["lf"]):
            dist = float(
                lead_distance(ego, lead, cfg.camera_forward_m, cfg.camera_height_m, [times["lf"]])[
                    0
                ]
            )
        rows.append((i, a, lead_side, ego_side, times, lead_hits, ego_hits, dist))
    out = []
    for i, a, lead_side, ego_side, times, lead_hits, ego_hits, dist in rows:
        hard = False
        if lead_hits and not math.isnan(times["lf"]):
            for j, _, _, _, other, _, other_ego_hits, _ in rows:
                if j == i or not other_ego_hits:
                    continue
                near = [
                    abs(other[k] - times["lf"]) <= cfg.hard_window_s
                    for k in ("ef", "er")
                    if not math.isnan(other[k])
                ]
                if any(near):
                    hard = True
                    break
        out.append(
            AnomalyEvent(
                index=i,
                kind=a.kind,
                apex_x_m=a.apex_x_m,
                height_m=a.height_m,
                length_m=a.length_m,
                lead_side=lead_side,
                ego_side=ego_side,
                lead_front_t_s=times["lf"],
                lead_rear_t_s=times["lr"],
                ego_front_t_s=times["ef"],
                ego_rear_t_s=times["er"],
                lead_hits=lead_hits,
                ego_hits=ego_hits,
                lead_distance_m=dist,
                hard=hard,
            )
        )
    return tuple(out)


# -- the drive --------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class DriveMotion:
    """Everything that moves in one simulated drive, with its ground truth."""

    config: MotionConfig
    road: Road
    ego: BodyMotion
    lead: BodyMotion
    traffic: tuple[TrafficTrajectory, ...]
    events: tuple[AnomalyEvent, ...]

    @property
    def t(self) -> FloatArray:
        return self.ego.t

    @property
    def gap(self) -> FloatArray:
        """Bumper-to-bumper gap (lead rear to ego front) on the time grid."""
        return np.asarray(
            (self.lead.x - self.lead.shape.cg_to_rear_m)
            - (self.ego.x + self.ego.shape.cg_to_front_m)
        )

    def lead_distance(self, t: ArrayLike) -> FloatArray:
        """Camera to lead rear face along X at times ``t``."""
        c = self.config
        return lead_distance(self.ego, self.lead, c.camera_forward_m, c.camera_height_m, t)

    def camera_pose_at(self, t: float) -> CameraPose:
        c = self.config
        return camera_pose_at(self.ego, c.camera_forward_m, c.camera_height_m, t)

    def camera_track(self, times: ArrayLike) -> CameraTrack:
        c = self.config
        return camera_track(self.ego, c.camera_forward_m, c.camera_height_m, times)

    def vehicles_at(self, t: float) -> list[VehiclePose]:
        """Poses of every vehicle the ego camera may see (the lead and the traffic) at ``t``."""
        return [self.lead.pose_at(t), *(v.pose_at(t) for v in self.traffic)]


def simulate_motion(cfg: MotionConfig, rng: np.random.Generator) -> DriveMotion:
    """Simulate a drive; the same configuration and generator state give identical arrays."""
    check_ranges(cfg, "motion")
    cfg.validate("motion")
    kin = _kinematics(cfg, "motion")
    road = generate_road(cfg.road, rng)
    ego = simulate_vehicle(
        cfg.ego,
        road,
        kin.t,
        kin.x_ego,
        kin.v_ego,
        kin.a_ego,
        cfg.ego_lateral_m,
        vehicle_id=0,
        appearance=0,
    )
    lead = simulate_vehicle(
        cfg.lead,
        road,
        kin.t,
        kin.x_lead,
        kin.v_lead,
        kin.a_lead,
        cfg.lead_lateral_m,
        vehicle_id=1,
        is_lead=True,
        appearance=int(rng.integers(0, 2**31 - 1)),
    )
    traffic = _traffic(cfg, road, kin, rng)
    return DriveMotion(
        config=cfg,
        road=road,
        ego=ego,
        lead=lead,
        traffic=traffic,
        events=_events(cfg, road, ego, lead),
    )


__all__ = [
    "MIN_GAP_M",
    "AnomalyEvent",
    "CameraTrack",
    "DriveMotion",
    "GapKnot",
    "LeadEvent",
    "MotionConfig",
    "SpeedKnot",
    "TrafficTrajectory",
    "TrafficVehicle",
    "camera_pose_at",
    "camera_track",
    "lead_distance",
    "simulate_motion",
]
