"""The calibration's pure estimators on synthetic data with known answers (fast)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from roadpreview.calib.forward import body_axes_in_camera, focus_of_expansion, forward_direction
from roadpreview.calib.motion import relative_motion, rotation_given_direction
from roadpreview.calib.rotation import rate_axis, rotation_from_rates
from roadpreview.calib.timing import estimate_time_offset
from roadpreview.camera import CameraModel
from roadpreview.canbus.mapping import load_mapping, packaged_mapping_path
from roadpreview.canbus.samples import ImuMeasurements, ImuMount
from roadpreview.errors import ConfigError
from roadpreview.sim.imu import ImuConfig, simulate_imu
from roadpreview.types import ImuSample

CAM = CameraModel.from_fov(640, 360, 54.0)
#: the issue's example: the chip yawed 90 deg and pitched 5 deg in its holder
MOUNT = Rotation.from_euler("ZYX", [90.0, 5.0, 0.0], degrees=True).as_matrix()


def _views(
    rng: np.random.Generator,
    q_rotvec: np.ndarray,
    direction: np.ndarray,
    noise_px: float,
    baseline_m: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of 300 static points 5-60 m ahead seen before and after the camera turned by
    ``q_rotvec`` (b's axes in a's frame) and moved ``baseline_m`` along ``direction``."""
    n = 300
    z = rng.uniform(5.0, 60.0, n)
    pts = np.column_stack(
        [rng.uniform(-0.5, 0.5, n) * z, rng.uniform(-0.25, 0.28, n) * z, z]
    )  # camera a's frame
    Q = Rotation.from_rotvec(q_rotvec).as_matrix()
    c_b = baseline_m * direction / np.linalg.norm(direction)
    pts_b = (pts - c_b) @ Q  # Qᵀ (p - c) per row
    a = CAM.project(pts) + noise_px * rng.standard_normal((n, 2))
    b = CAM.project(pts_b) + noise_px * rng.standard_normal((n, 2))
    return a, b


def test_rotation_with_known_direction_is_recovered_to_a_hundredth_of_a_degree() -> None:
    rng = np.random.default_rng(1)
    t = np.array([0.02, -0.035, 1.0])
    q = np.radians([0.3, -0.2, 0.15])
    a, b = _views(rng, q, t, noise_px=0.2)
    r = rotation_given_direction(a, b, CAM.K, t)
    assert r
    assert np.degrees(np.abs(r.rotvec - q)).max() < 0.01


def test_essential_matrix_gives_the_direction_of_travel_within_a_degree() -> None:
    rng = np.random.default_rng(2)
    t = np.array([0.02, -0.035, 1.0])
    # a key frame's pair: 3 m of travel (0.2 s at 54 km/h); one pair is only good to about
    # a degree (yaw trades against sideways motion): the calibration takes many
    a, b = _views(rng, np.radians([0.2, 0.1, 0.0]), t, noise_px=0.2, baseline_m=3.0)
    m = relative_motion(a, b, CAM.K)
    assert m
    assert m.parallax_px > 2.0
    assert math.degrees(math.acos(m.direction @ t / np.linalg.norm(t))) < 1.0
    # its yaw is off by a tenth of a degree or so, against 0.01 with the direction known
    assert np.degrees(np.abs(m.rotvec - np.radians([0.2, 0.1, 0.0]))).max() < 0.3


def test_forward_direction_is_the_robust_centre_with_its_standard_error() -> None:
    rng = np.random.default_rng(3)
    yaw, pitch = math.radians(1.0), math.radians(-2.0)
    ang = np.column_stack(
        [yaw + 0.01 * rng.standard_normal(200), pitch + 0.01 * rng.standard_normal(200)]
    )
    ang[:10] += 0.3  # gross outliers
    d = np.column_stack([np.tan(ang[:, 0]), np.tan(ang[:, 1]), np.ones(200)])
    f = forward_direction(d / np.linalg.norm(d, axis=1, keepdims=True))
    assert f
    assert f.n_rejected >= 10
    # the standard error is 0.01 / sqrt(190) rad; the estimate lies within 4 of them
    assert abs(f.yaw_rad - yaw) < 4 * f.yaw_std_rad
    assert abs(f.pitch_rad - pitch) < 4 * f.pitch_std_rad
    assert f.pitch_std_rad == pytest.approx(0.01 / math.sqrt(190), rel=0.25)
    _u, v = focus_of_expansion(f.t, CAM.K)
    assert v == pytest.approx(CAM.cy + CAM.fy * math.tan(f.pitch_rad), abs=1e-6)
    assert not forward_direction(d[:3])


