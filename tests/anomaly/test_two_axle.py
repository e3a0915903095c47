"""The two-axle CFAR detector: signature, channels, background, resolution, bad input."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pytest

from roadpreview.anomaly import AnomalyEvent, EventKind, TrajectorySample, TwoAxleConfig
from roadpreview.anomaly.response import NominalVehicle, TemplateBank
from roadpreview.anomaly.two_axle import TwoAxleDetector
from roadpreview.types import Side

VEH = NominalVehicle()


def _trajectory(
    *,
    duration_s: float = 40.0,
    fps: float = 30.0,
    focal_px: float = 1000.0,
    distance_m: float = 15.0,
    speed_mps: float = 10.0,
    events: Sequence[tuple[float, float, float, str]] = (),
    noise_px: float = 0.15,
    rough_mm: float = 0.0,
    seed: int = 0,
    wheelbase_m: float = VEH.wheelbase_m,
) -> list[TrajectorySample]:
    """A lead at a constant distance and speed; ``events`` (front-axle crossing time s,
    height m, duration s, side "both"/"left"/"right") move its rear face as the two-axle
    model (of a car with ``wheelbase_m``); ``rough_mm``: a rough road's bouncing (1.3 Hz
    band-limited noise of this RMS at the rear face); tracking noise in px per half."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / fps)
    z_left = np.zeros_like(t)
    z_right = np.zeros_like(t)
    for t0, h, dur, side in events:
        bank = TemplateBank.build(VEH, (dur,))
        z = h * bank.two_axle(t - t0, wheelbase_m / speed_mps, VEH.rho)[0]
        if side in ("both", "left"):
            z_left += z
        if side in ("both", "right"):
            z_right += z
    if rough_mm > 0:
        for z in (z_left, z_right):
            w = rng.normal(0.0, 1.0, t.size)
            # a resonant body: white noise through a 1.3 Hz second-order filter
            wn, zeta, dt = 2 * math.pi * 1.3, 0.3, 1.0 / fps
            x = v = 0.0
            out = np.empty_like(t)
            for i in range(t.size):
                a = wn * wn * (w[i] - x) - 2 * zeta * wn * v
                v += a * dt
                x += v * dt
                out[i] = x
            z += rough_mm * 1e-3 * out / out.std()
    scale = focal_px / distance_m
    y_l = 400.0 - scale * z_left + rng.normal(0.0, noise_px, t.size)
    y_r = 400.0 - scale * z_right + rng.normal(0.0, noise_px, t.size)
    return [
        TrajectorySample(
            t=float(t[i]),
            y_c=float(0.5 * (y_l[i] + y_r[i])),
            y_c_left=float(y_l[i]),
            y_c_right=float(y_r[i]),
            lead_distance_m=distance_m,
            lead_distance_std_m=0.5,
            ego_speed_mps=speed_mps,
            focal_px=focal_px,
            compensation_px=0.0,
        )
        for i in range(t.size)
    ]


def _run(
    samples: list[TrajectorySample], cfg: TwoAxleConfig | None = None
) -> tuple[TwoAxleDetector, list[AnomalyEvent]]:
    det = TwoAxleDetector(cfg)
    events: list[AnomalyEvent] = []
    for s in samples:
        events += det.push(s)
    events += det.flush()
    # the two-axle fit's events (the provisional ones: test_provisional.py)
    return det, [e for e in events if not e.suppressed and e.kind is EventKind.CONFIRMED]


