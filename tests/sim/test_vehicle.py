"""Vehicle dynamics against closed-form quarter-car / half-car answers, energy, dive, speed."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from roadpreview.configtools import from_mapping
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.sim.road import Anomaly, Road, RoadConfig, generate_road, paper_speed_bump
from roadpreview.sim.vehicle import (
    VehicleModel,
    VehicleParams,
    simulate_vehicle,
    wheel_road_inputs,
)

DT = 0.001
FN, ZETA = 1.2, 0.25


def decoupled(model: str = "3dof", zeta: float = ZETA, **kw: float | str) -> VehicleParams:
    """A car whose front and rear corners move as independent quarter cars: equal ride
    frequencies, dynamic index I_pitch / (m a b) = 1 and I_roll = m (track/2)^2; no tyre
    enveloping, so the road reaches the springs unfiltered."""
    m, a, b, track = 1200.0, 1.2, 1.3, 1.5
    base: dict[str, float | str] = dict(
        model=model, sprung_mass_kg=m, cg_to_front_axle_m=a, cg_to_rear_axle_m=b, track_m=track,
        pitch_inertia_kgm2=m * a * b, roll_inertia_kgm2=m * (track / 2) ** 2,
        front_ride_freq_hz=FN, rear_ride_freq_hz=FN, front_damping_ratio=zeta,
        rear_damping_ratio=zeta, wheel_radius_m=0.0, contact_length_m=0.0,
    )
    base.update(kw)
    return VehicleParams(**base)  # type: ignore[arg-type]


def base_step(t: np.ndarray, fn: float = FN, zeta: float = ZETA) -> np.ndarray:
    """Closed-form response of a spring-damper quarter car (damper to the road) to a unit
    step of the road at t = 0: 1 - exp(-s t) (cos wd t - s / wd sin wd t)."""
    wn = 2 * math.pi * fn
    s, wd = zeta * wn, wn * math.sqrt(1 - zeta * zeta)
    tp = np.clip(t, 0.0, None)
    out = 1 - np.exp(-s * tp) * (np.cos(wd * tp) - s / wd * np.sin(wd * tp))
    return np.where(t >= 0, out, 0.0)


def base_step_peak(fn: float = FN, zeta: float = ZETA) -> float:
    """Closed-form peak of `base_step`: at wd t = pi - atan(2 s wd / (wd^2 - s^2))."""
    wn = 2 * math.pi * fn
    s, wd = zeta * wn, wn * math.sqrt(1 - zeta * zeta)
    tp = (math.pi - math.atan(2 * s * wd / (wd * wd - s * s))) / wd
    return float(base_step(np.array([tp]), fn, zeta)[0])


def crossing_period(t: np.ndarray, signal: np.ndarray) -> float:
    """Mean period from successive upward zero crossings (linearly interpolated)."""
    i = np.nonzero((signal[:-1] < 0) & (signal[1:] >= 0))[0]
    tc = t[i] - signal[i] * (t[i + 1] - t[i]) / (signal[i + 1] - signal[i])
    return float(np.diff(tc).mean())


def test_four_wheel_step_heave_peak_and_ringing_match_quarter_car() -> None:
    h = 0.05
    model = VehicleModel(decoupled())
    t = np.arange(0.0, 6.0, DT)
    w = np.where(t[:, None] >= 0.5, h, 0.0) * np.ones((1, 4))
    q = model.respond(t, w).q
    z, pitch, roll = q[:, 0], q[:, 1], q[:, 2]
    peak_expected = h * base_step_peak()
    # 1.506 h for fn = 1.2 Hz, zeta = 0.25: more than a force step's overshoot
    # exp(-zeta pi / sqrt(1 - zeta^2)) = 0.444, because the damper also pushes
    assert z.max() == pytest.approx(peak_expected, rel=0.005)
    assert z.max() - h == pytest.approx(peak_expected - h, rel=0.02)
    fd = FN * math.sqrt(1 - ZETA**2)
    after = t > 0.5
    assert 1 / crossing_period(t[after], z[after] - h) == pytest.approx(fd, rel=0.01)
    assert np.abs(pitch).max() < 1e-12
    assert np.abs(roll).max() < 1e-12


def test_road_step_pitch_and_heave_match_delayed_quarter_cars() -> None:
    """A joint step across the lane crossed at 5 m/s: the front corner answers like a quarter
    car at t_f, the rear like one at t_f + L / v; heave and pitch are their combinations."""
    p = decoupled()
    h, v, x_step, x0 = 0.03, 5.0, 20.0, 10.0
    road = Road.flat(100.0, anomalies=[Anomaly(kind="step", start_x_m=x_step, length_m=0.0,
                                               height_m=h)])
    t = np.arange(0.0, 6.0, DT)
    body = simulate_vehicle(p, road, t, x0 + v * t, np.full(t.size, v), np.zeros(t.size), 0.0)
    a, b, wb = p.cg_to_front_axle_m, p.cg_to_rear_axle_m, p.wheelbase_m
    t_front = (x_step - x0 - a) / v
    t_rear = t_front + wb / v
    z_front, z_rear = h * base_step(t - t_front), h * base_step(t - t_rear)
    heave = (b * z_front + a * z_rear) / wb
    pitch = (z_front - z_rear) / wb
    assert np.abs(body.pitch - pitch).max() < 0.02 * np.abs(pitch).max()
    assert body.pitch.max() == pytest.approx(pitch.max(), rel=0.02)
    assert body.pitch.min() == pytest.approx(pitch.min(), rel=0.02)
    z = body.z - p.shape.cg_height_m
    assert np.abs(z - heave).max() < 0.02 * h
    assert z.max() == pytest.approx(heave.max(), rel=0.02)
    np.testing.assert_allclose(body.heave, z, atol=1e-12)  # flat road: heave is z itself


def test_braking_dive_static_pitch_overshoot_and_sign() -> None:
    """A step of a_x: the pitch mode of the decoupled car is a force-driven oscillator, so it
    overshoots its static value m a h / K_pitch by exp(-zeta pi / sqrt(1 - zeta^2))."""
    p = decoupled()
    model = VehicleModel(p)
    accel = -4.0
    t = np.arange(0.0, 8.0, DT)
    a_x = np.where(t >= 0.5, accel, 0.0)
    pitch = model.respond(t, np.zeros((t.size, 4)), a_x).q[:, 1]
    k = model.rates
    k_pitch = 2 * (k.front_spring_npm * p.cg_to_front_axle_m**2
                   + k.rear_spring_npm * p.cg_to_rear_axle_m**2)
    static = p.sprung_mass_kg * accel * p.shape.cg_height_m / k_pitch
    assert static < 0  # braking: nose down
    assert pitch[-1] == pytest.approx(static, rel=1e-3)
    overshoot = (pitch.min() - static) / static
    assert overshoot == pytest.approx(math.exp(-ZETA * math.pi / math.sqrt(1 - ZETA**2)), rel=0.02)


def test_braking_dive_of_the_default_7dof_car_through_the_drive() -> None:
    """Default (coupled, 7-DOF) car braking at 2 m/s^2 on a flat road: the static pitch is
    m a h / K_pitch with series spring-tyre rates and the heave-pitch coupling."""
    p = VehicleParams()
    t = np.arange(0.0, 6.0, DT)
    accel = -2.0
    a = np.where(t >= 0.5, accel, 0.0)
    v = 14.0 + np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1])) * DT])
    x = 10.0 + np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) * DT])
    body = simulate_vehicle(p, Road.flat(200.0), t, x, v, a, 0.0)
    r = VehicleModel(p).rates
    kt = p.tyre_stiffness_npm
    kf = r.front_spring_npm * kt / (r.front_spring_npm + kt)
    kr = r.rear_spring_npm * kt / (r.rear_spring_npm + kt)
    fa, rb = p.cg_to_front_axle_m, p.cg_to_rear_axle_m
    k_zz, k_zt, k_tt = 2 * (kf + kr), 2 * (kf * fa - kr * rb), 2 * (kf * fa**2 + kr * rb**2)
    k_pitch = k_tt - k_zt**2 / k_zz
    static = p.sprung_mass_kg * accel * p.shape.cg_height_m / k_pitch
    assert body.pitch[-1] == pytest.approx(static, rel=0.01)
    assert body.pitch[-1] < -0.005  # about 0.6 deg nose down


def test_flat_road_gives_no_motion() -> None:
    road = generate_road(RoadConfig(iso_class="off", hill_grade_pct=0.0, cross_slope_pct=0.0,
                                    anomaly_density_per_km=0.0, length_m=500.0),
                         np.random.default_rng(0))
    t = np.arange(0.0, 10.0, DT)
    v = np.full(t.size, 15.0)
    for p in (VehicleParams(), decoupled()):
        body = simulate_vehicle(p, road, t, 20.0 + v * t, v, np.zeros(t.size), 0.3)
        for arr in (body.heave, body.z - p.shape.cg_height_m, body.pitch, body.roll,
                    body.pitch_rate, body.accel_world[:, 2]):
            assert np.abs(arr).max() < 1e-9


@pytest.mark.parametrize("model", ["3dof", "7dof"])
def test_energy_decays_with_damping_and_is_conserved_without(model: str) -> None:
    t = np.arange(0.0, 10.0, DT)
    w = np.zeros((t.size, 4))
    for zeta in (0.3, 0.0):
        vm = VehicleModel(VehicleParams(model=model, front_damping_ratio=zeta,
                                        rear_damping_ratio=zeta))
        qd0 = np.zeros(vm.ndof)
        qd0[:3] = (0.3, 0.2, 0.3)  # an impulse: heave, pitch and roll velocities
        if model == "7dof":
            qd0[3:] = (0.5, -0.4, 0.2, 0.1)
        r = vm.respond(t, w, q0=np.zeros(vm.ndof), qd0=qd0)
        energy = vm.energy(r.q, r.qd)
        e0 = float(energy[0])
        if zeta > 0:
            assert np.diff(energy).max() <= 1e-12 * e0  # never increases
            second = energy[t.searchsorted(np.arange(0, 10, 1.0))]
            assert np.all(np.diff(second) < 0)  # strictly falls from period to period
            assert energy[-1] < 1e-3 * e0
        else:
            assert np.abs(energy / e0 - 1).max() < 1e-6


def test_7dof_modes_include_the_two_mass_quarter_car_roots() -> None:
    """Front and rear corners alike (a = b): heave with all wheels in phase is a two-mass
    quarter car (m_s / 4 on k, m_u on k_t); its undamped frequencies solve
    m_s m_u w^4 - (k m_u + (k + k_t) m_s) w^2 + k k_t = 0 per corner."""
    p = decoupled("7dof", zeta=0.0, cg_to_front_axle_m=1.25, cg_to_rear_axle_m=1.25,
                  pitch_inertia_kgm2=1200 * 1.25**2, front_unsprung_kg=40.0,
                  rear_unsprung_kg=40.0)
    vm = VehicleModel(p)
    freqs, zetas = vm.modes()
    ms, mu, k, kt = 300.0, 40.0, vm.rates.front_spring_npm, p.tyre_stiffness_npm
    poly = [ms * mu, -(k * mu + (k + kt) * ms), k * kt]
    roots = np.sort(np.sqrt(np.roots(poly).real)) / (2 * math.pi)
    for f in roots:
        assert np.abs(freqs - f).min() < 1e-6 * f
    assert np.abs(zetas).max() < 1e-9
    # the ride frequency counts the tyre in series: the body mode sits at the requested 1.2 Hz
    # up to the unsprung-mass correction (below 2 %)
    assert roots[0] == pytest.approx(FN, rel=0.02)


def test_7dof_bump_response_matches_an_independent_ode_solver() -> None:
    """The exact discretisation against scipy's RK45 on the same ODE (inputs linear between
    samples), the default car over the paper's bump at 20 km/h."""
    p = VehicleParams()
    road = Road.flat(100.0, anomalies=[paper_speed_bump(15.0)])
    t = np.arange(0.0, 3.0, DT)
    v = 20 / 3.6
    x = 12.0 + v * t
    vm = VehicleModel(p)
    w = wheel_road_inputs(p, road, x, 0.0)
    r = vm.respond(t, w)
    m_inv = np.linalg.inv(vm.m)
    nd = vm.ndof

    def rhs(tt: float, s: np.ndarray) -> np.ndarray:
        wt = np.array([np.interp(tt, t, w[:, i]) for i in range(4)])
        i = min(int(tt / DT), t.size - 2)
        wd = (w[i + 1] - w[i]) / DT
        acc = m_inv @ (-vm.k @ s[:nd] - vm.c @ s[nd:] + vm.kw @ wt + vm.cw @ wd)
        return np.concatenate([s[nd:], acc])

    sol = solve_ivp(rhs, (0.0, 1.6), np.zeros(2 * nd), t_eval=t[t <= 1.6], rtol=1e-8,
                    atol=1e-11, max_step=DT)
    ref = sol.y[:nd].T
    scale = np.abs(ref[:, :2]).max(axis=0)  # heave and pitch (a symmetric bump: no roll)
    err = np.abs(r.q[: ref.shape[0], :2] - ref[:, :2]).max(axis=0)
    assert np.all(err < 1e-4 * scale)
    # physics sanity: the body rises by the order of the bump height, nose up first
    assert 0.3 * 0.06 < r.q[:, 0].max() < 1.5 * 0.06
    first = np.argmax(np.abs(r.q[:, 1]) > 1e-4)
    assert r.q[first, 1] > 0