def test_body_axes_of_a_level_camera_are_the_fixed_permutation() -> None:
    # body x forward = camera z, body y left = camera -x, body z up = camera -y
    expected = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    np.testing.assert_allclose(body_axes_in_camera([0.0, 0.0, 1.0]), expected, atol=1e-12)


def _rates(
    rng: np.random.Generator, t: np.ndarray, scales: tuple[float, float, float]
) -> np.ndarray:
    """Smooth random body rates (roll, pitch, yaw about the camera's x, y, z), rad/s."""
    out = []
    for s in scales:
        f = rng.uniform(0.5, 2.5, 6)
        ph = rng.uniform(0, 2 * np.pi, 6)
        out.append(s * np.sin(2 * np.pi * f[None, :] * t[:, None] + ph).sum(axis=1) / 2.5)
    return np.column_stack(out)


def test_time_offset_and_rotation_of_a_rotated_gyro_are_recovered() -> None:
    rng = np.random.default_rng(4)
    tau = 0.060
    t_fine = np.arange(0.0, 30.0, 1e-3)
    w_cam = _rates(rng, t_fine, (0.03, 0.01, 0.02))  # pitch (cam x), yaw (cam y), roll (cam z)
    R_cam_chip = body_axes_in_camera([0.0, 0.0, 1.0]) @ MOUNT
    # gyro at 104 Hz, interval means, in the chip's axes, stamps late by tau, biased, noisy
    tg = np.arange(0.05, 29.9, 1 / 104)
    G = np.cumsum(w_cam, axis=0) * 1e-3
    mean = (
        np.column_stack([np.interp(tg, t_fine, c) for c in G.T])
        - np.column_stack([np.interp(tg - 1 / 104, t_fine, c) for c in G.T])
    ) * 104
    gyro = mean @ R_cam_chip + 0.01 + 0.002 * rng.standard_normal(mean.shape)
    # camera rotations between 30 Hz frames, with 0.002 deg of noise (0.06 deg/s)
    tf = np.arange(0.5, 29.0, 1 / 30)
    Gf = np.column_stack([np.interp(tf, t_fine, c) for c in G.T])
    rot = np.diff(Gf, axis=0) + math.radians(0.002) * rng.standard_normal((tf.size - 1, 3))
    res = estimate_time_offset(tf[:-1], tf[1:], rot, tg + tau, gyro)
    assert res, res.reason
    assert abs(res.offset_s - tau) < 1e-3
    assert res.std_s < 2e-3
    assert res.r2 > 0.7
    v = rot / np.diff(tf)[:, None]
    from roadpreview.calib.timing import gyro_integral, mean_rates

    g = mean_rates(*gyro_integral(tg + tau, gyro), tf[:-1] + res.offset_s, tf[1:] + res.offset_s)
    rr = rotation_from_rates(v, g)
    assert rr, rr.reason
    err = math.degrees(Rotation.from_matrix(rr.R @ R_cam_chip.T).magnitude())
    assert err < 0.5, (err, rr.std_deg, rr.excitation_rad_s)
    assert err < 3 * rr.std_deg + 0.1  # the jackknife's error is honest
    # the camera's pitch rate (about its x) is the chip's -x: yawed 90 deg, the chip's x is left
    ax = rate_axis(v[:, 0], g)
    assert ax
    assert (ax.axis, ax.sign) == (0, -1)


def test_time_offset_beyond_the_search_range_is_refused() -> None:
    rng = np.random.default_rng(5)
    t_fine = np.arange(0.0, 20.0, 1e-3)
    w = _rates(rng, t_fine, (0.03, 0.01, 0.01))
    G = np.cumsum(w, axis=0) * 1e-3
    tf = np.arange(1.0, 18.0, 1 / 30)
    Gf = np.column_stack([np.interp(tf, t_fine, c) for c in G.T])
    res = estimate_time_offset(
        tf[:-1], tf[1:], np.diff(Gf, axis=0), t_fine + 0.5, w, max_offset_s=0.2, min_offset_s=-0.2
    )
    assert not res
    assert "edge" in res.reason


