"""The simulator's camera: draws a `SceneLayout` and vehicles with OpenCV, then degrades it.

`SceneRenderer.render` returns a `RenderedFrame`: a BGR image with real texture
(textured planes warped by homographies, painter's algorithm far to near), the
vehicle-id mask and the lead vehicle's ground truth, after fog (Koschmieder),
night / tunnel lighting with lamp glow, motion blur, lens blur, exposure, gamma
and sensor noise. It composes the package's stages: `quads` (what to draw),
`raster` (painting), `atmosphere` (fog and light) and `sensor` (optics and noise).
Conventions are those of ``docs/method.md``; the design is in
``docs/simulator-rendering.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.errors import InputDataError
from roadpreview.sim.render import sensor
from roadpreview.sim.render.atmosphere import Atmosphere, exposure_gain, headlight_beam
from roadpreview.sim.render.config import RenderConfig
from roadpreview.sim.render.geometry import (
    box_corners,
    clip_near,
    mount_rotation,
    rear_face_center_body,
    vehicle_points_world,
    world_to_camera,
)
from roadpreview.sim.render.quads import DrawListBuilder, DrawQuads
from roadpreview.sim.render.raster import Canvas, Rasterizer
from roadpreview.sim.scene import SceneLayout, Texture
from roadpreview.sim.types import CameraPose, Conditions, VehiclePose

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

#: the lead's box faces as corner indices (corner index = 4 ix + 2 iy + iz, `box_corners`)
_BOX_FACES = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))


@dataclass(frozen=True)
class RenderedFrame:
    """One camera image with its ground truth.

    ``vehicle_mask`` holds the ``vehicle_id`` of the vehicle seen at each pixel
    (0 = background, parked cars included). ``lead_box`` is the (x0, y0, x1, y1)
    pixel bounding box of the lead's box from the road (tyres) to the roof
    (near-clipped, clipped to the image),
    ``lead_rear_center_px`` the (u, v) projection of the centre of its rear face;
    both None without a lead in front of the camera.
    """

    image: U8
    vehicle_mask: NDArray[np.int16]
    lead_box: tuple[float, float, float, float] | None
    lead_rear_center_px: tuple[float, float] | None


class SceneRenderer:
    """Renders a `SceneLayout` seen by `camera` with vehicles, weather and sensor effects.

    Parameters
    ----------
    camera
        Intrinsics and size of the output images; its ``forward`` direction is the
        body's forward axis in camera coordinates (the camera is mounted so).
    scene
        The static world from `roadpreview.sim.scene.generate_scene`.
    cfg
        Optics, sensor and drawing limits.
    """

    def __init__(
        self, camera: CameraModel, scene: SceneLayout, cfg: RenderConfig | None = None
    ) -> None:
        self.camera = camera
        self.scene = scene
        self.cfg = cfg or RenderConfig()
        self.cfg.validate()
        self.W, self.H = camera.width, camera.height
        self._mount = mount_rotation(camera.t)
        self._draw = DrawListBuilder(scene, self.cfg.near_m, camera.fy)
        self._raster = Rasterizer(camera, self.cfg)
        # ray lengths (for per-pixel depth) and the headlight beam
        xn = (self._raster.U - camera.cx) / camera.fx
        yn = (self._raster.V - camera.cy) / camera.fy
        ray_len = np.sqrt(1.0 + xn * xn + yn * yn).astype(np.float32)
        beam = headlight_beam(self.cfg, self._mount, xn, yn, ray_len)
        self._atmosphere = Atmosphere(self.cfg, ray_len, beam)
        self._noise = sensor.SensorNoise(self.cfg, self.W, self.H)

    def world_to_camera(self, cam: CameraPose) -> tuple[F64, F64]:
        """(R, C) with p_cam = R @ (p_world - C) for the camera pose ``cam``."""
        return world_to_camera(self._mount, cam)

    def render(
        self,
        cam: CameraPose,
        vehicles: Sequence[VehiclePose],
        conditions: Conditions,
        rng: np.random.Generator,
        *,
        pitch_rate_rad_s: float = 0.0,
    ) -> RenderedFrame:
        """Draw one frame.

        ``pitch_rate_rad_s`` (nose-up rate of the camera) only sets the vertical
        motion blur. ``rng`` draws the sensor noise (the scene itself is fixed by
        the layout's seed and the vehicles' appearance seeds).
        """
        cfg = self.cfg
        vals = (cam.x_m, cam.y_m, cam.z_m, cam.pitch_rad, cam.roll_rad, cam.yaw_rad)
        if not all(math.isfinite(v) for v in vals):
            raise InputDataError(f"render: camera pose has non-finite values {cam}")
        k_fog = max(0.0, float(conditions.fog_density_per_m))
        tunnel = bool(conditions.tunnel)
        ambient = float(np.clip(conditions.light, 0.0, 1.0))
        if tunnel:
            ambient = min(ambient, cfg.tunnel_light)
        lights_on = ambient < cfg.headlights_below_light or tunnel
        # beyond 6.5 / k the fog transmits < 0.15 %: nothing there is visible
        dmax = cfg.max_distance_m if k_fog <= 0 else min(cfg.max_distance_m, 6.5 / k_fog)
        R, C = self.world_to_camera(cam)
        zr = self.scene.height(cam.x_m, cam.y_m)
        cv = Canvas(self.W, self.H, need_depth=k_fog > 0 or lights_on, need_emission=lights_on)

        bg = self.scene.tunnel_bgr if tunnel else self.scene.far_ground_bgr
        cv2.rectangle(cv.img, (0, 0), (self.W - 1, self.H - 1), bg, -1)  # 20x faster than numpy
        if not tunnel:
            sky = self.scene.sky
            self._raster.draw_sky(cv, R, sky, self.scene.textures[sky.tex_id])
        draw = self._draw
        textures: list[Texture] = list(draw.textures)
        parts: list[DrawQuads] = []
        strips = draw.strips(cam, R, C, zr, dmax, tunnel)
        if strips is not None:
            parts.append(strips)
        if not tunnel:
            st = draw.roadside(cam, R, C, dmax)
            if st is not None:
                parts.append(st)
        lead_pose: VehiclePose | None = None
        item = draw.static.n_groups + 1
        for pose in vehicles:  # a few vehicles, each vectorised over its quads
            if pose.is_lead and lead_pose is None:
                lead_pose = pose
            parts += draw.vehicle(
                pose,
                R,
                C,
                vid=int(pose.vehicle_id),
                night=lights_on,
                item=item,
                textures=textures,
            )
            item += 1
        allq = DrawQuads.concat(parts)
        order = np.lexsort((np.arange(allq.key.shape[0]), allq.item, -allq.key, allq.layer))
        self._raster.paint_all(cv, allq.take(order), textures)

        lead_box, lead_c = self._lead_truth(lead_pose, R, C)
        image = self._develop(cv, k_fog, ambient, lights_on, pitch_rate_rad_s, rng)
        return RenderedFrame(
            image=image, vehicle_mask=cv.vmask, lead_box=lead_box, lead_rear_center_px=lead_c
        )

    def _lead_truth(
        self, pose: VehiclePose | None, R: F64, C: F64
    ) -> tuple[tuple[float, float, float, float] | None, tuple[float, float] | None]:
        """The lead's pixel box (road to roof, near-clipped) and its rear face's centre."""
        if pose is None:
            return None, None
        near = self.cfg.near_m
        centre = vehicle_points_world(pose, rear_face_center_body(pose.shape))
        pc = (centre - C) @ R.T
        lead_c: tuple[float, float] | None = None
        if pc[0, 2] > near:
            uv = self.camera.project(pc)[0]
            lead_c = (float(uv[0]), float(uv[1]))
        corners = (vehicle_points_world(pose, box_corners(pose.shape)) - C) @ R.T
        if corners[:, 2].min() >= near:
            uv = self.camera.project(corners)
        else:  # each face of the box clipped to the near plane
            pts = [clip_near(corners[list(f)], near) for f in _BOX_FACES]
            pts = [p for p in pts if p.shape[0] >= 3]
            if not pts:
                return None, lead_c
            uv = self.camera.project(np.concatenate(pts))
        x0, y0 = np.clip(uv.min(axis=0), 0, [self.W - 1, self.H - 1])
        x1, y1 = np.clip(uv.max(axis=0), 0, [self.W - 1, self.H - 1])
        if x1 <= x0 or y1 <= y0:
            return None, lead_c
        return (float(x0), float(y0), float(x1), float(y1)), lead_c

    def _develop(
        self,
        cv: Canvas,
        k_fog: float,
        ambient: float,
        lights_on: bool,
        pitch_rate: float,
        rng: np.random.Generator,
    ) -> U8:
        """The painted canvas through air, light, optics and sensor to the output image."""
        cfg = self.cfg
        img = cv.img
        if k_fog > 0 and cv.invz is not None:
            img = self._atmosphere.fog(img, cv.invz, k_fog)
        gain = exposure_gain(cfg, ambient, lights_on)
        if lights_on and cv.invz is not None:
            img = self._atmosphere.light(img, cv.invz, cv.emission, ambient, gain)
            expo = 1.0
        else:
            expo = ambient * gain
        img = sensor.blur(img, cfg, self.camera.fy, pitch_rate)
        img = sensor.expose(img, cfg, expo)
        if cfg.noise:
            img = self._noise.add(img, gain, rng)
        return np.ascontiguousarray(img, np.uint8)
