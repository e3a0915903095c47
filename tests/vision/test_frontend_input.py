"""Bad input to the front end and the finder registry: values with reasons, not exceptions."""

from __future__ import annotations

import builtins
import math
from dataclasses import fields
from typing import Any

import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.errors import ConfigError, MissingDependencyError
from roadpreview.vision import FINDERS, make_finder
from roadpreview.vision.base import Detection
from roadpreview.vision.frontend import VisionConfig, VisionFrontEnd
from roadpreview.vision.motion import MotionLeadFinder
from roadpreview.vision.tracker import LeadTrackerConfig, LeadVehicleTracker, choose_target

CAM = CameraModel.from_fov(320, 180, 54.0)


def _textured(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 255, (180, 320, 3)).astype(np.uint8)
    return img


@pytest.mark.parametrize(
    ("frame", "why"),
    [
        (None, "no frame"),
        ("not an image", "not an image array"),
        (np.zeros((180, 320, 3), np.float32), "dtype float32"),
        (np.zeros((180, 320, 4), np.uint8), "expected (H, W, 3)"),
        (np.zeros((100, 100, 3), np.uint8), "the camera is 320x180"),
        (np.zeros((180, 320, 3), np.uint8), "blank frame"),
        (np.full((180, 320, 3), 200, np.uint8), "blank frame"),
    ],
)
def test_bad_frame_gives_no_target_with_reason(frame: Any, why: str) -> None:
    fe = VisionFrontEnd(
        CAM, VisionConfig(finder="box", finder_options={"box": (100, 80, 200, 150)})
    )
    out = fe.process(0.0, frame)
    assert not out
    assert not out.lead
    assert not out.background
    assert why in out.lead.reason
    assert why in out.background.reason
    assert math.isnan(out.lead.y)
    assert out.background.x_key.shape == (0, 2)


def test_tracking_resumes_after_a_black_frame() -> None:
    img = _textured()
    fe = VisionFrontEnd(
        CAM, VisionConfig(finder="box", finder_options={"box": (100, 80, 200, 150)})
    )
    first = fe.process(0.0, img)
    assert first.lead
    assert first.lead.target_changed
    assert not fe.process(1 / 30, np.zeros_like(img)).lead
    again = fe.process(2 / 30, img)
    assert again.lead
    assert not again.lead.target_changed
    assert again.lead.y == pytest.approx(first.lead.y, abs=0.05)  # a static scene: y stays


def test_registry_names_and_errors() -> None:
    assert set(FINDERS) == {"onnx", "motion", "box"}
    with pytest.raises(ConfigError, match=r"unknown; choose one of"):
        make_finder("yolo", CAM)
    with pytest.raises(ConfigError, match=r"unknown key vision\.box\.colour"):
        make_finder("box", CAM, box=(1, 1, 10, 10), colour="red")
    with pytest.raises(ConfigError, match="model_path"):
        make_finder("onnx", CAM)


