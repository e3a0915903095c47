"""The vision front end: find and track the lead vehicle, and give the pitch estimator
clean background correspondences.

Lead finders are chosen by name from `FINDERS` (imported lazily)::

    finder = make_finder("motion", camera)             # built in, no model
    finder = make_finder("onnx", camera, model_path="yolov8n.onnx")
    finder = make_finder("box", camera, box=(500, 300, 700, 450))

`VisionFrontEnd` combines a finder, the `LeadVehicleTracker` and the
`BackgroundTracker`; ``process(t, frame)`` returns a `FrameVision` per frame.
"""

from __future__ import annotations

import importlib
from typing import Any

from roadpreview.camera import CameraModel
from roadpreview.errors import ConfigError
from roadpreview.registry import build
from roadpreview.vision.base import Detection, FrameContext, LeadFinder

#: config name -> (module, class, config class); the config's and the CLI's choices
FINDERS: dict[str, tuple[str, str, str]] = {
    "motion": ("roadpreview.vision.motion", "MotionLeadFinder", "MotionFinderConfig"),
    "onnx": ("roadpreview.vision.onnx", "OnnxLeadFinder", "OnnxFinderConfig"),
    "box": ("roadpreview.vision.box", "BoxLeadFinder", "BoxFinderConfig"),
}


def make_finder(name: str, camera: CameraModel, **options: Any) -> LeadFinder:
    """Build the lead finder registered as ``name``; ``options`` fill its config dataclass."""
    finder: LeadFinder = build(
        FINDERS, name, camera, key="vision.finder", where=f"vision.{name}", options=options
    )
    return finder


def finder_class(name: str) -> type:
    """The class registered as ``name`` (its module imported now), to read the class-level
    traits the front end needs before building the finder (see `LeadFinder`)."""
    try:
        module_name, cls_name, _ = FINDERS[name]
    except KeyError:
        raise ConfigError(
            f"vision.finder = {name!r}: unknown; choose one of {sorted(FINDERS)}"
        ) from None
    cls: type = getattr(importlib.import_module(module_name), cls_name)
    return cls


def __getattr__(name: str) -> Any:
    """Lazy access to the front end's classes (keeps ``import roadpreview.vision`` light)."""
    lazy = {
        "VisionFrontEnd": "roadpreview.vision.frontend",
        "VisionConfig": "roadpreview.vision.frontend",
        "FrameVision": "roadpreview.vision.frontend",
        "LeadVehicleTracker": "roadpreview.vision.tracker",
        "LeadObservation": "roadpreview.vision.tracker",
        "BackgroundTracker": "roadpreview.vision.background",
        "BackgroundCorrespondences": "roadpreview.vision.background",
    }
    if name in lazy:
        return getattr(importlib.import_module(lazy[name]), name)
    raise AttributeError(f"module 'roadpreview.vision' has no attribute {name!r}")


__all__ = [
    "FINDERS",
    "BackgroundCorrespondences",
    "BackgroundTracker",
    "Detection",
    "FrameContext",
    "FrameVision",
    "LeadFinder",
    "LeadObservation",
    "LeadVehicleTracker",
    "VisionConfig",
    "VisionFrontEnd",
    "finder_class",
    "make_finder",
]
