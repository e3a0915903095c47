"""What one frame draws: quads in camera coordinates with their draw-order keys.

`DrawListBuilder` turns a `SceneLayout` (ground strips, roadside groups, with the
parked cars baked in once) and the moving vehicles into `DrawQuads` for a camera
pose; `roadpreview.sim.render.raster` paints them in order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.sim.frames import body_to_world
from roadpreview.sim.render.geometry import (
    VehicleGeometry,
    footprint,
    vehicle_points_world,
)
from roadpreview.sim.scene import (
    LAYER_ROADSIDE,
    QuadSet,
    SceneLayout,
    Texture,
    VehicleTextures,
    make_vehicle_textures,
)
from roadpreview.sim.types import CameraPose, VehiclePose, VehicleShape

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: distances (m ahead of the camera) where ground strips are cut; later chunks <= 48 m
_STRIP_CUTS = (-4.0, 4.0, 7.0, 11.0, 17.0, 26.0, 40.0, 60.0, 90.0, 135.0)
_FIELDS = ("pc", "tex", "rect", "colour", "shade", "vid", "emissive", "layer", "key", "item")


@dataclass
class DrawQuads:
    """A block of quads in camera coordinates with their draw-order keys.

    Quads are sorted by (layer, -depth key, item, seq): back layers first, far
    items first, an item's quads in their own order.
    """

    pc: F64  # (N, 4, 3) camera-frame corners P0..P3
    tex: I64  # index into the frame's texture list, -1 = flat
    rect: F64  # (N, 4) texel-edge coordinates (s0, t0, s1, t1)
    colour: I64  # (N, 3) flat colour (emissive colour for lamps)
    shade: F64  # (N,)
    vid: I64  # (N,)
    emissive: NDArray[np.bool_]  # (N,)
    layer: I64  # (N,)
    key: F64  # (N,)
    item: I64  # (N,)

    @classmethod
    def make(
        cls,
        pc: F64,
        tex: Sequence[int] | I64,
        rect: F64 | Sequence[Sequence[float]],
        colour: I64 | Sequence[Sequence[int]],
        shade: F64 | Sequence[float],
        *,
        vid: int = 0,
        emissive: bool = False,
        layer: int | I64 = 0,
        key: float | F64 = 0.0,
        item: int | I64 = 0,
    ) -> DrawQuads:
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
    def concat(cls, parts: Sequence[DrawQuads]) -> DrawQuads:
        return cls(**{n: np.concatenate([getattr(p, n) for p in parts]) for n in _FIELDS})

    def take(self, order: I64) -> DrawQuads:
        return DrawQuads(**{n: getattr(self, n)[order] for n in _FIELDS})


class VehicleLibrary:
    """Textures per (appearance, shape) and body-frame quads per shape, made once each."""

    def __init__(self) -> None:
        self._tex: dict[tuple[int, VehicleShape], VehicleTextures] = {}
        self._geo: dict[VehicleShape, VehicleGeometry] = {}

    def textures(self, pose: VehiclePose) -> VehicleTextures:
        """The (cached) textures of a vehicle's appearance."""
        key = (pose.appearance, pose.shape)
        tex = self._tex.get(key)
        if tex is None:
            tex = make_vehicle_textures(pose.appearance, pose.shape)
            self._tex[key] = tex
        return tex

    def geometry(self, shape: VehicleShape) -> VehicleGeometry:
        """The (cached) body-frame quads of a vehicle shape."""
        geo = self._geo.get(shape)
        if geo is None:
            geo = VehicleGeometry.build(shape)
            self._geo[shape] = geo
        return geo


def _face_rects(geo: VehicleGeometry, tx: VehicleTextures) -> F64:
    """Texel rectangles (N, 4) of a vehicle's quads on its rear/front/side textures."""
    sizes = np.array([t.size for t in (tx.rear, tx.front, tx.side)], np.float64)
    wh = sizes[np.maximum(geo.face_tex, 0)]
    rect: F64 = geo.rect_frac * np.concatenate([wh, wh], axis=1)
    return rect


def bake_static(scene: SceneLayout, vehicles: VehicleLibrary) -> tuple[list[Texture], QuadSet]:
    """The scene's textures and quads plus its parked cars (static vehicles) as one `QuadSet`."""
    textures = list(scene.textures)
    parked = scene.parked
    if not parked:
        return textures, scene.quads
    corners: list[F64] = []
    tex: list[I64] = []
    rect: list[F64] = []
    colour: list[I64] = []
    shade: list[F64] = []
    counts: list[int] = []
    xr: list[tuple[float, float]] = []
    tex_index: dict[tuple[int, VehicleShape], int] = {}
    for pose in parked:  # objects, once per scene
        geo = vehicles.geometry(pose.shape)
        key = (pose.appearance, pose.shape)
        tx = vehicles.textures(pose)
        if key not in tex_index:
            tex_index[key] = len(textures)
            textures.extend((tx.rear, tx.front, tx.side))
        base = tex_index[key]
        world = vehicle_points_world(pose, geo.quads.reshape(-1, 3)).reshape(-1, 4, 3)
        foot = footprint(pose, scene.height(pose.x_m, pose.y_m) + 0.01)
        corners += [foot[None], world]
        tex += [np.array([-1]), np.where(geo.face_tex >= 0, base + geo.face_tex, -1)]
        rect += [np.array([[0.0, 0, 1, 1]]), _face_rects(geo, tx)]
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
        group_layer=np.concatenate([q.group_layer, np.full(len(counts), LAYER_ROADSIDE)]).astype(
            np.int8
        ),
        group_x=np.concatenate([q.group_x, np.array(xr)]),
    )


