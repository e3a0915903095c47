"""CameraModel: intrinsics, validation, TOML round trip, projection geometry."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.errors import ConfigError, RoadPreviewError


def test_focal_length_from_vertical_field_of_view() -> None:
    cam = CameraModel.from_fov(1920, 1080, 54.0)
    assert cam.fy == pytest.approx(540.0 / math.tan(math.radians(27.0)))
    assert cam.fy == pytest.approx(1060.0, abs=0.5)  # the paper rounds to 1066 px
    assert cam.fx == cam.fy
    assert (cam.cx, cam.cy) == (959.5, 539.5)


def test_projection_of_a_vertical_displacement_is_f_delta_over_d() -> None:
    cam = CameraModel.from_fov(1280, 720, 50.0)
    for d, delta in ((10.0, 0.05), (25.0, 0.06), (5.0, 0.03)):
        p = cam.project(np.array([[0.3, 0.2, d], [0.3, 0.2 - delta, d]]))
        assert p[0, 1] - p[1, 1] == pytest.approx(cam.f * delta / d, rel=1e-12)
    assert np.isnan(cam.project(np.array([[0.0, 0.0, -1.0]]))).all()


def test_rays_invert_projection() -> None:
    cam = CameraModel.from_fov(640, 360, 60.0)
    pts = np.array([[1.0, -0.5, 7.0], [-3.0, 1.2, 40.0]])
    rays = cam.rays(cam.project(pts))
    np.testing.assert_allclose(rays * pts[:, 2:3], pts, atol=1e-12)


def test_toml_round_trip(tmp_path: Path) -> None:
    cam = CameraModel(
        width=1242,
        height=375,
        fx=721.5,
        fy=721.5,
        cx=609.6,
        cy=172.9,
        forward=(0.0, 0.6, 0.8),
        mount_height_m=1.65,
    )
    path = tmp_path / "camera.toml"
    cam.save(path)
    assert CameraModel.load(path) == cam
    assert "[camera]" in path.read_text()


def test_scaled_camera_keeps_angles() -> None:
    cam = CameraModel.from_fov(1920, 1080, 54.0)
    small = cam.scaled(640, 360)
    assert small.fy == pytest.approx(cam.fy / 3)
    # the same ray lands on the corresponding pixel of the smaller image
    p_big = cam.project(np.array([[1.0, 0.5, 10.0]]))[0]
    p_small = small.project(np.array([[1.0, 0.5, 10.0]]))[0]
    np.testing.assert_allclose((p_small + 0.5) * 3.0 - 0.5, p_big, atol=1e-9)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"fx": -5.0}, "fx"),
        ({"fy": 0.0}, "fy"),
        ({"cx": 2000.0}, "cx"),
        ({"cy": -1.0}, "cy"),
        ({"forward": (0.0, 0.0, 2.0)}, "forward"),
        ({"forward": (0.0, 0.0, -1.0)}, "forward"),
        ({"mount_height_m": 0.0}, "mount_height_m"),
        ({"width": 0}, "width"),
    ],
)
def test_invalid_calibration_names_the_field(change: dict[str, object], field: str) -> None:
    base: dict[str, object] = {
        "width": 640,
        "height": 360,
        "fx": 500.0,
        "fy": 500.0,
        "cx": 320.0,
        "cy": 180.0,
    }
    base.update(change)
    with pytest.raises(ConfigError, match=field):
        CameraModel(**base)  # type: ignore[arg-type]


def test_bad_files_name_the_file_and_field(tmp_path: Path) -> None:
    missing = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match=r"nope\.toml"):
        CameraModel.load(missing)
    garbled = tmp_path / "garbled.toml"
    garbled.write_text("[camera\nwidth = 3")
    with pytest.raises(ConfigError, match=r"garbled\.toml"):
        CameraModel.load(garbled)
    unknown = tmp_path / "unknown.toml"
    unknown.write_text(
        "[camera]\nwidth=640\nheight=360\nfx=500.0\nfy=500.0\ncx=320.0\ncy=180.0\nfocal=3\n"
    )
    with pytest.raises(ConfigError, match="focal"):
        CameraModel.load(unknown)
    incomplete = tmp_path / "incomplete.toml"
    incomplete.write_text("[camera]\nwidth=640\nheight=360\nfx=500.0\n")
    with pytest.raises(ConfigError, match=r"incomplete.toml.*fy"):
        CameraModel.load(incomplete)
    assert issubclass(ConfigError, RoadPreviewError)
