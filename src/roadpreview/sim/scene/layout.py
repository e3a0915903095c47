"""The simulator's static world laid out from a seed: `generate_scene` -> `SceneLayout`.

`generate_scene` builds a `SceneLayout` once (textures with their mip pyramids,
road cross-section, buildings, trees, poles, fences, parked cars, sky, tunnel
lining) in world coordinates (X forward along the road, Y left, Z up; see
``docs/method.md``); `roadpreview.sim.render.SceneRenderer` draws it every
frame. Nothing here runs per frame. See ``docs/simulator-rendering.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from roadpreview.errors import ConfigError
from roadpreview.sim.scene.config import SceneConfig
from roadpreview.sim.scene.mipmap import Texture
from roadpreview.sim.scene.textures import (
    facade_texture,
    fence_texture,
    kerb_texture,
    road_texture,
    side_wall_texture,
    sky_texture,
    tree_texture,
    tunnel_texture,
    verge_texture,
)
from roadpreview.sim.types import VehiclePose, VehicleShape

RoadHeight = Callable[[float, float], float]
U8 = NDArray[np.uint8]

#: draw layers, back to front; objects in a higher layer are never occluded by a lower one
#: because they stand nearer the road (rays from a camera on the road cross them first)
LAYER_FACADE = 0
LAYER_FENCE = 1
LAYER_ROADSIDE = 2


@dataclass(frozen=True)
class QuadSet:
    """Static planar rectangles (and their draw groups) in world coordinates.

    Quad i has corners P0..P3 (``corners[i]``) that carry texel-edge coordinates
    (s0, t0), (s1, t0), (s1, t1), (s0, t1) of texture ``tex_id[i]`` with
    ``tex_rect[i] = (s0, t0, s1, t1)`` (level-0 texels); ``tex_id = -1`` is a flat
    polygon of ``colour[i]``. Quads of one object form a group drawn together in
    order; groups carry their layer and X extent.
    """

    corners: NDArray[np.float64]  # (N, 4, 3)
    tex_id: NDArray[np.int32]  # (N,)
    tex_rect: NDArray[np.float64]  # (N, 4)
    colour: NDArray[np.uint8]  # (N, 3)
    shade: NDArray[np.float32]  # (N,)
    two_sided: NDArray[np.bool_]  # (N,)
    group_first: NDArray[np.int64]  # (G,)
    group_count: NDArray[np.int64]  # (G,)
    group_layer: NDArray[np.int8]  # (G,)
    group_x: NDArray[np.float64]  # (G, 2) min/max X

    @property
    def n_groups(self) -> int:
        return int(self.group_first.shape[0])


@dataclass(frozen=True)
class GroundStrip:
    """An infinite-length strip along X with a periodic texture, between two cross-section
    edges (Y, Z-above-road): edge a carries texture row 0, edge b the last row."""

    name: str
    tex_id: int
    y_a: float
    z_a: float
    y_b: float
    z_b: float
    period_m: float
    texel_s_m: float
    tunnel: bool = False  # only drawn inside a tunnel


@dataclass(frozen=True)
class SkySpec:
    """The sky (and haze-grey far ground below the horizon) on a plane at infinity.

    Texture column c, row r (edge coordinates) look along the world direction
    (1, tan_az_max - c * step, tan_el_max - r * step).
    """

    tex_id: int
    tan_az_max: float
    tan_el_max: float
    step: float


@dataclass(frozen=True)
class SceneLayout:
    """Everything static in the world, ready for `roadpreview.sim.render.SceneRenderer`."""

    cfg: SceneConfig
    seed: int
    length_m: float
    textures: tuple[Texture, ...]
    strips: tuple[GroundStrip, ...]
    quads: QuadSet
    parked: tuple[VehiclePose, ...]
    sky: SkySpec
    far_ground_bgr: tuple[int, int, int]
    tunnel_bgr: tuple[int, int, int]
    road_height: RoadHeight = field(default=lambda x, y: 0.0, compare=False)

    def height(self, x: float, y: float) -> float:
        """Road elevation at (x, y) in metres."""
        return float(self.road_height(x, y))


class _QuadBuilder:
    def __init__(self) -> None:
        self.corners: list[NDArray[np.float64]] = []
        self.tex: list[int] = []
        self.rect: list[tuple[float, float, float, float]] = []
        self.colour: list[tuple[int, int, int]] = []
        self.shade: list[float] = []
        self.two: list[bool] = []
        self.g_first: list[int] = []
        self.g_count: list[int] = []
        self.g_layer: list[int] = []
        self.g_x: list[tuple[float, float]] = []

    def begin(self, layer: int) -> None:
        self.g_first.append(len(self.tex))
        self.g_count.append(0)
        self.g_layer.append(layer)
        self.g_x.append((math.inf, -math.inf))

    def add(
        self,
        corners: NDArray[np.float64],
        tex_id: int,
        rect: tuple[float, float, float, float],
        colour: tuple[int, int, int],
        shade: float = 1.0,
        two_sided: bool = False,
    ) -> None:
        self.corners.append(np.asarray(corners, np.float64).reshape(4, 3))
        self.tex.append(tex_id)
        self.rect.append(rect)
        self.colour.append(colour)
        self.shade.append(shade)
        self.two.append(two_sided)
        self.g_count[-1] += 1
        lo, hi = self.g_x[-1]
        xs = self.corners[-1][:, 0]
        self.g_x[-1] = (min(lo, float(xs.min())), max(hi, float(xs.max())))

    def build(self) -> QuadSet:
        n = len(self.tex)
        return QuadSet(
            corners=np.array(self.corners, np.float64).reshape(n, 4, 3),
            tex_id=np.array(self.tex, np.int32),
            tex_rect=np.array(self.rect, np.float64).reshape(n, 4),
            colour=np.array(self.colour, np.uint8).reshape(n, 3),
            shade=np.array(self.shade, np.float32),
            two_sided=np.array(self.two, bool),
            group_first=np.array(self.g_first, np.int64),
            group_count=np.array(self.g_count, np.int64),
            group_layer=np.array(self.g_layer, np.int8),
            group_x=np.array(self.g_x, np.float64).reshape(-1, 2),
        )


def _vertical_quad(
    x0: float, y0: float, x1: float, y1: float, z_bot: float, z_top: float
) -> NDArray[np.float64]:
    """Corners P0..P3 of a vertical rectangle from (x0, y0) to (x1, y1): P0 top-left."""
    return np.array(
        [[x0, y0, z_top], [x1, y1, z_top], [x1, y1, z_bot], [x0, y0, z_bot]], np.float64
    )


def generate_scene(
    cfg: SceneConfig | None = None,
    seed: int = 0,
    length_m: float = 1000.0,
    road_height: RoadHeight | None = None,
) -> SceneLayout:
    """Lay out a straight road of ``length_m`` (from X = 0) with its roadside, deterministically.

    Objects are placed from X = -50 m to ``length_m + cfg.margin_m`` so that the
    draw distance is filled at the end of the drive; their bases sit at
    ``road_height(x, y)`` (flat 0 by default).
    """
    cfg = cfg or SceneConfig()
    cfg.validate()
    if not (math.isfinite(length_m) and length_m > 0):
        raise ConfigError(f"generate_scene: length_m must be positive, got {length_m}")
    hfun: RoadHeight = road_height or (lambda x, y: 0.0)
    root = np.random.SeedSequence([seed & 0xFFFFFFFF, 0x5CE7E])
    rngs = [np.random.default_rng(s) for s in root.spawn(8)]
    r_tex, r_facade, r_tree, r_layout, r_sky = rngs[0], rngs[1], rngs[2], rngs[3], rngs[4]

    textures: list[Texture] = []

    def add_tex(name: str, img: U8) -> int:
        textures.append(Texture.build(name, img))
        return len(textures) - 1

    def doubled(img: U8) -> U8:
        # two periods side by side: any <= 1-period chunk of road fits without wrapping
        return np.ascontiguousarray(np.concatenate([img, img], axis=1))

    road_img, road_ts, _ = road_texture(cfg, r_tex)
    t_road = add_tex("road", doubled(road_img))
    vr_img, v_ts, _ = verge_texture(cfg, r_tex, left=False)
    t_vr = add_tex("verge-right", doubled(vr_img))
    vl_img, _, _ = verge_texture(cfg, r_tex, left=True)
    t_vl = add_tex("verge-left", doubled(vl_img))
    kerb_img, kerb_ts, _ = kerb_texture(cfg, r_tex)
    t_kerb = add_tex("kerb", doubled(kerb_img))
    tun_img, tun_ts, _ = tunnel_texture(r_tex, cfg.texture_period_m, cfg.tunnel_height_m, 0.04)
    t_tun = add_tex("tunnel-wall", doubled(tun_img))
    ceil_w = cfg.kerb_left_y - cfg.kerb_right_y + 2 * cfg.tunnel_width_m
    ceil_img, ceil_ts, _ = tunnel_texture(r_tex, cfg.texture_period_m, ceil_w, 0.04)
    t_ceil = add_tex("tunnel-ceiling", doubled((ceil_img * 0.8).astype(np.uint8)))

    P = cfg.texture_period_m
    kr, kl, kh = cfg.kerb_right_y, cfg.kerb_left_y, cfg.kerb_height_m
    tw, th = cfg.tunnel_width_m, cfg.tunnel_height_m
    strips = (
        GroundStrip("road", t_road, kl, 0.0, kr, 0.0, P, road_ts),
        GroundStrip("verge-right", t_vr, kr, kh, kr - cfg.verge_m, kh, P, v_ts),
        GroundStrip("verge-left", t_vl, kl + cfg.verge_m, kh, kl, kh, P, v_ts),
        GroundStrip("kerb-right", t_kerb, kr, kh, kr, 0.0, P, kerb_ts),
        GroundStrip("kerb-left", t_kerb, kl, kh, kl, 0.0, P, kerb_ts),
        GroundStrip("tunnel-right", t_tun, kr - tw, th, kr - tw, kh, P, tun_ts, True),
        GroundStrip("tunnel-left", t_tun, kl + tw, th, kl + tw, kh, P, tun_ts, True),
        GroundStrip("tunnel-ceiling", t_ceil, kl + tw, th, kr - tw, th, P, ceil_ts, True),
    )

    # -- texture libraries ---------------------------------------------------------
    ftex = cfg.facade_texel_m
    facades: list[tuple[int, float, float]] = []
    for k in range(cfg.n_facade_styles):
        w = float(r_facade.choice([12.0, 16.0, 20.0, 24.0]))
        h = float(r_facade.choice([6.5, 9.5, 12.5, 15.5, 18.5]))
        facades.append((add_tex(f"facade{k}", facade_texture(r_facade, ftex, w, h)), w, h))
    side_walls = [
        add_tex(f"endwall{k}", side_wall_texture(r_facade, ftex, 12.0, 19.0)) for k in range(3)
    ]
    trees: list[tuple[int, float, float]] = []
    for k in range(cfg.n_tree_styles):
        w, h = float(r_tree.uniform(3.5, 5.5)), float(r_tree.uniform(6.0, 9.0))
        trees.append((add_tex(f"tree{k}", tree_texture(r_tree, 0.025, w, h)), w, h))
    t_fence = add_tex("fence", fence_texture(r_tree, 0.01, 4.0, 1.4))
    sky_cols, sky_rows, step = 1200, 560, 2.5 / 1200
    horizon_row = 1.0 / step  # tan_el_max = 1.0
    t_sky = add_tex("sky", sky_texture(r_sky, sky_cols, sky_rows, horizon_row))
    sky = SkySpec(t_sky, tan_az_max=1.25, tan_el_max=1.0, step=step)

    def mean_of(tid: int) -> tuple[int, int, int]:
        return textures[tid].mean_bgr

    # -- roadside objects ----------------------------------------------------------
    qb = _QuadBuilder()
    x_lo, x_hi = -50.0, length_m + cfg.margin_m
    parked: list[VehiclePose] = []
    # a few car models for the parked cars (their textures are shared)
    models = [
        (
            VehicleShape(
                length_m=float(r_layout.uniform(4.0, 4.9)),
                width_m=float(r_layout.uniform(1.7, 1.9)),
                height_m=float(r_layout.uniform(1.4, 1.7)),
            ),
            int(r_layout.integers(1 << 30)),
        )
        for _ in range(cfg.n_parked_models)
    ]
    occupied: dict[int, list[tuple[float, float]]] = {1: [], -1: []}
    for side in (-1, 1):  # -1 right (Y < 0), +1 left
        kerb = kr if side < 0 else kl
        # parked cars first (trees avoid them)
        x = x_lo + float(r_layout.uniform(0, cfg.parked_car_spacing_m))
        while x < x_hi:
            shape, appearance = models[int(r_layout.integers(len(models)))]
            yc = kerb + side * (cfg.sidewalk_m + 0.8 + shape.width_m / 2)
            parked.append(
                VehiclePose(
                    vehicle_id=0,
                    x_m=x,
                    y_m=yc,
                    z_m=hfun(x, yc) + kh + shape.cg_height_m,
                    pitch_rad=0.0,
                    roll_rad=0.0,
                    yaw_rad=float(r_layout.normal(0, 0.03)) + (math.pi if side > 0 else 0.0),
                    shape=shape,
                    appearance=appearance,
                )
            )
            occupied[side].append((x - 3.5, x + 3.5))
            x += float(r_layout.uniform(0.5, 1.5) * cfg.parked_car_spacing_m)

        # buildings (or fences) in slots
        x = x_lo
        while x < x_hi:
            gap = float(r_layout.uniform(2.0, 14.0))
            x += gap
            if r_layout.random() < cfg.building_probability:
                tid, w, h = facades[int(r_layout.integers(len(facades)))]
                setback = float(r_layout.uniform(*cfg.setback_m))
                yf = kerb + side * setback
                depth = float(r_layout.uniform(8.0, 12.0))
                z0 = hfun(x + w / 2, yf) + kh
                qb.begin(LAYER_FACADE)
                # facade split in <= 8 m segments (mip level per segment, tighter sort)
                nseg = max(1, math.ceil(w / 8.0))
                tex_w, tex_h = textures[tid].size
                for k in range(nseg):
                    xa, xb = x + w * k / nseg, x + w * (k + 1) / nseg
                    if side < 0:  # faces +Y: seen from the road, +X runs to the left
                        c = _vertical_quad(xb, yf, xa, yf, z0, z0 + h)
                        s0, s1 = tex_w * (nseg - k - 1) / nseg, tex_w * (nseg - k) / nseg
                    else:  # faces -Y: seen from the road, +X runs to the right
                        c = _vertical_quad(xa, yf, xb, yf, z0, z0 + h)
                        s0, s1 = tex_w * k / nseg, tex_w * (k + 1) / nseg
                    qb.add(
                        c,
                        tid,
                        (s0, 0.0, s1, float(tex_h)),
                        mean_of(tid),
                        shade=0.82 if side < 0 else 1.0,
                    )
                # end walls: the one facing the approaching camera (-X) and the far one (+X)
                sid = side_walls[int(r_layout.integers(len(side_walls)))]
                sw, sh = textures[sid].size
                ds, hs = depth / ftex, h / ftex
                y_out = yf + side * depth
                y_hi, y_lo = max(yf, y_out), min(yf, y_out)
                rect = (0.0, sh - hs, min(ds, sw), float(sh))
                qb.add(_vertical_quad(x, y_hi, x, y_lo, z0, z0 + h), sid, rect, mean_of(sid), 0.7)
                qb.add(
                    _vertical_quad(x + w, y_lo, x + w, y_hi, z0, z0 + h),
                    sid,
                    rect,
                    mean_of(sid),
                    0.95,
                )
                x += w
            else:
                length = float(r_layout.uniform(8.0, 24.0))
                yfen = kerb + side * (cfg.setback_m[0] - 1.5)
                nseg = max(1, math.ceil(length / 4.0))
                fw, fh = textures[t_fence].size
                for k in range(nseg):
                    xa = x + 4.0 * k
                    xb = min(x + length, xa + 4.0)
                    z0 = hfun(xa, yfen) + kh
                    qb.begin(LAYER_FENCE)
                    c = _vertical_quad(xa, yfen, xb, yfen, z0, z0 + 1.4)
                    qb.add(
                        c,
                        t_fence,
                        (0.0, 0.0, fw * (xb - xa) / 4.0, float(fh)),
                        mean_of(t_fence),
                        two_sided=True,
                    )
                x += length

        # street trees, avoiding parked cars
        x = x_lo + float(r_layout.uniform(0, cfg.tree_spacing_m))
        while x < x_hi:
            tid, w, h = trees[int(r_layout.integers(len(trees)))]
            if not any(a < x < b for a, b in occupied[side]):
                yt = kerb + side * (cfg.sidewalk_m + float(r_layout.uniform(0.8, 2.2)))
                w = min(w, 2 * (cfg.setback_m[0] - 1.6 - abs(yt - kerb)) + 0.0) if w > 0 else w
                w = max(w, 2.0)
                z0 = hfun(x, yt) + kh
                tw_, th_ = textures[tid].size
                qb.begin(LAYER_ROADSIDE)
                # the crown plane faces the approaching camera (-X); +Y is image-left
                c = _vertical_quad(x, yt + w / 2, x, yt - w / 2, z0, z0 + h)
                qb.add(c, tid, (0.0, 0.0, float(tw_), float(th_)), mean_of(tid), two_sided=True)
            x += float(r_layout.uniform(0.6, 1.4) * cfg.tree_spacing_m)

        # street lamps: a square pole with an arm over the road
        x = x_lo + float(r_layout.uniform(0, cfg.pole_spacing_m))
        while x < x_hi:
            yp = kerb + side * 0.5
            z0 = hfun(x, yp) + kh
            hp, a = 8.0, 0.09
            qb.begin(LAYER_ROADSIDE)
            grey = (118, 122, 126)
            for (xa, ya, xb, yb), sh_ in (
                ((x - a, yp + a, x - a, yp - a), 0.7),  # face -X
                ((x + a, yp + a, x - a, yp + a), 0.95),  # face +Y
                ((x - a, yp - a, x + a, yp - a), 0.85),  # face -Y
                ((x + a, yp - a, x + a, yp + a), 0.6),  # face +X
            ):
                qb.add(_vertical_quad(xa, ya, xb, yb, z0, z0 + hp), -1, (0, 0, 1, 1), grey, sh_)
            y_end = yp - side * 2.2
            arm = np.array(
                [
                    [x - 0.06, yp, z0 + hp - 0.1],
                    [x - 0.06, y_end, z0 + hp - 0.1],
                    [x - 0.06, y_end, z0 + hp - 0.3],
                    [x - 0.06, yp, z0 + hp - 0.3],
                ]
            )
            qb.add(arm, -1, (0, 0, 1, 1), (100, 104, 108), 0.8, two_sided=True)
            lamp = np.array(
                [
                    [x - 0.25, y_end + 0.2, z0 + hp - 0.3],
                    [x - 0.25, y_end - 0.2, z0 + hp - 0.3],
                    [x - 0.25, y_end - 0.2, z0 + hp - 0.45],
                    [x - 0.25, y_end + 0.2, z0 + hp - 0.45],
                ]
            )
            qb.add(lamp, -1, (0, 0, 1, 1), (200, 215, 220), 1.0, two_sided=True)
            x += float(r_layout.uniform(0.85, 1.15) * cfg.pole_spacing_m)

    return SceneLayout(
        cfg=cfg,
        seed=seed,
        length_m=float(length_m),
        textures=tuple(textures),
        strips=strips,
        quads=qb.build(),
        parked=tuple(parked),
        sky=sky,
        far_ground_bgr=(112, 128, 124),
        tunnel_bgr=(14, 14, 16),
        road_height=hfun,
    )
