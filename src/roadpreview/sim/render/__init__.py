"""The simulator's camera: draws a `SceneLayout` and vehicles with OpenCV, then degrades it."""

from roadpreview.sim.render.renderer import (
    RenderConfig,
    RenderedFrame,
    SceneRenderer,
    rear_face_center_body,
)

__all__ = ["RenderConfig", "RenderedFrame", "SceneRenderer", "rear_face_center_body"]
