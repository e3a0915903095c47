"""Paper eq. (4): y_c = y - f tan(phi), vectorised, with the sign conventions of method.md."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.compensation import compensation
from roadpreview.errors import InputDataError


def test_a_pitching_camera_is_compensated_exactly() -> None:
    """A static point straight ahead at v = c_y + f tan(phi) in a camera pitched nose up by
    phi (method.md) is put back at c_y."""
    cam = CameraModel.from_fov(1280, 720, 54.0)
    phi = np.radians(np.linspace(-3.0, 3.0, 61))
    f = float(cam.K[1, 1])
    cy = float(cam.K[1, 2])
    # project the forward direction through the pitched camera: R(phi) @ (0, 0, 1)
    d = np.stack([np.zeros_like(phi), np.sin(phi), np.cos(phi)])
    v = cy + f * d[1] / d[2]
    assert np.allclose(compensation(v, phi, f), cy, atol=1e-9)


def test_vectorised_and_broadcast() -> None:
    y = np.array([[100.0, 200.0], [300.0, 400.0]])
    out = compensation(y, np.radians(1.0), 1000.0)
    assert out.shape == (2, 2)
    assert np.allclose(out, y - 1000.0 * math.tan(math.radians(1.0)))
    assert compensation(100.0, 0.0, 900.0) == pytest.approx(100.0)


def test_missing_values_stay_missing() -> None:
    out = compensation([1.0, np.nan, 3.0], [0.0, 0.0, np.nan], 800.0)
    assert out[0] == 1.0
    assert np.isnan(out[1])
    assert np.isnan(out[2])


@pytest.mark.parametrize("f", [0.0, -5.0, math.nan, math.inf])
def test_bad_focal_length(f: float) -> None:
    with pytest.raises(InputDataError, match="focal length"):
        compensation(1.0, 0.0, f)


def test_a_pitch_of_ninety_degrees_is_refused() -> None:
    with pytest.raises(InputDataError, match="pi/2"):
        compensation([1.0, 2.0], [0.0, math.pi / 2], 800.0)