def test_rotation_needs_two_excited_axes() -> None:
    rng = np.random.default_rng(6)
    v = np.zeros((600, 3))
    v[:, 0] = 0.05 * rng.standard_normal(600)  # pitch only
    g = v @ MOUNT + 1e-4 * rng.standard_normal((600, 3))
    rr = rotation_from_rates(v, g)
    assert not rr
    assert "one axis" in rr.reason


def test_axis_choice_is_not_fooled_by_a_tilted_axis_that_only_sees_the_pitch() -> None:
    rng = np.random.default_rng(7)
    body = np.zeros((800, 3))
    body[:, 1] = 0.05 * rng.standard_normal(800)  # ISO pitch rate (about y, left)
    chip = body @ MOUNT + 1e-3 * rng.standard_normal((800, 3))
    ax = rate_axis(-body[:, 1], chip)  # roadpreview's pitch rate, nose up
    # the chip's z is tilted 5 deg towards the body's y: it correlates almost as well
    assert abs(ax.correlations[2]) > 0.9
    assert ax
    assert (ax.axis, ax.sign) == (0, -1)


def test_mount_undoes_the_simulated_rotation_and_clock_offset() -> None:
    t = np.arange(0.0, 2.0, 1e-3)
    omega = np.column_stack([0.1 * np.sin(3 * t), 0.2 * np.sin(5 * t), 0.05 * np.cos(2 * t)])
    cfg = ImuConfig.ideal()
    mounted = ImuConfig(
        **{**cfg.__dict__, "mount_ypr_deg": (90.0, 5.0, 0.0), "time_offset_s": 0.06}
    )
    att = np.zeros((t.size, 3))
    acc = np.zeros((t.size, 3))
    ref = simulate_imu(t, omega, acc, att, cfg, np.random.default_rng(0))
    chip = simulate_imu(t, omega, acc, att, mounted, np.random.default_rng(0))
    np.testing.assert_allclose(chip.gyro_rad_s, ref.gyro_rad_s @ MOUNT, atol=1e-12)
    back = ImuMount(MOUNT, 0.06).apply(chip.measurements())
    np.testing.assert_allclose(back.gyro_rad_s, ref.gyro_rad_s, atol=1e-12)
    np.testing.assert_allclose(back.accel_m_s2, ref.accel_m_s2, atol=1e-9)
    np.testing.assert_allclose(back.t_s, ref.t_stamp_s, atol=1e-12)


def test_mount_of_one_sample_keeps_what_the_message_lacks_missing() -> None:
    mount = ImuMount(MOUNT, 0.06)
    w_chip = np.array([0.1, 0.2, 0.3])
    s = ImuSample(10.0, tuple(w_chip * [1, -1, 1]), (math.nan, math.nan, math.nan), "IMU_RATES")
    out = mount.apply_sample(s)
    body = MOUNT @ w_chip
    assert out.t_s == pytest.approx(9.94)
    np.testing.assert_allclose(out.rates_rad_s, body * [1, -1, 1], atol=1e-12)
    assert all(math.isnan(a) for a in out.accel_m_s2)
    meas = ImuMeasurements(np.array([0.0]), np.array([[0.0, 0.0, 0.0]]), np.zeros((1, 3)))
    assert mount.apply(meas).t_s[0] == pytest.approx(-0.06)


def test_mapping_mount_table_is_read_and_checked(tmp_path: Path) -> None:
    text = packaged_mapping_path("roadpreview").read_text()
    good = tmp_path / "mapping.toml"
    good.write_text(
        text + "\n[mount]\nrotation = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]\ntime_offset_s = 0.05\n"
    )
    m = load_mapping(good)
    assert m.mount is not None
    assert m.mount.time_offset_s == 0.05
    bad = tmp_path / "bad.toml"
    bad.write_text(text + "\n[mount]\nrotation = [[1, 1, 0], [0, 1, 0], [0, 0, 1]]\n")
    with pytest.raises(ConfigError, match=r"bad\.toml: mount\.rotation"):
        load_mapping(bad)
    typo = tmp_path / "typo.toml"
    typo.write_text(text + "\n[mount]\ntime_offset = 0.05\n")
    with pytest.raises(ConfigError, match=r"typo\.toml: unknown key mount\.time_offset"):
        load_mapping(typo)
