"""The simulator's camera: draws a `SceneLayout` and vehicles with OpenCV, then degrades it.

`SceneRenderer` (in `renderer`) composes the stages: `geometry` (frames, mount,
clipping, vehicle boxes), `quads` (what one frame draws), `raster` (painting it),
`atmosphere` (fog and light) and `sensor` (optics, exposure, noise); `config` holds
`RenderConfig`.
"""

from roadpreview.sim.render.config import RenderConfig
from roadpreview.sim.render.geometry import rear_face_center_body
from roadpreview.sim.render.renderer import RenderedFrame, SceneRenderer

__all__ = ["RenderConfig", "RenderedFrame", "SceneRenderer", "rear_face_center_body"]
