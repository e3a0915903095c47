"""Road model: ISO 8608 roughness spectrum, track coherence, hills, anomaly geometry, config."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import coherence, welch

from roadpreview.configtools import from_mapping
from roadpreview.errors import ConfigError
from roadpreview.sim.road import (
    ISO8608_GD_N0,
    Anomaly,
    Road,
    RoadConfig,
    generate_road,
    iso8608_psd,
    paper_speed_bump,
)


def smooth(iso_class: str, length_m: float, track_coherence: float = 0.5) -> RoadConfig:
    """Roughness only: no hills, crossfall or anomalies."""
    return RoadConfig(iso_class=iso_class, length_m=length_m, track_coherence=track_coherence,
                      hill_grade_pct=0.0, cross_slope_pct=0.0, anomaly_density_per_km=0.0)


def _profile(road: Road, y: float, dx: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    x = np.arange(0.0, road.length_m, dx)
    return x, road.height(x, y)


def test_iso8608_class_c_psd_matches_within_factor_1_5() -> None:
    road = generate_road(smooth("C", 2000.0), np.random.default_rng(1))
    for track_y in (road.left_track_y_m, road.right_track_y_m):
        _, h = _profile(road, track_y)
        n, psd = welch(h, fs=1 / 0.05, nperseg=4096)
        band = (n >= 0.05) & (n <= 2.0)
        ratio = psd[band] / iso8608_psd(n[band], "C")
        assert ratio.min() > 1 / 1.5
        assert ratio.max() < 1.5


@pytest.mark.parametrize(("lower", "upper"), [("A", "B"), ("B", "C"), ("C", "D"), ("D", "E")])
def test_each_iso_class_doubles_the_rms(lower: str, upper: str) -> None:
    """Gd(n0) quadruples from class to class, so with equal phases the RMS doubles exactly."""
    assert ISO8608_GD_N0[upper] == pytest.approx(4 * ISO8608_GD_N0[lower])
    rms = []
    for cls in (lower, upper):
        road = generate_road(smooth(cls, 300.0), np.random.default_rng(5))
        rms.append(float(np.std(_profile(road, road.left_track_y_m)[1])))
    assert rms[1] / rms[0] == pytest.approx(2.0, rel=1e-9)


@pytest.mark.parametrize("c", [0.3, 0.9])
def test_track_coherence_is_the_square_of_the_parameter(c: float) -> None:
    road = generate_road(smooth("C", 2000.0, c), np.random.default_rng(2))
    _, left = _profile(road, road.left_track_y_m)
    _, right = _profile(road, road.right_track_y_m)
    n, coh = coherence(left, right, fs=20.0, nperseg=2048)
    band = (n >= 0.05) & (n <= 2.0)
    # Welch coherence with ~75 averages is biased up by about (1 - c^2)^2 / 75
    assert float(coh[band].mean()) == pytest.approx(c * c, abs=0.06)


def test_roughness_between_and_beyond_the_tracks() -> None:
    road = generate_road(smooth("C", 200.0), np.random.default_rng(3))
    x = np.linspace(0, 199, 500)
    left, right = road.height(x, road.left_track_y_m), road.height(x, road.right_track_y_m)
    mid_y = 0.5 * (road.left_track_y_m + road.right_track_y_m)
    np.testing.assert_allclose(road.height(x, mid_y), 0.5 * (left + right), atol=1e-15)
    # mirrored beyond the tracks: one spacing left of the left track is the right track
    spacing = road.left_track_y_m - road.right_track_y_m
    np.testing.assert_allclose(road.height(x, road.left_track_y_m + spacing), right, atol=1e-15)
    np.testing.assert_allclose(road.height(x, road.right_track_y_m - spacing), left, atol=1e-15)


def test_hills_reach_the_configured_grade_and_grade_is_the_derivative() -> None:
    cfg = RoadConfig(iso_class="off", hill_grade_pct=4.0, hill_wavelength_m=300.0,
                     cross_slope_pct=0.0, anomaly_density_per_km=0.0, length_m=1500.0)
    road = generate_road(cfg, np.random.default_rng(4))
    x = np.arange(0.0, 1500.0, 0.5)
    h = road.height(x, 0.0)
    assert float(np.abs(road.grade(x)).max()) == pytest.approx(0.04, rel=0.01)
    numeric = np.gradient(h, x)
    np.testing.assert_allclose(road.grade(x)[1:-1], numeric[1:-1], atol=1e-5)


def test_crossfall_falls_from_the_centre_line() -> None:
    road = generate_road(RoadConfig(iso_class="off", hill_grade_pct=0.0, cross_slope_pct=2.5,
                                    anomaly_density_per_km=0.0), np.random.default_rng(0))
    crown = road.lane_width_m / 2
    assert road.height(50.0, crown) == pytest.approx(0.0)
    # ego lane (Y < crown) rises to the left: positive roll of a car on it
    assert road.height(50.0, 0.8) - road.height(50.0, -0.8) == pytest.approx(0.025 * 1.6)
    assert float(road.cross_slope_at(0.0)) == pytest.approx(0.025)
    assert float(road.cross_slope_at(road.lane_width_m)) == pytest.approx(-0.025)


def test_paper_speed_bump_geometry() -> None:
    bump = paper_speed_bump(100.0)
    ramp = 0.06 / math.tan(math.radians(7.0))
    assert bump.ramp_length_m == pytest.approx(ramp)
    assert bump.apex_x_m == pytest.approx(101.0)
    road = Road.flat(anomalies=[bump])
    assert road.height(101.0, 0.0) == pytest.approx(0.06)
    assert road.height(100.0 + ramp / 2, 0.5) == pytest.approx(0.03)
    assert road.height(102.0 - ramp / 4, -0.5) == pytest.approx(0.015)
    assert road.height(99.99, 0.0) == 0.0
    assert road.height(102.01, 0.0) == 0.0
    assert road.height(101.0, 1.8) == 0.0  # beyond the 3.5 m lane width


def test_pothole_under_the_left_track_only() -> None:
    hole = Anomaly(kind="pothole", start_x_m=50.0, length_m=0.6, height_m=-0.05,
                   center_y_m=0.78, width_m=0.5)
    road = Road.flat(anomalies=[hole])
    assert road.height(50.3, 0.78) == pytest.approx(-0.05)
    assert road.height(50.3, -0.78) == 0.0
    assert hole.side(0.0, 1.55) == "left"
    assert hole.side(1.55, 1.55) == "right"  # offset left by a track: its right wheels
    assert hole.side(-1.55, 1.55) == "none"  # offset right by a track: straddles nothing
    assert Anomaly(kind="bump", width_m=3.5).side(0.0, 1.55) == "both"


def test_step_wave_and_vectorised_height() -> None:
    step = Anomaly(kind="step", start_x_m=10.0, length_m=0.0, height_m=-0.02)
    wave = Anomaly(kind="wave", start_x_m=30.0, length_m=10.0, height_m=0.03, wavelength_m=2.4)
    road = Road.flat(anomalies=[step, wave])
    assert wave.effective_wavelength_m == pytest.approx(2.5)
    assert wave.apex_x_m == pytest.approx(31.25)
    x = np.array([[9.99, 10.0], [500.0, 31.25]])
    y = np.array([0.0, 1.0])
    h = road.height(x, y)
    assert h.shape == (2, 2)
    np.testing.assert_allclose(h, [[0.0, -0.02], [-0.02, 0.03 - 0.02]], atol=1e-12)
    assert road.height(40.0, 0.0) == pytest.approx(-0.02)  # the wave ends at zero


def test_random_anomalies_follow_density_and_mix() -> None:
    cfg = RoadConfig(length_m=20_000.0, anomaly_density_per_km=5.0, anomaly_min_spacing_m=0.0,
                     anomaly_mix={"pothole": 1.0, "step": 1.0})
    road = generate_road(cfg, np.random.default_rng(6))
    count = len(road.anomalies)
    assert abs(count - 100) < 4 * math.sqrt(100)
    assert {a.kind for a in road.anomalies} == {"pothole", "step"}
    for a in road.anomalies:
        a.validate("anomaly")
        assert 0 <= a.start_x_m <= cfg.length_m
        if a.kind == "pothole":
            assert -0.08 <= a.height_m <= -0.02


def test_explicit_anomalies_replace_random_ones() -> None:
    bump = paper_speed_bump(40.0)
    road = generate_road(RoadConfig(anomalies=[bump]), np.random.default_rng(0))
    assert road.anomalies == (bump,)


def test_same_seed_same_road_other_seed_other_road() -> None:
    cfg = RoadConfig(length_m=500.0)
    x = np.linspace(0, 499, 2000)
    a = generate_road(cfg, np.random.default_rng(11))
    b = generate_road(cfg, np.random.default_rng(11))
    c = generate_road(cfg, np.random.default_rng(12))
    np.testing.assert_array_equal(a.height(x, 0.3), b.height(x, 0.3))
    assert a.anomalies == b.anomalies
    assert not np.array_equal(a.height(x, 0.3), c.height(x, 0.3))


def test_config_from_mapping_and_errors_name_the_field() -> None:
    cfg = from_mapping(RoadConfig, {
        "iso_class": "C", "length_m": 300.0,
        "anomalies": [{"kind": "pothole", "start_x_m": 50.0, "length_m": 0.5, "height_m": -0.04,
                       "center_y_m": 0.8, "width_m": 0.4}],
    })
    assert cfg.anomalies[0].kind == "pothole"
    with pytest.raises(ConfigError, match="bumpiness"):
        from_mapping(RoadConfig, {"bumpiness": 3})
    with pytest.raises(ConfigError, match="iso_class"):
        from_mapping(RoadConfig, {"iso_class": "F"})
    with pytest.raises(ConfigError, match=r"anomalies\[0\]\.height_m"):
        from_mapping(RoadConfig, {"anomalies": [{"kind": "pothole", "height_m": 0.05}]})
    with pytest.raises(ConfigError, match=r"anomalies\[0\]\.ramp_deg"):
        from_mapping(RoadConfig, {"anomalies": [{"kind": "bump", "height_m": 0.1,
                                                 "length_m": 0.5, "ramp_deg": 5.0}]})
    with pytest.raises(ConfigError, match=r"anomaly_mix\.crater"):
        from_mapping(RoadConfig, {"anomaly_mix": {"crater": 1.0}})
    with pytest.raises(ConfigError, match=r"road\.length_m"):
        generate_road(RoadConfig(length_m=-5.0), np.random.default_rng(0))
