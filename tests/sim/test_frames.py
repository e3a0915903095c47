"""The body-to-world rotation against independently written rotations and its sign convention."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.sim.frames import body_to_world
from roadpreview.sim.imu import rotation_body_to_world


def _reference(pitch: float, roll: float, yaw: float) -> np.ndarray:
    """Rz(yaw) Ry(-pitch) Rx(roll) multiplied out by hand (docs/method.md conventions)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(-pitch), math.sin(-pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    rot: np.ndarray = rz @ ry @ rx
    return rot


@pytest.mark.parametrize(
    ("pitch", "roll", "yaw", "axis", "expected"),
    [
        # nose up: the forward axis climbs (+Z)
        (0.1, 0.0, 0.0, [1.0, 0.0, 0.0], [math.cos(0.1), 0.0, math.sin(0.1)]),
        # nose up: the up axis leans back (-X)
        (0.1, 0.0, 0.0, [0.0, 0.0, 1.0], [-math.sin(0.1), 0.0, math.cos(0.1)]),
        # left side up: the left axis climbs (+Z)
        (0.0, 0.2, 0.0, [0.0, 1.0, 0.0], [0.0, math.cos(0.2), math.sin(0.2)]),
        # turn left: the forward axis swings to +Y
        (0.0, 0.0, 0.3, [1.0, 0.0, 0.0], [math.cos(0.3), math.sin(0.3), 0.0]),
        (0.0, 0.0, math.pi / 2, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
    ],
)
def test_sign_convention(
    pitch: float, roll: float, yaw: float, axis: list[float], expected: list[float]
) -> None:
    np.testing.assert_allclose(
        body_to_world(pitch, roll, yaw) @ np.array(axis), expected, rtol=0, atol=1e-12
    )


def test_matches_hand_written_rotation_vectorised_over_time() -> None:
    rng = np.random.default_rng(7)
    pitch = rng.uniform(-0.4, 0.4, 50)
    roll = rng.uniform(-0.3, 0.3, 50)
    yaw = rng.uniform(-math.pi, math.pi, 50)
    got = body_to_world(pitch, roll, yaw)
    assert got.shape == (50, 3, 3)
    want = np.array([_reference(p, r, y) for p, r, y in zip(pitch, roll, yaw, strict=True)])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # the same convention as the IMU model's own copy
    np.testing.assert_allclose(
        got, rotation_body_to_world(np.column_stack([roll, pitch, yaw])), rtol=0, atol=1e-12
    )


def test_shapes_follow_the_angles() -> None:
    assert body_to_world(0.0, 0.0, 0.0).shape == (3, 3)
    np.testing.assert_array_equal(body_to_world(0.0, 0.0, 0.0), np.eye(3))
    assert body_to_world(np.zeros((4, 2)), 0.1, 0.0).shape == (4, 2, 3, 3)