def test_a_bump_is_found_at_its_crossing_with_its_height_and_side() -> None:
    samples = _trajectory(events=[(20.0, 0.05, 0.2, "both")])
    _, events = _run(samples)
    assert len(events) == 1
    e = events[0]
    assert e.t_s == pytest.approx(20.1, abs=0.1)  # the front axle over the bump's middle
    assert e.side is Side.BOTH
    # a 2 m bump at 10 m/s (0.2 s): the height is resolved within its stated std
    assert abs(e.height_m - 0.05) < 2 * e.height_std_m
    assert e.height_m == pytest.approx(0.05, rel=0.5)
    # the anomaly lies a wheelbase and an overhang ahead of the lead's rear face
    assert e.anomaly_distance_m == pytest.approx(15.0 + VEH.wheelbase_m + VEH.rear_overhang_m)
    assert e.t_emit_s - e.t_s < VEH.wheelbase_m / 10.0 + 0.2 + 0.3 + 0.45 + 0.1  # τ+D+post+peak
    assert 0.5 < e.confidence <= 1.0


def test_a_pothole_has_a_negative_height() -> None:
    _, events = _run(_trajectory(events=[(20.0, -0.06, 0.1, "both")]))
    assert len(events) == 1
    e = events[0]
    assert e.height_m < 0
    # 1 m at 10 m/s: its body response is its depth x length, the std says so
    assert abs(e.height_m + 0.06) < 2 * e.height_std_m


def test_the_second_axle_arrives_at_the_predicted_lag() -> None:
    """The rear face moves most when the rear axle crosses, τ = wheelbase / v after the
    front one, and dips when the front one does. With the car's own wheelbase (2.7 m at
    10 m/s: 0.27 s) the detector places the crossing right and scores the bump high; if
    it assumed a much shorter car (1.5 m: 0.15 s) the signature does not fit: a low score
    at a wrong time."""
    speed = 10.0
    samples = _trajectory(events=[(20.0, 0.05, 0.05, "both")], noise_px=0.1, speed_mps=speed)
    found = {}
    for wheelbase in (1.5, 2.7):
        cfg = TwoAxleConfig(vehicle=replace(VEH, wheelbase_m=wheelbase))
        _, events = _run(samples, cfg)
        assert len(events) <= 1
        found[wheelbase] = events
    [right] = found[2.7]
    assert right.t_s == pytest.approx(20.025, abs=0.05)  # the bump's middle
    for wrong in found[1.5]:  # if found at all: a weak fit at a wrong time
        assert right.score > 2 * wrong.score
        assert abs(wrong.t_s - 20.025) > 2 * abs(right.t_s - 20.025)


def test_the_simulated_lead_moves_at_both_axles() -> None:
    """In the simulator's 7-DOF car the rear face dips when the front axle crosses a bump
    (the nose rises) and rises a wheelbase / speed later with the rear axle."""
    from roadpreview.sim.road import Anomaly, Road
    from roadpreview.sim.vehicle import VehicleParams, simulate_vehicle

    p = VehicleParams()
    speed = 8.0
    road = Road.flat(
        200.0,
        anomalies=[
            Anomaly(
                kind="bump", start_x_m=50.0, length_m=0.3, height_m=0.05, width_m=3.5, ramp_m=0.05
            )
        ],
    )
    t = np.arange(0.0, 10.0, 0.002)
    m = simulate_vehicle(p, road, t, 20.0 + speed * t, np.full_like(t, speed), 0 * t, 0.0)
    face = m.heave - (p.cg_to_rear_axle_m + VEH.rear_overhang_m) * m.pitch
    t_front = (50.15 - 20.0 - p.cg_to_front_axle_m) / speed
    t_rear = t_front + p.wheelbase_m / speed
    early = (t > t_front) & (t < t_rear)
    late = (t > t_rear) & (t < t_rear + 0.6)
    assert face[early].min() < -0.2 * face[late].max()  # the dip from the front axle
    t_peak = t[late][np.argmax(face[late])]
    assert 0.05 < t_peak - t_rear < 0.35  # the rear axle's rise, a quarter body period on


def test_a_one_sided_pothole_shows_on_the_roll_channel() -> None:
    samples = _trajectory(events=[(20.0, -0.06, 0.1, "left")])
    _, events = _run(samples)
    assert len(events) == 1
    e = events[0]
    assert e.side is Side.LEFT
    assert e.height_m < 0
    assert abs(e.height_m + 0.06) < 2 * e.height_std_m
    _, right = _run(_trajectory(events=[(20.0, -0.06, 0.1, "right")]))
    assert [x.side for x in right] == [Side.RIGHT]