def test_wheel_envelope_bridges_a_short_pothole() -> None:
    """A 0.3 m long, 8 cm deep pothole: a 0.31 m wheel drops only R - sqrt(R^2 - (L/2)^2) =
    3.8 cm into it, a point follower the full 8 cm."""
    hole = Anomaly(kind="pothole", start_x_m=20.0, length_m=0.3, height_m=-0.08, width_m=3.5)
    road = Road.flat(100.0, anomalies=[hole])
    x = np.arange(10.0, 25.0, 0.002)
    disc = dataclasses.replace(VehicleParams(), contact_length_m=0.0)
    point = dataclasses.replace(disc, wheel_radius_m=0.0)
    drop_disc = wheel_road_inputs(disc, road, x, 0.0).min()
    drop_point = wheel_road_inputs(point, road, x, 0.0).min()
    r = disc.wheel_radius_m
    assert drop_point == pytest.approx(-0.08)
    assert drop_disc == pytest.approx(-(r - math.sqrt(r * r - 0.15**2)), abs=1e-3)


def test_modal_and_loop_propagation_agree() -> None:
    p = VehicleParams()
    road = generate_road(RoadConfig(iso_class="D", length_m=300.0), np.random.default_rng(0))
    t = np.arange(0.0, 5.0, DT)
    v = np.full(t.size, 12.0)
    args = (p, road, t, 30.0 + v * t, v, np.zeros(t.size), 0.2)
    modal = simulate_vehicle(*args, method="modal")
    loop = simulate_vehicle(*args, method="loop")
    for name in ("z", "pitch", "roll", "pitch_rate", "accel_world"):
        ref = getattr(loop, name)
        assert np.abs(getattr(modal, name) - ref).max() < 1e-9 * np.abs(ref).max()


