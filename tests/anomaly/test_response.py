"""The detector's nominal vehicle against the simulator's independent 7-DOF car."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.anomaly.response import NominalVehicle, TemplateBank, roughness_gain, tukey_pulse
from roadpreview.sim.road import Anomaly, Road
from roadpreview.sim.vehicle import VehicleParams, simulate_vehicle


def test_quarter_car_follows_slow_road_and_resonates_at_its_ride_frequency() -> None:
    veh = NominalVehicle()
    f = np.array([0.01, veh.ride_freq_hz, 20.0])
    g = np.sqrt(veh.gain_sq(f))
    assert g[0] == pytest.approx(1.0, abs=1e-3)  # a long wave lifts the body as much
    assert g[1] > 1.5  # resonance near the ride frequency (ζ = 0.3: about 1/(2ζ))
    assert g[2] < 0.1  # the springs filter short waves
    peak_f = np.geomspace(0.5, 5, 400)[np.argmax(veh.gain_sq(np.geomspace(0.5, 5, 400)))]
    assert peak_f == pytest.approx(veh.ride_freq_hz, rel=0.15)


def test_tukey_pulse_is_a_unit_pulse_of_its_duration() -> None:
    t = np.linspace(-0.1, 0.6, 701)
    p = tukey_pulse(t, 0.5)
    assert p.max() == pytest.approx(1.0)
    assert np.all(p[(t < 0) | (t > 0.5)] == 0)
    assert np.all((p >= 0) & (p <= 1))


@pytest.mark.parametrize(
    ("length_m", "height_m", "speed_mps"),
    [(2.0, 0.06, 6.0), (0.8, -0.06, 8.3), (3.0, 0.07, 5.5), (0.5, 0.05, 10.0)],
)
def test_two_axle_template_matches_the_simulated_car(
    length_m: float, height_m: float, speed_mps: float
) -> None:
    """The rear face of the simulator's mid-size car (7-DOF, tyre enveloping, pitch coupling)
    over a full-width anomaly moves as h x the nominal two-axle template: correlation > 0.95
    and amplitude within 30 % (the enveloping tyre widens short anomalies)."""
    p = VehicleParams()
    kind = "pothole" if height_m < 0 else "bump"
    ramp = min(0.25 * length_m, 0.2)
    a = Anomaly(
        kind=kind, start_x_m=50.0, length_m=length_m, height_m=height_m, width_m=3.5, ramp_m=ramp
    )
    road = Road.flat(200.0, anomalies=[a])
    t = np.arange(0.0, 12.0, 0.002)
    x = 20.0 + speed_mps * t
    m = simulate_vehicle(p, road, t, x, np.full_like(t, speed_mps), np.zeros_like(t), 0.0)
    veh = NominalVehicle()
    z_face = m.heave - (p.cg_to_rear_axle_m + veh.rear_overhang_m) * m.pitch
    t_front = (50.0 - 20.0 - p.cg_to_front_axle_m) / speed_mps
    bank = TemplateBank.build(veh, (length_m / speed_mps,))
    tpl = height_m * bank.two_axle(t - t_front, veh.wheelbase_m / speed_mps, veh.rho)[0]
    sel = (t > t_front - 0.5) & (t < t_front + 3.0)
    z = z_face[sel] - z_face[sel][0]
    assert np.corrcoef(z, tpl[sel])[0, 1] > 0.95
    ratio = float(np.dot(z, tpl[sel]) / np.dot(tpl[sel], tpl[sel]))
    assert 0.7 < ratio < 1.3


def test_roughness_gain_grows_with_speed_and_class() -> None:
    veh = NominalVehicle()
    g10 = roughness_gain(veh, 10.0, derivative=2, band_hz=(0.3, 20.0))
    g20 = roughness_gain(veh, 20.0, derivative=2, band_hz=(0.3, 20.0))
    assert g20 == pytest.approx(2 * g10, rel=1e-9)  # G_t ∝ v for waviness 2
    assert math.isnan(roughness_gain(veh, 0.0, derivative=2, band_hz=(0.3, 20.0)))
    # ISO class C (256e-6 m³) at 36 km/h: body acceleration of order 1 m/s² (a rough ride)
    rms = math.sqrt(256e-6 * g10)
    assert 0.3 < rms < 3.0