def test_the_ego_motion_cancels_out_of_the_roll_channel() -> None:
    """A residual of the ego's compensation moves both halves alike: the heave channel sees
    it, the roll channel does not."""
    samples = _trajectory(events=[(20.0, 0.05, 0.2, "both")], noise_px=0.0)
    det = TwoAxleDetector()
    heave = roll = 0.0
    for s in samples:
        det.push(s)
        fit = det._fit(s.t, s)
        if fit is not None:
            heave = max(heave, float(np.nanmax(np.abs(fit.amplitude[0]))))
            roll = max(roll, float(np.nanmax(np.abs(fit.amplitude[1]))))
    assert heave > 0.03
    assert roll < 1e-9


def test_on_a_clean_rough_road_the_background_rises_and_false_alarms_stay_rare() -> None:
    calm = TwoAxleDetector()
    for s in _trajectory(duration_s=60.0):
        calm.push(s)
    rough, events = _run(_trajectory(duration_s=300.0, rough_mm=12.0, seed=3))
    assert np.nanmedian(rough.background_m[0]) > 3 * np.nanmedian(calm.background_m[0])
    assert len(events) / 5.0 <= 0.5  # per minute, over 5 minutes of a class D-like road
    # a 6 cm bump on the same rough road still stands out
    _, hit = _run(
        _trajectory(duration_s=60.0, rough_mm=12.0, seed=3, events=[(40.0, 0.06, 0.25, "both")])
    )
    assert any(abs(e.t_s - 40.0) < 0.3 for e in hit)


@pytest.mark.parametrize("fps", [25.0, 60.0])
def test_the_same_road_at_three_resolutions_gives_the_same_detections(fps: float) -> None:
    """640x360, 1280x720 and 1920x1080 over the same road (focal length ∝ width, tracking
    noise in pixels alike): the same anomalies, heights within 25 %."""
    events = [(10.0, 0.05, 0.2, "both"), (22.0, -0.07, 0.1, "left"), (33.0, 0.06, 0.4, "both")]
    found = {}
    for focal in (500.0, 1000.0, 1500.0):
        _, ev = _run(_trajectory(focal_px=focal, fps=fps, events=events, seed=1))
        found[focal] = ev
    for focal, ev in found.items():
        assert [round(e.t_s) for e in ev] == [10, 22, 33], focal
        assert [e.side for e in ev] == [Side.BOTH, Side.LEFT, Side.BOTH], focal
        for e, (_, h, _, _) in zip(ev, events, strict=True):
            assert e.height_m * h > 0  # bump or pothole
            # a short anomaly's height trades with its length: within its stated std
            assert abs(e.height_m - h) < 2.5 * e.height_std_m
    # and alike at every resolution, within what each says of itself
    for k in range(len(events)):
        heights = [found[f][k].height_m for f in found]
        stds = [found[f][k].height_std_m for f in found]
        assert max(heights) - min(heights) < 2 * max(stds)


def test_bad_input_gives_no_alert_and_no_crash() -> None:
    base = _trajectory(duration_s=30.0)
    bad = []
    for i, s in enumerate(base):
        if 100 <= i < 130:  # NaN halves
            s = replace(s, y_c_left=math.nan, y_c_right=math.nan)
        elif 200 <= i < 260:  # the lead lost for 2 s
            s = replace(s, valid=False, y_c=math.nan)
        elif 400 <= i < 500:  # standing still
            s = replace(s, ego_speed_mps=0.0)
        elif 600 <= i < 700:  # the gap closing fast, a distance glitch
            d = 15.0 - 0.5 * (i - 600) if i % 7 else math.nan
            s = replace(s, lead_distance_m=d)
        bad.append(s)
    _, events = _run(bad)
    assert events == []