class DrawListBuilder:
    """Collects the quads of one frame in camera coordinates.

    Parameters
    ----------
    scene
        The static world; its parked cars are baked into the roadside quads here.
    near_m
        The near clipping plane (m): quads entirely nearer are dropped.
    fy
        Focal length (px) in y: tyres under 12 px tall are skipped.
    """

    def __init__(self, scene: SceneLayout, near_m: float, fy: float) -> None:
        self.scene = scene
        self.near_m = near_m
        self.fy = fy
        self.vehicles = VehicleLibrary()
        #: the scene's textures plus the parked cars'; a frame appends its moving vehicles'
        self.textures, self.static = bake_static(scene, self.vehicles)
        q = self.static
        self._normals = np.cross(
            q.corners[:, 1] - q.corners[:, 0], q.corners[:, 3] - q.corners[:, 0]
        )

    def strips(
        self, cam: CameraPose, R: F64, C: F64, zr: float, dmax: float, tunnel: bool
    ) -> DrawQuads | None:
        """Ground strips (road, verges, kerbs, tunnel lining) cut into chunks along X."""
        cuts = [c for c in _STRIP_CUTS if c < dmax]
        while cuts[-1] + 48.0 < dmax:
            cuts.append(cuts[-1] + 48.0)
        cuts.append(dmax)
        x0s = cam.x_m + np.array(cuts[:-1])
        x1s = cam.x_m + np.array(cuts[1:])
        n = x0s.shape[0]
        parts: list[DrawQuads] = []
        for st in self.scene.strips:  # a handful of strips, each vectorised over its chunks
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
                DrawQuads.make(
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
                DrawQuads.make(
                    (corners - C) @ R.T,
                    np.full(m, -1),
                    np.tile([0.0, 0, 1, 1], (m, 1)),
                    np.tile([200, 235, 255], (m, 1)),
                    np.ones(m),
                    emissive=True,
                    layer=-1,
                )
            )
        return DrawQuads.concat(parts) if parts else None

    def roadside(self, cam: CameraPose, R: F64, C: F64, dmax: float) -> DrawQuads | None:
        """Roadside objects (and parked cars) within the draw distance, facing the camera."""
        q = self.static
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
        alive = facing & (zc.max(axis=1) > self.near_m) & (zc.min(axis=1) < dmax)
        gkey = np.minimum.reduceat(np.where(alive[:, None], zc, np.inf).min(axis=1), starts)
        grp = np.repeat(np.arange(gsel.size), count)
        keep = alive & np.isfinite(gkey[grp])
        if not np.any(keep):
            return None
        idx, grp = idx[keep], grp[keep]
        return DrawQuads.make(
            pcs[keep],
            q.tex_id[idx],
            q.tex_rect[idx],
            q.colour[idx],
            q.shade[idx],
            layer=q.group_layer[gsel[grp]].astype(np.int64),
            key=gkey[grp],
            item=gsel[grp],
        )

    def vehicle(
        self,
        pose: VehiclePose,
        R: F64,
        C: F64,
        *,
        vid: int,
        night: bool,
        item: int,
        textures: list[Texture],
    ) -> list[DrawQuads]:
        """A vehicle's contact shadow, tyres and body faces (and lamps at night).

        Its textures are appended to ``textures``, the frame's texture list.
        """
        shape = pose.shape
        geo = self.vehicles.geometry(shape)
        rb = body_to_world(pose.pitch_rad, pose.roll_rad, pose.yaw_rad)
        world = geo.quads @ rb.T + np.array([pose.x_m, pose.y_m, pose.z_m])
        pcs = (world - C) @ R.T
        z = pcs[..., 2]
        if z.max() <= self.near_m:
            return []
        key = float(z.min())
        normals = np.cross(world[:, 1] - world[:, 0], world[:, 3] - world[:, 0])
        facing = np.einsum("ij,ij->i", normals, world[:, 0] - C) > 0
        if self.fy * shape.height_m < 12.0 * max(key, 1e-3):
            facing &= ~geo.is_tyre  # tyres are sub-pixel: skip
        tx = self.vehicles.textures(pose)
        base = len(textures)
        textures.extend((tx.rear, tx.front, tx.side))
        tex = np.where(geo.face_tex >= 0, base + geo.face_tex, -1)
        rect = _face_rects(geo, tx)
        colour = np.where(geo.is_tyre[:, None], np.array([24, 24, 26]), np.array(tx.body_bgr))
        sel = np.nonzero(facing)[0]
        parts = [
            DrawQuads.make(
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
        foot = footprint(pose, self.scene.height(pose.x_m, pose.y_m) + 0.01)
        parts.insert(
            0,
            DrawQuads.make(
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
            lamps = self._lamps(pcs, facing, geo, tx, vid=vid, key=key, item=item)
            if lamps is not None:
                parts.append(lamps)
        return parts

    @staticmethod
    def _lamps(
        pcs: F64,
        facing: NDArray[np.bool_],
        geo: VehicleGeometry,
        tx: VehicleTextures,
        *,
        vid: int,
        key: float,
        item: int,
    ) -> DrawQuads | None:
        """Emissive tail and head lamps on the rear/front faces that face the camera."""
        lamps = []
        colours: list[tuple[int, int, int]] = []
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
        if not lamps:
            return None
        lp = np.concatenate(lamps)
        return DrawQuads.make(
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
