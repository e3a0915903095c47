"""The simulator's camera: draws a `SceneLayout` and vehicles with OpenCV, then degrades it.

`SceneRenderer.render` returns a `RenderedFrame`: a BGR image with real texture
(textured planes warped by homographies, painter's algorithm far to near), the
vehicle-id mask and the lead vehicle's ground truth, after fog (Koschmieder),
night / tunnel lighting with lamp glow, motion blur, lens blur, exposure, gamma
and sensor noise. Conventions are those of ``docs/method.md``; the design is in
``docs/simulator-rendering.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.sim.scene.textures import (
    LAYER_ROADSIDE,
    QuadSet,
    SceneLayout,
    Texture,
    VehicleTextures,
    make_vehicle_textures,
)
from roadpreview.sim.types import CameraPose, Conditions, VehiclePose, VehicleShape

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

#: world (X fwd, Y left, Z up) -> camera (x right, y down, z forward) for a level camera
_R_BASE = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
#: standard normal quantiles of the 256 byte values: Gaussian noise by table lookup
_GAUSS_Q = np.array([NormalDist().inv_cdf((k + 0.5) / 256.0) for k in range(256)])
#: distances (m ahead of the camera) where ground strips are cut; later chunks <= 48 m
_STRIP_CUTS = (-4.0, 4.0, 7.0, 11.0, 17.0, 26.0, 40.0, 60.0, 90.0, 135.0)
#: the inverse depth written for "infinitely far" pixels (sky, beyond the draw distance)
_INVZ_FAR = 1e-6
#: fog transmittance t = exp(-k d) tabulated on 255 sqrt(k d / KD_MAX)
_FOG_KD_MAX = 6.5
_FOG_T = np.exp(-_FOG_KD_MAX * (np.arange(256) / 255.0) ** 2).astype(np.float32)
_FOG_1MT = (1.0 - _FOG_T).astype(np.float32)


@dataclass(frozen=True)
class RenderConfig:
    """Camera, optics and sensor of the simulated front camera, and drawing limits."""

    near_m: float = param(0.3, unit="m", gt=0.0, le=5.0, help="near clipping plane")
    max_distance_m: float = param(
        300.0, unit="m", gt=20.0, help="beyond this the road is haze; f*1.3 m/300 m ~ 4 px"
    )
    lod_px: float = param(
        5.0, unit="px", ge=0.0, help="planes smaller than this are filled with their mean colour"
    )
    lod_thin_px: float = param(
        2.5, unit="px", ge=0.0, help="planes thinner than this (area / longest edge) too"
    )
    mip_bias: float = param(0.0, ge=-2.0, le=2.0, help="+1 = one mip level blurrier")
    sky_downsample: int = param(2, ge=1, le=8, help="the smooth sky is warped at 1/n resolution")
    optics_blur_sigma_px: float = param(
        0.6, unit="px", ge=0.0, le=5.0, help="lens PSF + pixel integration; antialiases edges"
    )
    exposure_ev: float = param(0.0, unit="EV", ge=-8.0, le=8.0, help="manual exposure offset")
    gamma: float = param(2.2, gt=1.0, le=3.0, help="output encoding, the same as the textures'")
    auto_exposure: bool = param(True, help="gain follows the scene light, up to max_gain")
    max_gain: float = param(
        32.0,
        ge=1.0,
        le=1000.0,
        help="auto exposure limit, exposure x analog gain over day (~1/500 -> 1/60 s, x4): 30 dB",
    )
    full_well_e: float = param(
        10000.0, unit="e-", gt=100.0, help="electrons at white at unity gain (small CMOS pixel)"
    )
    read_noise_e: float = param(4.0, unit="e-", ge=0.0, help="read noise")
    noise: bool = param(True, help="add shot + read noise")
    exposure_time_s: float = param(
        0.008, unit="s", ge=0.0, le=0.1, help="for the vertical motion blur of pitch rate"
    )
    motion_blur: bool = param(True, help="blur by f * pitch_rate * exposure_time vertically")
    airlight_bgr: tuple[int, int, int] = param(
        (206, 204, 200), help="fog colour in daylight (BGR); scaled by the light"
    )
    headlights_below_light: float = param(
        0.3, ge=0.0, le=1.0, help="Conditions.light below which the headlights are on"
    )
    headlight_gain: float = param(
        0.004,
        ge=0.0,
        help="low-beam illuminance on axis at headlight_ref_m over daylight (~40 lx / 10 klx)",
    )
    headlight_ref_m: float = param(10.0, unit="m", gt=0.0, help="reference distance of the gain")
    headlight_spread_deg: float = param(
        16.0, unit="deg", gt=1.0, le=90.0, help="horizontal 1/e half-width of the low beam"
    )
    headlight_cutoff_deg: float = param(
        -0.6, unit="deg", ge=-10.0, le=10.0, help="low-beam cut-off elevation"
    )
    lamp_glow_sigma: float = param(
        0.012, gt=0.0, le=0.2, help="glow of lamps at night, fraction of the image height"
    )
    lamp_glow_gain: float = param(1.5, ge=0.0, le=10.0, help="strength of the glow")
    tunnel_light: float = param(
        0.005, ge=0.0, le=1.0, help="tunnel interior lighting over daylight (~50 lx / 10 klx)"
    )
    metering_distance_m: float = param(
        15.0, unit="m", gt=0.0, help="auto exposure meters the road lit by the low beam here"
    )

    def validate(self, where: str = "RenderConfig") -> None:
        check_ranges(self, where)
        if any(not 0 <= c <= 255 for c in self.airlight_bgr):
            raise ConfigError(f"{where}.airlight_bgr = {self.airlight_bgr}: components in 0..255")


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


# ----------------------------------------------------------------------------------------
# Geometry helpers
# ----------------------------------------------------------------------------------------
def _rot_x(a: float) -> F64:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> F64:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_z(a: float) -> F64:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def body_to_world(pitch: float, roll: float, yaw: float) -> F64:
    """Rotation of a body (X fwd, Y left, Z up) with pitch nose-up, roll left-up, yaw left."""
    return _rot_z(yaw) @ _rot_y(-pitch) @ _rot_x(roll)


def _mount_rotation(forward: F64) -> F64:
    """Smallest rotation M taking the optical axis (0, 0, 1) to the calibrated forward t
    (camera coordinates): p_cam = M p_aligned, where the aligned frame has the body's
    forward direction on its z axis, so that the body's forward direction images at K t."""
    z = np.array([0.0, 0.0, 1.0])
    t = forward / np.linalg.norm(forward)
    axis = np.cross(z, t)
    s, c = float(np.linalg.norm(axis)), float(np.dot(z, t))
    if s < 1e-12:
        return np.eye(3)
    rvec = axis / s * math.atan2(s, c)
    m, _ = cv2.Rodrigues(rvec)
    return np.asarray(m, np.float64)