def test_pose_sample_and_body_points_follow_the_sign_conventions() -> None:
    p = VehicleParams()
    # a bump under the left wheels only: nose up, then left side up, as it is climbed
    road = Road.flat(200.0, anomalies=[paper_speed_bump(40.0, center_y_m=1.0, width_m=1.0)])
    t = np.arange(0.0, 4.0, DT)
    v = np.full(t.size, 8.0)
    body = simulate_vehicle(p, road, t, 20.0 + v * t, v, np.zeros(t.size), 0.0, vehicle_id=3)
    i = int(np.argmax(body.roll))
    ti = float(t[i])
    assert body.roll[i] > 0.01
    assert body.wheel_road[i, 0] > 0.0
    pose = body.pose_at(ti)
    assert pose.vehicle_id == 3
    assert pose.pitch_rad == pytest.approx(body.pitch[i])
    assert pose.roll_rad == pytest.approx(body.roll[i])
    pts = body.point_world(ti, [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(pts[2], [body.x[i], 0.0, body.z[i]], atol=1e-12)
    # a point 2 m ahead is higher by 2 sin(pitch); one 1 m left by cos(pitch) sin(roll)
    assert abs(body.pitch[i]) > 1e-3
    assert pts[0, 2] - pts[2, 2] == pytest.approx(2 * math.sin(body.pitch[i]), rel=1e-9)
    assert pts[1, 2] - pts[2, 2] == pytest.approx(
        math.cos(body.pitch[i]) * math.sin(body.roll[i]), rel=1e-9)
    assert pts[1, 1] == pytest.approx(math.cos(body.roll[i]), rel=1e-9)
    half = body.sample(t[:-1] + DT / 2)
    np.testing.assert_allclose(half.z, 0.5 * (body.z[:-1] + body.z[1:]), atol=1e-15)
    assert half.accel_world.shape == (t.size - 1, 3)
    with pytest.raises(InputDataError, match="times"):
        body.sample([5.0])


def test_vehicle_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError, match="front_spring_npm: missing"):
        from_mapping(VehicleParams, {"suspension_from": "rates"}, where="ego")
    with pytest.raises(ConfigError, match=r"ego\.rear_damper_nspm: given"):
        from_mapping(VehicleParams, {"rear_damper_nspm": 1500.0}, where="ego")
    with pytest.raises(ConfigError, match="cg_to_front_axle_m"):
        from_mapping(VehicleParams, {"cg_to_front_axle_m": 2.5})
    with pytest.raises(ConfigError, match="front_ride_freq_hz"):
        from_mapping(VehicleParams, {"front_ride_freq_hz": 5.0})
    with pytest.raises(ConfigError, match=r"shape\.wheels"):
        from_mapping(VehicleParams, {"shape": {"wheels": 4}}, where="ego")
    rates = from_mapping(VehicleParams, {
        "suspension_from": "rates", "front_spring_npm": 30e3, "rear_spring_npm": 28e3,
        "front_damper_nspm": 2000.0, "rear_damper_nspm": 1800.0})
    assert rates.rates().front_spring_npm == 30e3
