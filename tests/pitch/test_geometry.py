"""The epipolar model F(φ) = -K^-T [t]x R(φ) K^-1, the Sampson error and its derivative."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roadpreview.camera import CameraModel
from roadpreview.pitch.geometry import (
    PitchOnlySampson,
    fundamental,
    normalise,
    rot_pitch,
    rot_roll,
    rot_yaw,
    rotation,
    sampson_distance,
    sampson_distance_and_jacobian,
    sampson_error,
    sampson_error_derivative,
)
from roadpreview.pitch.synthetic import make_two_view_scene

CAM = CameraModel.from_fov(1920, 1080, 54.0)
TILTED = CameraModel.from_fov(
    1280, 720, 50.0, forward=(0.02, -0.03, math.sqrt(1.0 - 0.02**2 - 0.03**2))
)


def test_pitch_rotation_sign_nose_up_moves_content_down() -> None:
    phi = math.radians(1.5)
    d = rot_pitch(phi) @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(d, [0.0, math.sin(phi), math.cos(phi)], atol=1e-15)
    # a far point straight ahead moves down (larger v) by f tan(phi)
    v = CAM.project(d[None, :])[0, 1]
    assert v - CAM.cy == pytest.approx(CAM.fy * math.tan(phi), abs=1e-9)


def test_yaw_and_roll_sign_conventions() -> None:
    # turning left: content moves right
    assert (rot_yaw(0.01) @ [0.0, 0.0, 1.0])[0] > 0.0
    # rolling left side up: a point right of centre moves up (y decreases)
    assert (rot_roll(0.01) @ [1.0, 0.0, 5.0])[1] < 0.0
    for R in (rotation([0.1, -0.2, 0.05]), rot_yaw(0.3), rot_roll(-0.2)):
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("camera", [CAM, TILTED])
def test_true_pitch_satisfies_epipolar_constraint(camera: CameraModel) -> None:
    rng = np.random.default_rng(3)
    sc = make_two_view_scene(
        camera, 300, rng, phi=math.radians(1.2), forward_m=0.8, noise_px=0.0, outlier_ratio=0.0
    )
    F = fundamental([sc.phi], camera.K, camera.t)
    assert np.linalg.matrix_rank(F, tol=1e-10 * np.abs(F).max()) == 2
    h1 = np.column_stack([sc.x_ref, np.ones(len(sc.x_ref))])
    h2 = np.column_stack([sc.x_cur, np.ones(len(sc.x_cur))])
    algebraic = np.einsum("ij,jk,ik->i", h2, F, h1)
    assert np.abs(algebraic).max() < 1e-9
    assert sampson_error([sc.phi], sc.x_ref, sc.x_cur, camera.K, camera.t).max() < 1e-12
    # a wrong pitch gives an error of the order of (f * dphi)^2
    wrong = sampson_error([sc.phi + math.radians(0.1)], sc.x_ref, sc.x_cur, camera.K, camera.t)
    assert np.median(wrong) > 0.05


@settings(max_examples=40, deadline=None)
@given(
    phi=st.floats(-0.05, 0.05),
    yaw=st.floats(-0.05, 0.05),
    roll=st.floats(-0.05, 0.05),
    seed=st.integers(0, 10_000),
)
def test_analytic_jacobian_matches_finite_differences(
    phi: float, yaw: float, roll: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    sc = make_two_view_scene(TILTED, 60, rng, phi=0.01, yaw=0.005, outlier_ratio=0.3)
    theta = np.array([phi, yaw, roll])
    e, de = sampson_error_derivative(theta, sc.x_ref, sc.x_cur, TILTED.K, TILTED.t)
    h = 1e-6
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        fd = (
            sampson_error(theta + step, sc.x_ref, sc.x_cur, TILTED.K, TILTED.t)
            - sampson_error(theta - step, sc.x_ref, sc.x_cur, TILTED.K, TILTED.t)
        ) / (2 * h)
        # central differences: relative accuracy about 1e-6 of the derivative's scale
        np.testing.assert_allclose(de[:, k], fd, rtol=1e-4, atol=1e-6 * np.abs(fd).max() + 1e-9)
    np.testing.assert_allclose(
        e, sampson_error(theta, sc.x_ref, sc.x_cur, TILTED.K, TILTED.t), rtol=1e-9, atol=1e-12
    )


def test_fast_pitch_path_equals_general_model() -> None:
    rng = np.random.default_rng(7)
    sc = make_two_view_scene(TILTED, 500, rng, phi=0.02, outlier_ratio=0.3)
    n1, n2 = normalise(sc.x_ref, TILTED.K), normalise(sc.x_cur, TILTED.K)
    fast = PitchOnlySampson(n1, n2, TILTED.t, TILTED.fx, TILTED.fy)
    for phi in (-0.1, 0.0, 0.013, 0.3):
        g, J = sampson_distance_and_jacobian([phi], n1, n2, TILTED.t, TILTED.fx, TILTED.fy)
        g_fast, dg_fast = fast(phi)
        np.testing.assert_allclose(g_fast, g, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(dg_fast, J[:, 0], rtol=1e-9, atol=1e-8)
        np.testing.assert_allclose(fast.distance(phi), g, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(
            g, sampson_distance([phi], sc.x_ref, sc.x_cur, TILTED.K, TILTED.t), rtol=1e-10
        )