def clip_near(poly: F64, near: float) -> F64:
    """Sutherland-Hodgman clip of a convex (n, 3) camera-frame polygon to z >= near."""
    d = poly[:, 2] - near
    nxt = np.roll(poly, -1, axis=0)
    dn = np.roll(d, -1)
    inside = d >= 0.0
    cross = inside != (dn >= 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, d / (d - dn), 0.0)
    inter = poly + t[:, None] * (nxt - poly)
    pts = np.stack([poly, inter], axis=1)
    keep = np.stack([inside, cross], axis=1)
    return pts[keep]


def _box_corners(shape: VehicleShape) -> F64:
    """The 8 corners of the vehicle's box relative to the CG (body frame), from the
    road at rest (the tyres' contact) up to the roof."""
    r, f = -shape.cg_to_rear_m, shape.cg_to_front_m
    w = shape.width_m / 2
    zb = -shape.cg_height_m
    zt = shape.height_m - shape.cg_height_m
    return np.array([[x, y, z] for x in (r, f) for y in (-w, w) for z in (zb, zt)], np.float64)


def rear_face_center_body(shape: VehicleShape) -> F64:
    """Centre of the rear face of the body box in the body frame (relative to the CG).

    The body box spans from the ground clearance up to ``height_m`` (the overall
    height above the road) and its full width and length.
    """
    zc = 0.5 * (shape.ground_clearance_m + shape.height_m) - shape.cg_height_m
    return np.array([-shape.cg_to_rear_m, 0.0, zc])


