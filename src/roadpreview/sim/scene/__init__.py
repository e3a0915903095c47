"""The simulator's static world: procedural textures and the roadside layout, made from a seed."""

from roadpreview.sim.scene.textures import SceneConfig, SceneLayout, generate_scene

__all__ = ["SceneConfig", "SceneLayout", "generate_scene"]
