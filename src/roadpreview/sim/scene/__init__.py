"""The simulator's static world: procedural textures and the roadside layout, made from a seed.

`generate_scene` (in `layout`) builds a `SceneLayout` once; `roadpreview.sim.render`
draws it every frame. Modules: `config` (SceneConfig), `mipmap` (Texture), `noise`
(procedural noise), `textures` (the world's textures), `vehicle_textures` (vehicle
faces), `layout` (where everything stands).
"""

from roadpreview.sim.scene.config import SceneConfig
from roadpreview.sim.scene.layout import (
    LAYER_FACADE,
    LAYER_FENCE,
    LAYER_ROADSIDE,
    GroundStrip,
    QuadSet,
    RoadHeight,
    SceneLayout,
    SkySpec,
    generate_scene,
)
from roadpreview.sim.scene.mipmap import Texture
from roadpreview.sim.scene.vehicle_textures import VehicleTextures, make_vehicle_textures

__all__ = [
    "LAYER_FACADE",
    "LAYER_FENCE",
    "LAYER_ROADSIDE",
    "GroundStrip",
    "QuadSet",
    "RoadHeight",
    "SceneConfig",
    "SceneLayout",
    "SkySpec",
    "Texture",
    "VehicleTextures",
    "generate_scene",
    "make_vehicle_textures",
]