@dataclass(frozen=True)
class _VehicleGeometry:
    """Body-frame quads of a vehicle shape: four tyres, then the body box's faces.

    Corners P0..P3 run top-left, top-right, bottom-right, bottom-left as seen
    from outside; ``face_tex`` is 0 rear, 1 front, 2 side, -1 flat (tyres, roof);
    ``rect_frac`` the texture rectangle as fractions of the texture size.
    """

    quads: F64  # (N, 4, 3)
    face_tex: NDArray[np.int64]
    rect_frac: F64  # (N, 4)
    shade: F64
    is_tyre: NDArray[np.bool_]
    rear_face: int
    front_face: int

    @classmethod
    def build(cls, shape: VehicleShape) -> _VehicleGeometry:
        r, f = -shape.cg_to_rear_m, shape.cg_to_front_m
        w = shape.width_m / 2
        g = -shape.cg_height_m  # the road at rest
        zb = shape.ground_clearance_m + g
        zt = shape.height_m + g
        quads: list[list[list[float]]] = []
        shade: list[float] = []
        tl, tw_, tz = 0.62, 0.22, zb + 0.06
        for xc in (r + 0.9, f - 0.9):
            for ys in (-1.0, 1.0):
                y0, y1 = ys * (w - 0.17) - tw_ / 2, ys * (w - 0.17) + tw_ / 2
                x0, x1 = xc - tl / 2, xc + tl / 2
                quads += [
                    [[x0, y1, tz], [x0, y0, tz], [x0, y0, g], [x0, y1, g]],  # rear (-X)
                    [[x1, y0, tz], [x1, y1, tz], [x1, y1, g], [x1, y0, g]],  # front (+X)
                    [[x1, y1, tz], [x0, y1, tz], [x0, y1, g], [x1, y1, g]],  # left (+Y)
                    [[x0, y0, tz], [x1, y0, tz], [x1, y0, g], [x0, y0, g]],  # right (-Y)
                ]
                shade += [0.8, 1.0, 0.9, 0.9]
        n_tyre = len(quads)
        quads += [
            [[r, w, zt], [r, -w, zt], [r, -w, zb], [r, w, zb]],  # rear
            [[f, -w, zt], [f, w, zt], [f, w, zb], [f, -w, zb]],  # front
            [[f, w, zt], [r, w, zt], [r, w, zb], [f, w, zb]],  # left side (front at left)
            [[r, -w, zt], [f, -w, zt], [f, -w, zb], [r, -w, zb]],  # right side
            [[r, w, zt], [f, w, zt], [f, -w, zt], [r, -w, zt]],  # roof, seen from above
        ]
        shade += [1.0, 0.95, 0.8, 0.9, 1.08]
        face_tex = [-1] * n_tyre + [0, 1, 2, 2, -1]
        rect = [[0.0, 0.0, 1.0, 1.0]] * n_tyre + [
            [0.0, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
        ]
        return cls(
            quads=np.array(quads, np.float64),
            face_tex=np.array(face_tex, np.int64),
            rect_frac=np.array(rect, np.float64),
            shade=np.array(shade, np.float64),
            is_tyre=np.arange(len(quads)) < n_tyre,
            rear_face=n_tyre,
            front_face=n_tyre + 1,
        )


def _footprint(pose: VehiclePose, z: float) -> F64:
    """Contact-shadow quad under a vehicle (10 cm larger than the body), at height z."""
    shape = pose.shape
    rr, ff = -shape.cg_to_rear_m - 0.1, shape.cg_to_front_m + 0.1
    w = shape.width_m / 2 + 0.1
    foot = np.array([[rr, w, 0.0], [ff, w, 0.0], [ff, -w, 0.0], [rr, -w, 0.0]])
    foot = foot @ _rot_z(pose.yaw_rad).T + np.array([pose.x_m, pose.y_m, 0.0])
    foot[:, 2] = z
    return foot


# ----------------------------------------------------------------------------------------
# Per-frame drawing state
# ----------------------------------------------------------------------------------------
class _Canvas:
    """The frame and its side buffers for one render."""

    def __init__(self, w: int, h: int, need_depth: bool, need_emission: bool) -> None:
        self.w, self.h = w, h
        self.img = np.empty((h, w, 3), np.uint8)
        self.vmask = np.zeros((h, w), np.int16)
        self.invz: F32 | None = np.full((h, w), _INVZ_FAR, np.float32) if need_depth else None
        self.emission: U8 | None = np.zeros((h, w, 3), np.uint8) if need_emission else None
        self.vehicle_drawn = False


@dataclass
class _Quads:
    """A block of quads in camera coordinates with their draw-order keys.

    Quads are sorted by (layer, -depth key, item, seq): back layers first, far
    items first, an item's quads in their own order.
    """

    pc: F64  # (N, 4, 3) camera-frame corners P0..P3
    tex: NDArray[np.int64]  # index into the frame's texture list, -1 = flat
    rect: F64  # (N, 4) texel-edge coordinates (s0, t0, s1, t1)
    colour: NDArray[np.int64]  # (N, 3) flat colour (emissive colour for lamps)
    shade: F64  # (N,)
    vid: NDArray[np.int64]  # (N,)
    emissive: NDArray[np.bool_]  # (N,)
    layer: NDArray[np.int64]  # (N,)
    key: F64  # (N,)
    item: NDArray[np.int64]  # (N,)

    @classmethod
    def make(
        cls,
        pc: F64,
        tex: Sequence[int] | NDArray[np.int64],
        rect: F64 | Sequence[Sequence[float]],
        colour: NDArray[np.int64] | Sequence[Sequence[int]],
        shade: F64 | Sequence[float],
        *,
        vid: int = 0,
        emissive: bool = False,
        layer: int | NDArray[np.int64] = 0,
        key: float | F64 = 0.0,
        item: int | NDArray[np.int64] = 0,
    ) -> _Quads:
        n = int(pc.shape[0])

        return cls(
            pc=np.asarray(pc, np.float64).reshape(n, 4, 3),
            tex=np.asarray(tex, np.int64).reshape(n),
            rect=np.asarray(rect, np.float64).reshape(n, 4),
            colour=np.asarray(colour, np.int64).reshape(n, 3),
            shade=np.asarray(shade, np.float64).reshape(n),
            vid=np.full(n, vid, np.int64),
            emissive=np.full(n, emissive, np.bool_),
            layer=np.broadcast_to(np.asarray(layer, np.int64), (n,)).copy(),
            key=np.broadcast_to(np.asarray(key, np.float64), (n,)).copy(),
            item=np.broadcast_to(np.asarray(item, np.int64), (n,)).copy(),
        )

    @classmethod
    def concat(cls, parts: Sequence[_Quads]) -> _Quads:
        names = ("pc", "tex", "rect", "colour", "shade", "vid", "emissive", "layer", "key", "item")
        return cls(**{n: np.concatenate([getattr(p, n) for p in parts]) for n in names})

    def take(self, order: NDArray[np.int64]) -> _Quads:
        names = ("pc", "tex", "rect", "colour", "shade", "vid", "emissive", "layer", "key", "item")
        return _Quads(**{n: getattr(self, n)[order] for n in names})


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
        self.K = camera.K
        self.W, self.H = camera.width, camera.height
        self._mount = _mount_rotation(camera.t)
        self._veh_tex: dict[tuple[int, VehicleShape], VehicleTextures] = {}
        self._veh_geo: dict[VehicleShape, _VehicleGeometry] = {}
        self._textures, self._static = self._bake_static()
        q = self._static
        self._normals = np.cross(
            q.corners[:, 1] - q.corners[:, 0], q.corners[:, 3] - q.corners[:, 0]
        )
        # pixel grids and ray lengths (for per-pixel depth) and the headlight beam
        u = np.arange(self.W, dtype=np.float32)
        v = np.arange(self.H, dtype=np.float32)
        self._U, self._V = np.meshgrid(u, v)
        xn = (self._U - camera.cx) / camera.fx
        yn = (self._V - camera.cy) / camera.fy
        self._ray_len = np.sqrt(1.0 + xn * xn + yn * yn).astype(np.float32)
        self._beam = self._headlight_beam(xn, yn)
        self._airlight_cache: dict[tuple[int, int, int], U8] = {}
        #: scratch for the noise (reused: allocating 2 x 5.5 MB per frame costs page faults)
        self._noise_buf = (
            np.empty((self.H, self.W, 3), np.int16),
            np.empty((self.H, self.W, 3), np.int16),
        )

    # -- geometry ------------------------------------------------------------------
    def world_to_camera(self, cam: CameraPose) -> tuple[F64, F64]:
        """(R, C) with p_cam = R @ (p_world - C) for the camera pose ``cam``."""
        rb = body_to_world(cam.pitch_rad, cam.roll_rad, cam.yaw_rad)
        R = self._mount @ _R_BASE @ rb.T
        return R, np.array([cam.x_m, cam.y_m, cam.z_m])

    @staticmethod
    def vehicle_points_world(pose: VehiclePose, body_points: F64) -> F64:
        """Body-frame points (relative to the CG) of a vehicle to world coordinates."""
        rb = body_to_world(pose.pitch_rad, pose.roll_rad, pose.yaw_rad)
        return np.asarray(body_points, np.float64).reshape(-1, 3) @ rb.T + np.array(
            [pose.x_m, pose.y_m, pose.z_m]
        )

    def _headlight_beam(self, xn: F32, yn: F32) -> F32:
        """Low-beam pattern in the image (fixed: lamps and camera ride on the same body)."""
        cfg = self.cfg
        rays = np.stack([xn, yn, np.ones_like(xn)], axis=-1) @ self._mount  # body-aligned
        az = np.arctan2(rays[..., 0], rays[..., 2])
        el = np.arctan2(-rays[..., 1], rays[..., 2])
        spread = math.radians(cfg.headlight_spread_deg)
        cut = math.radians(cfg.headlight_cutoff_deg)
        horiz = np.exp(-((az / spread) ** 2))
        vert = np.where(el < cut, 1.0, np.exp(-(((el - cut) / 0.01) ** 2)))
        # illumination = gain * beam * (d_ref / d)^2 with d = ray_len / invz
        b = cfg.headlight_gain * horiz * vert * cfg.headlight_ref_m**2 / self._ray_len**2
        return b.astype(np.float32)

    def vehicle_textures(self, pose: VehiclePose) -> VehicleTextures:
        """The (cached) textures of a vehicle's appearance."""
        key = (pose.appearance, pose.shape)
        tex = self._veh_tex.get(key)
        if tex is None:
            tex = make_vehicle_textures(pose.appearance, pose.shape)
            self._veh_tex[key] = tex
        return tex

    def _bake_static(self) -> tuple[list[Texture], QuadSet]:
        """The scene's quads plus its parked cars (static vehicles) as one `QuadSet`."""
        scene = self.scene
        textures = list(scene.textures)
        parked = scene.parked
        if not parked:
            return textures, scene.quads
        corners, tex, rect, colour, shade, counts, xr = [], [], [], [], [], [], []
        tex_index: dict[tuple[int, VehicleShape], int] = {}
        for pose in parked:
            geo = self._geometry(pose.shape)
            key = (pose.appearance, pose.shape)
            if key not in tex_index:
                tx = self.vehicle_textures(pose)
                tex_index[key] = len(textures)
                textures.extend((tx.rear, tx.front, tx.side))
            tx = self.vehicle_textures(pose)
            base = tex_index[key]
            world = self.vehicle_points_world(pose, geo.quads.reshape(-1, 3)).reshape(-1, 4, 3)
            sizes = np.array([t.size for t in (tx.rear, tx.front, tx.side)], np.float64)
            wh = sizes[np.maximum(geo.face_tex, 0)]
            foot = _footprint(pose, scene.height(pose.x_m, pose.y_m) + 0.01)
            corners += [foot[None], world]
            tex += [np.array([-1]), np.where(geo.face_tex >= 0, base + geo.face_tex, -1)]
            rect += [np.array([[0.0, 0, 1, 1]]), geo.rect_frac * np.concatenate([wh, wh], axis=1)]
            colour += [
                np.array([[40, 42, 44]]),
                np.where(geo.is_tyre[:, None], np.array([24, 24, 26]), np.array(tx.body_bgr)),
            ]
            shade += [np.ones(1), geo.shade]
            counts.append(1 + geo.quads.shape[0])
            xs = world[..., 0]
            xr.append((float(xs.min()), float(xs.max())))
        q = scene.quads
        n_new = int(sum(counts))
        first = q.corners.shape[0] + np.concatenate([[0], np.cumsum(counts)[:-1]])
        return textures, QuadSet(
            corners=np.concatenate([q.corners, *corners]),
            tex_id=np.concatenate([q.tex_id, *tex]).astype(np.int32),
            tex_rect=np.concatenate([q.tex_rect, *rect]),
            colour=np.concatenate([q.colour, *colour]).astype(np.uint8),
            shade=np.concatenate([q.shade, *shade]).astype(np.float32),
            two_sided=np.concatenate([q.two_sided, np.zeros(n_new, bool)]),
            group_first=np.concatenate([q.group_first, first]).astype(np.int64),
            group_count=np.concatenate([q.group_count, counts]).astype(np.int64),
            group_layer=np.concatenate(
                [q.group_layer, np.full(len(counts), LAYER_ROADSIDE)]
            ).astype(np.int8),
            group_x=np.concatenate([q.group_x, np.array(xr)]),
        )

    def _geometry(self, shape: VehicleShape) -> _VehicleGeometry:
        geo = self._veh_geo.get(shape)
        if geo is None:
            geo = _VehicleGeometry.build(shape)
            self._veh_geo[shape] = geo
        return geo

    # -- what to draw ---------------------------------------------------------------
    def _strip_quads(
        self, cam: CameraPose, R: F64, C: F64, zr: float, dmax: float, tunnel: bool
    ) -> _Quads | None:
        """Ground strips (road, verges, kerbs, tunnel lining) cut into chunks along X."""
        cuts = [c for c in _STRIP_CUTS if c < dmax]
        while cuts[-1] + 48.0 < dmax:
            cuts.append(cuts[-1] + 48.0)
        cuts.append(dmax)
        x0s = cam.x_m + np.array(cuts[:-1])
        x1s = cam.x_m + np.array(cuts[1:])
        n = x0s.shape[0]
        parts: list[_Quads] = []
        for st in self.scene.strips:
            if st.tunnel and not tunnel:
                continue
            tex = self.scene.textures[st.tex_id]
            corners = np.empty((n, 4, 3))
            corners[:, 0, 0] = corners[:, 3, 0] = x0s
            corners[:, 1, 0] = corners[:, 2, 0] = x1s
            corners[:, 0:2, 1] = st.y_a
            corners[:, 2:4, 1] = st.y_b
            corners[:, 0:2, 2] = zr + st.z_a
            corners[:, 2:4, 2] = zr + st.z_b
            off = np.floor(x0s / st.period_m) * st.period_m
            rect = np.stack(
                [
                    (x0s - off) / st.texel_s_m,
                    np.zeros(n),
                    (x1s - off) / st.texel_s_m,
                    np.full(n, float(tex.size[1])),
                ],
                axis=1,
            )
            parts.append(
                _Quads.make(
                    (corners - C) @ R.T,
                    np.full(n, st.tex_id),
                    rect,
                    np.tile(tex.mean_bgr, (n, 1)),
                    np.ones(n),
                    layer=-2,
                )
            )
        if tunnel:
            sc = self.scene.cfg
            sp = sc.tunnel_light_spacing_m
            xs = (np.floor(cam.x_m / sp) + np.arange(0, int(min(dmax, 250.0) / sp) + 2)) * sp
            yc, z = 0.5 * sc.lane_width_m, zr + sc.tunnel_height_m - 0.02
            m = xs.shape[0]
            corners = np.empty((m, 4, 3))
            corners[:, 0, 0] = corners[:, 3, 0] = xs - 0.75
            corners[:, 1, 0] = corners[:, 2, 0] = xs + 0.75
            corners[:, 0:2, 1] = yc + 0.2
            corners[:, 2:4, 1] = yc - 0.2
            corners[:, :, 2] = z
            parts.append(
                _Quads.make(
                    (corners - C) @ R.T,
                    np.full(m, -1),
                    np.tile([0.0, 0, 1, 1], (m, 1)),
                    np.tile([200, 235, 255], (m, 1)),
                    np.ones(m),
                    emissive=True,
                    layer=-1,
                )
            )
        return _Quads.concat(parts) if parts else None

    def _static_quads(self, cam: CameraPose, R: F64, C: F64, dmax: float) -> _Quads | None:
        """Roadside objects (and parked cars) within the draw distance, facing the camera."""
        q = self._static
        if q.n_groups == 0:
            return None
        gx = q.group_x
        gsel = np.nonzero((gx[:, 1] > cam.x_m - 30.0) & (gx[:, 0] < cam.x_m + dmax))[0]
        if gsel.size == 0:
            return None
        first, count = q.group_first[gsel], q.group_count[gsel]
        total = int(count.sum())
        starts = np.cumsum(count) - count
        idx = np.repeat(first, count) + (np.arange(total) - np.repeat(starts, count))
        pcs = (q.corners[idx] - C) @ R.T
        zc = pcs[..., 2]
        facing = q.two_sided[idx] | (
            np.einsum("ij,ij->i", self._normals[idx], q.corners[idx, 0] - C) > 0
        )
        alive = facing & (zc.max(axis=1) > self.cfg.near_m) & (zc.min(axis=1) < dmax)
        gkey = np.minimum.reduceat(np.where(alive[:, None], zc, np.inf).min(axis=1), starts)
        grp = np.repeat(np.arange(gsel.size), count)
        keep = alive & np.isfinite(gkey[grp])
        if not np.any(keep):
            return None
        idx, grp = idx[keep], grp[keep]
        return _Quads.make(
            pcs[keep],
            q.tex_id[idx],
            q.tex_rect[idx],
            q.colour[idx],
            q.shade[idx],
            layer=q.group_layer[gsel[grp]].astype(np.int64),
            key=gkey[grp],
            item=gsel[grp],
        )

    def _vehicle_quads(
        self,
        pose: VehiclePose,
        R: F64,
        C: F64,
        vid: int,
        night: bool,
        item: int,
        textures: list[Texture],
    ) -> list[_Quads]:
        """A vehicle's contact shadow, tyres and body faces (and lamps at night)."""
        shape = pose.shape
        geo = self._geometry(shape)
        rb = body_to_world(pose.pitch_rad, pose.roll_rad, pose.yaw_rad)
        world = geo.quads @ rb.T + np.array([pose.x_m, pose.y_m, pose.z_m])
        pcs = (world - C) @ R.T
        z = pcs[..., 2]
        if z.max() <= self.cfg.near_m:
            return []
        key = float(z.min())
        normals = np.cross(world[:, 1] - world[:, 0], world[:, 3] - world[:, 0])
        facing = np.einsum("ij,ij->i", normals, world[:, 0] - C) > 0
        if self.camera.fy * shape.height_m < 12.0 * max(key, 1e-3):
            facing &= ~geo.is_tyre  # tyres are sub-pixel: skip
        tx = self.vehicle_textures(pose)
        base = len(textures)
        textures.extend((tx.rear, tx.front, tx.side))
        tex = np.where(geo.face_tex >= 0, base + geo.face_tex, -1)
        sizes = np.array([t.size for t in (tx.rear, tx.front, tx.side)], np.float64)
        wh = sizes[np.maximum(geo.face_tex, 0)]
        rect = geo.rect_frac * np.concatenate([wh, wh], axis=1)
        colour = np.where(geo.is_tyre[:, None], np.array([24, 24, 26]), np.array(tx.body_bgr))
        sel = np.nonzero(facing)[0]
        parts = [
            _Quads.make(
                pcs[sel],
                tex[sel],
                rect[sel],
                colour[sel],
                geo.shade[sel],
                vid=vid,
                layer=LAYER_ROADSIDE,
                key=key,
                item=item,
            )
        ]
        # contact shadow on the road under the body, drawn just before the vehicle
        foot = _footprint(pose, self.scene.height(pose.x_m, pose.y_m) + 0.01)
        parts.insert(
            0,
            _Quads.make(
                ((foot - C) @ R.T)[None],
                [-1],
                [[0.0, 0, 1, 1]],
                [[40, 42, 44]],
                [1.0],
                layer=LAYER_ROADSIDE,
                key=key,
                item=item,
            ),
        )
        if night:
            lamps = []
            colours = []
            for face, lamp_rects, colour_ in (
                (geo.rear_face, tx.tail_lamps, (60, 60, 255)),
                (geo.front_face, tx.head_lamps, (235, 250, 255)),
            ):
                if not facing[face]:
                    continue
                p0 = pcs[face, 0]
                e1, e2 = pcs[face, 1] - p0, pcs[face, 3] - p0
                fr = np.asarray(lamp_rects, np.float64).reshape(-1, 4)
                fx0, fy0, fx1, fy1 = fr[:, 0:1], fr[:, 1:2], fr[:, 2:3], fr[:, 3:4]
                lamps.append(
                    np.stack(
                        [
                            p0 + fx0 * e1 + fy0 * e2,
                            p0 + fx1 * e1 + fy0 * e2,
                            p0 + fx1 * e1 + fy1 * e2,
                            p0 + fx0 * e1 + fy1 * e2,
                        ],
                        axis=1,
                    )
                )
                colours += [colour_] * fr.shape[0]
            if lamps:
                lp = np.concatenate(lamps)
                parts.append(
                    _Quads.make(
                        lp,
                        np.full(lp.shape[0], -1),
                        np.tile([0.0, 0, 1, 1], (lp.shape[0], 1)),
                        colours,
                        np.ones(lp.shape[0]),
                        vid=vid,
                        emissive=True,
                        layer=LAYER_ROADSIDE,
                        key=key,
                        item=item,
                    )
                )
        return parts

    # -- painting -------------------------------------------------------------------
    def _paint_all(self, cv: _Canvas, q: _Quads, textures: Sequence[Texture]) -> None:
        """Project all quads at once, then paint them in order (warps per bounding box)."""
        cfg = self.cfg
        cam = self.camera
        fx, fy, cx, cy = cam.fx, cam.fy, cam.cx, cam.cy
        n = q.pc.shape[0]
        if n == 0:
            return
        pc = q.pc
        z = pc[..., 2]
        near = cfg.near_m
        alive = z.max(axis=1) > near
        clipped = alive & (z.min(axis=1) < near)
        fast = alive & ~clipped
        zs = np.where(fast[:, None], z, 1.0)
        uv = np.stack([fx * pc[..., 0] / zs + cx, fy * pc[..., 1] / zs + cy], axis=-1)
        uv[~fast] = 0.0
        lo, hi = uv.min(axis=1), uv.max(axis=1)
        x0 = np.clip(np.floor(lo[:, 0]), 0, cv.w).astype(np.int64)
        y0 = np.clip(np.floor(lo[:, 1]), 0, cv.h).astype(np.int64)
        x1 = np.clip(np.ceil(hi[:, 0]) + 1, 0, cv.w).astype(np.int64)
        y1 = np.clip(np.ceil(hi[:, 1]) + 1, 0, cv.h).astype(np.int64)
        # sub-pixel flat details vanish under the lens blur: skip them
        tiny = (q.tex < 0) & ~q.emissive & ((hi - lo).max(axis=1) < 1.0)
        visible = clipped | (fast & (x1 > x0) & (y1 > y0) & ~tiny)
        # textures: mip level from the mean scale (px per texel) of the quad
        nlev = np.array([len(t.levels) for t in textures] + [1], np.int64)[q.tex]
        s0, t0, s1, t1 = q.rect.T
        area_tex = np.abs((s1 - s0) * (t1 - t0))
        area_px = 0.5 * np.abs(
            np.sum(
                uv[..., 0] * np.roll(uv[..., 1], -1, axis=1)
                - uv[..., 1] * np.roll(uv[..., 0], -1, axis=1),
                axis=1,
            )
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            lvl = np.round(
                -0.5 * np.log2(np.maximum(area_px, 1e-12) / np.maximum(area_tex, 1e-12))
                + cfg.mip_bias
            )
        level = np.clip(np.nan_to_num(lvl), 0, nlev - 1).astype(np.int64)
        # thin or small planes (far kerbs, fences, poles) are filled with their mean colour
        edge = np.linalg.norm(uv - np.roll(uv, -1, axis=1), axis=2).max(axis=1)
        thin = area_px < cfg.lod_thin_px * edge
        small = ((hi - lo).max(axis=1) < cfg.lod_px) | thin
        flat = (q.tex < 0) | (small & fast)
        tex_mean = np.array([t.mean_bgr for t in textures] + [(0, 0, 0)], np.float64)[q.tex]
        fcol = np.where((q.tex >= 0)[:, None], tex_mean, q.colour) * q.shade[:, None]
        fcol = np.where(q.emissive[:, None], q.colour, np.minimum(fcol, 255.0)).astype(np.int64)
        Hm = self._homographies(pc, q.rect, level, x0, y0)
        pts = np.round((uv - np.stack([x0, y0], axis=1)[:, None, :]) * 16.0).astype(np.int32)
        depth = self._depth_planes(pc) if cv.invz is not None else None

        order = np.nonzero(visible)[0].tolist()
        xl, yl, xh, yh = x0.tolist(), y0.tolist(), x1.tolist(), y1.tolist()
        texl, lvll, flatl, vidl, shadel = (
            q.tex.tolist(),
            level.tolist(),
            flat.tolist(),
            q.vid.tolist(),
            q.shade.tolist(),
        )
        cl, eml = fcol.tolist(), q.emissive.tolist()
        clipl = clipped.tolist()
        for i in order:
            vid = vidl[i]
            if vid:
                cv.vehicle_drawn = True
            if clipl[i]:
                self._paint_clipped(cv, q, i, textures, depth)
                continue
            self._paint(
                cv,
                xl[i],
                yl[i],
                xh[i],
                yh[i],
                pts[i],
                None if flatl[i] else textures[texl[i]],
                lvll[i],
                Hm[i],
                tuple(cl[i]),
                shadel[i],
                vid,
                None if depth is None else depth[i],
                eml[i],
            )

    def _homographies(
        self,
        pc: F64,
        rect: F64,
        level: NDArray[np.int64],
        x0: NDArray[np.int64],
        y0: NDArray[np.int64],
    ) -> F64:
        """Texture (level-L pixel centres) -> image ROI homographies of all quads.

        Level-L pixel c covers level-0 texel edges [c 2^L, (c + 1) 2^L): its centre
        is the edge coordinate (c + 0.5) 2^L, mapped linearly onto the quad.
        """
        s0, t0, s1, t1 = rect.T
        k = np.exp2(level.astype(np.float64))
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (pc[:, 1] - pc[:, 0]) / np.where(s1 != s0, s1 - s0, 1.0)[:, None]
            b = (pc[:, 3] - pc[:, 0]) / np.where(t1 != t0, t1 - t0, 1.0)[:, None]
        M = np.empty((pc.shape[0], 3, 3))
        M[:, :, 0] = k[:, None] * a
        M[:, :, 1] = k[:, None] * b
        M[:, :, 2] = pc[:, 0] + (0.5 * k - s0)[:, None] * a + (0.5 * k - t0)[:, None] * b
        Hm = np.einsum("ij,njk->nik", self.K, M)
        Hm[:, 0, :] -= x0[:, None] * Hm[:, 2, :]
        Hm[:, 1, :] -= y0[:, None] * Hm[:, 2, :]
        return Hm

    def _depth_planes(self, pc: F64) -> F64:
        """(N, 3) coefficients (a, b, c) with 1/z = a u + b v + c on each quad's plane."""
        cam = self.camera
        nrm = np.cross(pc[:, 1] - pc[:, 0], pc[:, 3] - pc[:, 0])
        c = np.einsum("ij,ij->i", nrm, pc[:, 0])
        c = np.where(np.abs(c) < 1e-12, np.inf, c)
        a = nrm[:, 0] / cam.fx / c
        b = nrm[:, 1] / cam.fy / c
        c0 = (nrm[:, 2] - nrm[:, 0] * cam.cx / cam.fx - nrm[:, 1] * cam.cy / cam.fy) / c
        return np.stack([a, b, c0], axis=1)

    def _paint_clipped(
        self, cv: _Canvas, q: _Quads, i: int, textures: Sequence[Texture], depth: F64 | None
    ) -> None:
        """A quad crossing the near plane: clip in 3-D first, then paint as usual."""
        cam = self.camera
        pc = q.pc[i]
        poly = clip_near(pc, self.cfg.near_m)
        if poly.shape[0] < 3:
            return
        uv = np.stack(
            [cam.fx * poly[:, 0] / poly[:, 2] + cam.cx, cam.fy * poly[:, 1] / poly[:, 2] + cam.cy],
            axis=1,
        )
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        x0, y0 = max(0, math.floor(lo[0])), max(0, math.floor(lo[1]))
        x1, y1 = min(cv.w, math.ceil(hi[0]) + 1), min(cv.h, math.ceil(hi[1]) + 1)
        if x1 <= x0 or y1 <= y0:
            return
        tid = int(q.tex[i])
        tex = textures[tid] if tid >= 0 else None
        level = 0
        if tex is not None:
            s0, t0, s1, t1 = q.rect[i]
            e1, e2 = pc[1] - pc[0], pc[3] - pc[0]
            rel = poly - pc[0]
            ta = rel @ e1 / float(e1 @ e1) * (s1 - s0)
            tb = rel @ e2 / float(e2 @ e2) * (t1 - t0)
            a_tex = 0.5 * abs(float(np.dot(ta, np.roll(tb, -1)) - np.dot(tb, np.roll(ta, -1))))
            a_px = 0.5 * abs(
                float(
                    np.dot(uv[:, 0], np.roll(uv[:, 1], -1))
                    - np.dot(uv[:, 1], np.roll(uv[:, 0], -1))
                )
            )
            if a_tex > 0 and a_px > 0:
                level = int(
                    np.clip(
                        round(-0.5 * math.log2(a_px / a_tex) + self.cfg.mip_bias),
                        0,
                        len(tex.levels) - 1,
                    )
                )
        Hm = self._homographies(
            pc[None], q.rect[i : i + 1], np.array([level]), np.array([x0]), np.array([y0])
        )[0]
        pts = np.round((uv - (x0, y0)) * 16.0).astype(np.int32)
        if q.emissive[i]:
            colour = tuple(int(c) for c in q.colour[i])
        else:
            base = tex.mean_bgr if tex is not None else q.colour[i]
            colour = tuple(int(min(255.0, float(c) * float(q.shade[i]))) for c in base)
        self._paint(
            cv,
            x0,
            y0,
            x1,
            y1,
            pts,
            tex,
            level,
            Hm,
            colour,
            float(q.shade[i]),
            int(q.vid[i]),
            None if depth is None else depth[i],
            bool(q.emissive[i]),
        )

    def _paint(
        self,
        cv: _Canvas,
        x0: int,
        y0: int,
        x1: int,
        y1: int,
        pts: NDArray[np.int32],
        tex: Texture | None,
        level: int,
        Hm: F64,
        colour: tuple[int, ...],
        shade: float,
        vid: int,
        depth: F64 | None,
        emissive: bool,
    ) -> None:
        """Paint one projected polygon: flat fill, or the texture warped over its box."""
        roi = cv.img[y0:y1, x0:x1]
        bw, bh = x1 - x0, y1 - y0
        if emissive:
            cv2.fillConvexPoly(roi, pts, colour, shift=4)
            if cv.emission is not None:
                cv2.fillConvexPoly(cv.emission[y0:y1, x0:x1], pts, colour, shift=4)
            return
        mask: U8 | None = None
        if tex is None:
            cv2.fillConvexPoly(roi, pts, colour, shift=4)
            if depth is not None or cv.emission is not None:
                mask = np.zeros((bh, bw), np.uint8)
                cv2.fillConvexPoly(mask, pts, 255, shift=4)
        else:
            warped = cv2.warpPerspective(
                tex.levels[level],
                Hm,
                (bw, bh),
                flags=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            )
            mask = np.zeros((bh, bw), np.uint8)
            cv2.fillConvexPoly(mask, pts, 255, shift=4)
            if tex.has_alpha:
                _, alpha = cv2.threshold(warped[..., 3], 127, 255, cv2.THRESH_BINARY)
                mask = np.asarray(cv2.bitwise_and(mask, alpha), np.uint8)
                warped = cv2.cvtColor(warped, cv2.COLOR_BGRA2BGR)
            if shade != 1.0:
                warped = cv2.convertScaleAbs(warped, alpha=shade)
            cv2.copyTo(warped, mask, roi)
        vm = cv.vmask[y0:y1, x0:x1]
        if vid:
            cv2.fillConvexPoly(vm, pts, vid, shift=4)
        elif cv.vehicle_drawn:  # occludes vehicles drawn before
            if mask is None:
                cv2.fillConvexPoly(vm, pts, 0, shift=4)
            else:
                cv2.subtract(vm, vm, dst=vm, mask=mask)
        if mask is None:
            return
        if cv.emission is not None:
            em = cv.emission[y0:y1, x0:x1]
            cv2.subtract(em, em, dst=em, mask=mask)
        if depth is not None and cv.invz is not None:
            plane = cv2.addWeighted(
                self._U[y0:y1, x0:x1],
                float(depth[0]),
                self._V[y0:y1, x0:x1],
                float(depth[1]),
                float(depth[2]),
            )
            cv2.copyTo(plane, mask, cv.invz[y0:y1, x0:x1])

    def _draw_sky(self, cv: _Canvas, R: F64) -> None:
        """The sky plane at infinity (rotation only), warped at reduced resolution."""
        cam = self.camera
        sky = self.scene.sky
        n_c = R @ np.array([0.0, 0.0, 1.0])
        lvec = np.linalg.inv(self.K).T @ n_c
        if abs(lvec[1]) < 1e-9:
            v_end = cv.h
        else:
            vs = [-(lvec[0] * u + lvec[2]) / lvec[1] for u in (0.0, cv.w - 1.0)]
            v_end = int(min(cv.h, max(0.0, max(vs) + 0.12 * cv.h)))
        if v_end <= 0:
            return
        m = self.cfg.sky_downsample
        ws, hs = math.ceil(cv.w / m), math.ceil(v_end / m)
        # small pixel j is centred on full pixel (j + 0.5) m - 0.5, as cv2.resize maps
        Ks = np.array(
            [
                [cam.fx / m, 0.0, (cam.cx + 0.5) / m - 0.5],
                [0.0, cam.fy / m, (cam.cy + 0.5) / m - 0.5],
                [0.0, 0.0, 1.0],
            ]
        )
        tex = self.scene.textures[sky.tex_id]
        step = sky.step
        M = np.array(
            [
                [0.0, 0.0, 1.0],
                [-step, 0.0, sky.tan_az_max - 0.5 * step],
                [0.0, -step, sky.tan_el_max - 0.5 * step],
            ]
        )
        small = cv2.warpPerspective(
            tex.levels[0],
            Ks @ R @ M,
            (ws, hs),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )
        big = (
            small if m == 1 else cv2.resize(small, (ws * m, hs * m), interpolation=cv2.INTER_LINEAR)
        )
        cv.img[:v_end] = big[:v_end, : cv.w]

    # -- the frame ------------------------------------------------------------------
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
        cv = _Canvas(self.W, self.H, need_depth=k_fog > 0 or lights_on, need_emission=lights_on)

        bg = self.scene.tunnel_bgr if tunnel else self.scene.far_ground_bgr
        cv2.rectangle(cv.img, (0, 0), (self.W - 1, self.H - 1), bg, -1)  # 20x faster than numpy
        if not tunnel:
            self._draw_sky(cv, R)
        textures: list[Texture] = list(self._textures)
        parts: list[_Quads] = []
        strips = self._strip_quads(cam, R, C, zr, dmax, tunnel)
        if strips is not None:
            parts.append(strips)
        lead_pose: VehiclePose | None = None
        poses: list[VehiclePose] = []
        if not tunnel:
            st = self._static_quads(cam, R, C, dmax)
            if st is not None:
                parts.append(st)
        poses += list(vehicles)
        item = self._static.n_groups + 1
        for pose in poses:
            if pose.is_lead and lead_pose is None:
                lead_pose = pose
            parts += self._vehicle_quads(
                pose, R, C, int(pose.vehicle_id), lights_on, item, textures
            )
            item += 1
        allq = _Quads.concat(parts)
        order = np.lexsort((np.arange(allq.key.shape[0]), allq.item, -allq.key, allq.layer))
        self._paint_all(cv, allq.take(order), textures)

        lead_box, lead_c = self._lead_truth(lead_pose, R, C)
        image = self._develop(cv, k_fog, ambient, lights_on, pitch_rate_rad_s, rng)
        return RenderedFrame(
            image=image, vehicle_mask=cv.vmask, lead_box=lead_box, lead_rear_center_px=lead_c
        )

    def _lead_truth(
        self, pose: VehiclePose | None, R: F64, C: F64
    ) -> tuple[tuple[float, float, float, float] | None, tuple[float, float] | None]:
        if pose is None:
            return None, None
        centre = self.vehicle_points_world(pose, rear_face_center_body(pose.shape))
        pc = (centre - C) @ R.T
        lead_c: tuple[float, float] | None = None
        if pc[0, 2] > self.cfg.near_m:
            uv = self.camera.project(pc)[0]
            lead_c = (float(uv[0]), float(uv[1]))
        corners = (self.vehicle_points_world(pose, _box_corners(pose.shape)) - C) @ R.T
        # faces of the box (corner index = 4 ix + 2 iy + iz), each clipped to the near plane
        if corners[:, 2].min() >= self.cfg.near_m:
            uv = self.camera.project(corners)
        else:
            faces = (
                (0, 1, 3, 2),
                (4, 5, 7, 6),
                (0, 1, 5, 4),
                (2, 3, 7, 6),
                (0, 2, 6, 4),
                (1, 3, 7, 5),
            )
            pts = [clip_near(corners[list(f)], self.cfg.near_m) for f in faces]
            pts = [p for p in pts if p.shape[0] >= 3]
            if not pts:
                return None, lead_c
            uv = self.camera.project(np.concatenate(pts))
        x0, y0 = np.clip(uv.min(axis=0), 0, [self.W - 1, self.H - 1])
        x1, y1 = np.clip(uv.max(axis=0), 0, [self.W - 1, self.H - 1])
        if x1 <= x0 or y1 <= y0:
            return None, lead_c
        return (float(x0), float(y0), float(x1), float(y1)), lead_c

    # -- optics and sensor -------------------------------------------------------------
    def _airlight(self, colour: tuple[int, int, int]) -> U8:
        img = self._airlight_cache.get(colour)
        if img is None:
            img = np.empty((self.H, self.W, 3), np.uint8)
            cv2.rectangle(img, (0, 0), (self.W - 1, self.H - 1), colour, -1)
            self._airlight_cache = {colour: img}
        return img

    def _develop(
        self,
        cv: _Canvas,
        k_fog: float,
        ambient: float,
        lights_on: bool,
        pitch_rate: float,
        rng: np.random.Generator,
    ) -> U8:
        cfg = self.cfg
        img: NDArray[Any] = cv.img
        inv_g = 1.0 / cfg.gamma
        # Koschmieder: I = J t + A (1 - t), t = exp(-k d), d = |ray| / (1/z)
        if k_fog > 0 and cv.invz is not None:
            # k d on a square-root scale to 8 bits (steps of <= 1.5 % in t where contrast
            # is left), then t and 1 - t by table: 3x faster than a float exp
            kd = cv2.divide(self._ray_len, cv.invz, scale=k_fog / _FOG_KD_MAX)
            idx = cv2.convertScaleAbs(cv2.sqrt(kd), alpha=255.0)  # saturates at k d > max
            t = cv2.LUT(idx, _FOG_T)
            img = cv2.blendLinear(img, self._airlight(cfg.airlight_bgr), t, cv2.LUT(idx, _FOG_1MT))
        # exposure: auto gain towards daylight brightness (metering the ambient light and
        # the low beam on the road ahead), capped by max_gain
        gain = 2.0**cfg.exposure_ev
        if cfg.auto_exposure:
            metered = ambient
            if lights_on:
                metered += cfg.headlight_gain * (cfg.headlight_ref_m / cfg.metering_distance_m) ** 2
            gain *= float(np.clip(1.0 / max(metered, 1e-9), 1.0, cfg.max_gain))
        if lights_on and cv.invz is not None:
            # per-pixel light = ambient + headlights (falling off as 1/d^2); display
            # value scales by (light * gain)^(1/gamma) for a power-law response
            inv2 = cv2.multiply(cv.invz, cv.invz)
            light = np.asarray(cv2.multiply(inv2, self._beam), np.float32)
            np.minimum(light, 8.0, out=light)
            light += ambient
            root = cv2.sqrt(cv2.multiply(light, gain))  # in [0, 4] mapped to 0..255
            idx = cv2.convertScaleAbs(root, alpha=255.0 / 4.0)
            table = np.clip(64.0 * ((np.arange(256) * 4.0 / 255.0) ** 2) ** inv_g, 0, 255).astype(
                np.uint8
            )
            s = cv2.LUT(idx, table)
            img = cv2.multiply(img, cv2.merge([s, s, s]), scale=1.0 / 64.0)
            if cv.emission is not None:
                em = cv.emission
                img = cv2.add(img, em)
                sig = cfg.lamp_glow_sigma * self.H
                small = cv2.resize(
                    em, (max(1, self.W // 4), max(1, self.H // 4)), interpolation=cv2.INTER_AREA
                )
                small = cv2.GaussianBlur(small, (0, 0), max(0.5, sig / 4))
                glow = cv2.resize(small, (self.W, self.H), interpolation=cv2.INTER_LINEAR)
                img = cv2.addWeighted(img, 1.0, glow, cfg.lamp_glow_gain, 0.0)
            expo = 1.0
        else:
            expo = ambient * gain
        # vertical motion blur (pitch rate over the exposure) and the lens PSF, one pass
        blur_px = abs(self.camera.fy * pitch_rate * cfg.exposure_time_s) if cfg.motion_blur else 0.0
        sigma = cfg.optics_blur_sigma_px
        if blur_px > 0.3:
            g = _gauss_kernel(sigma)
            ky = np.convolve(g, _box_kernel(blur_px)).astype(np.float32)
            img = cv2.sepFilter2D(img, -1, g, ky)
        elif sigma > 0:  # the fixed-point Gaussian is ~3x faster than a float kernel
            r = max(1, math.ceil(2.5 * sigma))
            img = cv2.GaussianBlur(img, (2 * r + 1, 2 * r + 1), sigma)
        if abs(expo - 1.0) > 1e-6:
            lut = np.clip(255.0 * ((np.arange(256) / 255.0) ** cfg.gamma * expo) ** inv_g, 0, 255)
            img = cv2.LUT(img, np.round(lut).astype(np.uint8))
        if cfg.noise:
            img = self._add_noise(img, gain, rng)
        return np.ascontiguousarray(img, np.uint8)

    def _add_noise(self, img: U8, gain: float, rng: np.random.Generator) -> U8:
        """Shot + read noise, signal dependent, drawn by inverse-CDF lookup of random bytes.

        For display value D the linear signal is y = (D/255)^gamma; the pixel
        collected y/gain * full_well electrons; its std in display units is the
        electron std through the response's slope (capped by a linear toe as in
        sRGB, slope 12.92, where the power law's slope is infinite).
        """
        cfg = self.cfg
        y = (np.arange(256) / 255.0) ** cfg.gamma
        electrons = y / gain * cfg.full_well_e
        sigma_y = gain * np.sqrt(electrons + cfg.read_noise_e**2) / cfg.full_well_e
        with np.errstate(divide="ignore"):
            slope = np.where(y > 0, (1.0 / cfg.gamma) * y ** (1.0 / cfg.gamma - 1.0), np.inf)
        slope = np.minimum(slope, 12.92)
        sigma_d = 255.0 * sigma_y * slope
        sig_tab = np.clip(np.round(sigma_d * 64.0), 0, 32767).astype(np.int16)
        g_tab = np.round(_GAUSS_Q * 64.0).astype(np.int16)
        n = img.size
        raw = rng.bit_generator.random_raw((n + 7) // 8)
        u8 = np.asarray(raw).view(np.uint8)[:n].reshape(img.shape)
        g, sig = self._noise_buf
        cv2.LUT(u8, g_tab, dst=g)
        cv2.LUT(img, sig_tab, dst=sig)
        cv2.multiply(g, sig, dst=g, scale=1.0 / 4096.0, dtype=cv2.CV_16S)
        return np.asarray(cv2.add(img, g, dtype=cv2.CV_8U), np.uint8)


def _gauss_kernel(sigma: float) -> NDArray[np.float32]:
    if sigma <= 0:
        return np.array([1.0], np.float32)
    r = max(1, math.ceil(3.0 * sigma))
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return (k / k.sum()).astype(np.float32)


def _box_kernel(length: float) -> NDArray[np.float64]:
    """A centred box of (fractional) length in pixels, integrated over each pixel."""
    r = math.ceil(length / 2 + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    lo = np.maximum(x - 0.5, -length / 2)
    hi = np.minimum(x + 0.5, length / 2)
    w = np.clip(hi - lo, 0, None)
    return w / w.sum()