def test_missing_onnxruntime_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def fake_import(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "onnxruntime":
            raise ImportError("No module named 'onnxruntime'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(MissingDependencyError, match="pip install onnxruntime"):
        make_finder("onnx", CAM, model_path="model.onnx")


def test_target_is_the_vehicle_nearest_the_centre() -> None:
    cam = CameraModel(width=1242, height=375, fx=721.5, fy=721.5, cx=609.6, cy=172.9)
    dets = [
        Detection((62, 180, 415, 370), 0.9, "car"),  # adjacent lane, left
        Detection((590, 170, 640, 205), 0.8, "car"),  # far, in our lane, spans the centre
        Detection((555, 190, 700, 315), 0.85, "car"),  # the lead: spans the centre, nearest
        Detection((790, 40, 1140, 370), 0.9, "truck"),  # right
        Detection((600, 20, 620, 40), 0.9, "car"),  # above the horizon: ignored
    ]
    assert choose_target(dets, cam, horizon_v=172.9) == 2
    assert choose_target(dets[:2] + dets[3:], cam, horizon_v=172.9) == 1


def test_target_nearer_than_the_minimum_distance_is_not_taken() -> None:
    # 720p, f = 706.5 px, camera 1.3 m above the road: the flat road at distance d lies
    # f h / d = 918.5 / d px below the horizon
    cam = CameraModel(
        width=1280, height=720, fx=706.5, fy=706.5, cx=639.5, cy=359.5, mount_height_m=1.3
    )
    horizon = 359.5
    lead = Detection((610, 330, 670, 359.5 + 918.5 / 18.0), 0.9, "vehicle")  # at 18 m
    road = Detection((350, 240, 1040, 719), 0.3, "obstacle")  # the road below it, 2.5 m
    at_5m = Detection((450, 200, 830, 359.5 + 918.5 / 5.0), 0.3, "vehicle")
    # without the gate the centre rule takes the nearest box, the road
    assert choose_target([lead, road], cam, horizon_v=horizon) == 1
    assert choose_target([lead, road], cam, horizon_v=horizon, min_distance_m=4.0) == 0
    assert choose_target([road], cam, horizon_v=horizon, min_distance_m=4.0) is None
    # the gate is the flat-road row of min_distance_m: 5 m passes a 4 m gate, not a 6 m one
    assert choose_target([lead, at_5m], cam, horizon_v=horizon, min_distance_m=4.0) == 1
    assert choose_target([lead, at_5m], cam, horizon_v=horizon, min_distance_m=6.0) == 0
    # the gate follows the horizon: 20 px lower, the 5 m bottom reads 5.6 m, past a 5.5 m gate
    assert choose_target([at_5m], cam, horizon_v=horizon, min_distance_m=5.5) is None
    assert choose_target([at_5m], cam, horizon_v=horizon + 20, min_distance_m=5.5) == 0


def test_distance_cues_and_their_fusion() -> None:
    cam = CameraModel(
        width=1280, height=720, fx=700.0, fy=700.0, cx=639.5, cy=359.5, mount_height_m=1.3
    )
    tr = LeadVehicleTracker(cam)
    cfg = tr.config
    d = 10.0
    w = 700.0 * cfg.vehicle_width_m / (d + cfg.width_section_ahead_m)
    bottom = 359.5 + 700.0 * 1.3 / (d + cfg.rear_overhang_m)
    box = (639.5 - w / 2, bottom - 100, 639.5 + w / 2, bottom)
    fused, std, dw, dg = tr.distance(box, 2.0)
    assert dw == pytest.approx(d, rel=1e-9)
    assert dg == pytest.approx(d, rel=1e-9)
    assert fused == pytest.approx(d, rel=1e-9)
    assert 0.0 < std < 0.6
    # a box cut by the image bottom has no ground cue; cut at the side, no width cue
    _, _, _, dg2 = tr.distance((box[0], box[1], box[2], 719.5), 2.0)
    assert math.isnan(dg2)
    _, _, dw3, _ = tr.distance((0.0, box[1], box[2], box[3]), 2.0)
    assert math.isnan(dw3)


def test_the_config_accepts_every_registered_finder_and_only_those() -> None:
    choices = {f.name: f for f in fields(VisionConfig)}["finder"].metadata["choices"]
    assert choices == tuple(FINDERS)
    with pytest.raises(ConfigError, match="must be one of"):
        VisionConfig(finder="yolo").validate()


def test_the_front_end_adapts_to_what_the_finder_class_declares() -> None:
    motion = VisionFrontEnd(CAM, VisionConfig(finder="motion", small_width_px=200))
    assert isinstance(motion.finder, MotionLeadFinder)
    assert motion.finder.config.small_width_px == 200
    assert motion.tracker.config.min_distance_m == LeadTrackerConfig().min_distance_m
    box = VisionFrontEnd(
        CAM, VisionConfig(finder="box", finder_options={"box": (100, 80, 200, 150)})
    )
    assert box.tracker.config.min_distance_m == 0.0  # the user's box, however near
