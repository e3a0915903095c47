"""The simulator's static world: procedural textures and the roadside layout, made from a seed.

`generate_scene` builds a `SceneLayout` once (textures with their mip pyramids,
road cross-section, buildings, trees, poles, fences, parked cars, sky, tunnel
lining) in world coordinates (X forward along the road, Y left, Z up; see
``docs/method.md``); `roadpreview.sim.render.SceneRenderer` draws it every
frame. Nothing here runs per frame. See ``docs/simulator-rendering.md``.
"""

from __future__ import annotations

import math
import string
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError
from roadpreview.sim.types import VehiclePose, VehicleShape

RoadHeight = Callable[[float, float], float]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

#: draw layers, back to front; objects in a higher layer are never occluded by a lower one
#: because they stand nearer the road (rays from a camera on the road cross them first)
LAYER_FACADE = 0
LAYER_FENCE = 1
LAYER_ROADSIDE = 2


@dataclass(frozen=True)
class SceneConfig:
    """How the static world is laid out and how finely its textures are sampled."""

    lane_width_m: float = param(3.5, unit="m", gt=2.0, le=5.0, help="typical European lane")
    shoulder_m: float = param(
        0.75, unit="m", ge=0.0, le=3.0, help="asphalt between edge line and kerb"
    )
    kerb_height_m: float = param(0.12, unit="m", ge=0.0, le=0.3, help="usual urban kerb")
    sidewalk_m: float = param(2.5, unit="m", gt=0.5, le=6.0, help="paved strip behind the kerb")
    verge_m: float = param(13.0, unit="m", gt=4.0, le=40.0, help="textured ground behind the kerb")
    road_texel_m: float = param(
        0.015, unit="m", gt=0.002, le=0.1, help="asphalt grain stays sharp down to ~5 m at 720p"
    )
    ground_texel_m: float = param(0.04, unit="m", gt=0.005, le=0.2, help="sidewalk and grass")
    facade_texel_m: float = param(0.04, unit="m", gt=0.005, le=0.2, help="window frames ~2 texels")
    texture_period_m: float = param(
        48.0,
        unit="m",
        gt=12.0,
        le=200.0,
        help="road texture repeats this often; a multiple of the 12 m dash cycle",
    )
    dash_length_m: float = param(3.0, unit="m", gt=0.5, help="centre-line dash")
    dash_gap_m: float = param(9.0, unit="m", gt=0.5, help="centre-line gap (3 + 9 = 12 m cycle)")
    building_probability: float = param(
        0.8, ge=0.0, le=1.0, help="share of roadside slots with a building rather than a fence"
    )
    setback_m: tuple[float, float] = param(
        (8.0, 11.0), unit="m", help="facade distance from the kerb (min, max)"
    )
    tree_spacing_m: float = param(14.0, unit="m", gt=2.0, help="mean gap between street trees")
    pole_spacing_m: float = param(32.0, unit="m", gt=5.0, help="street lamps")
    parked_car_spacing_m: float = param(45.0, unit="m", gt=6.0, help="mean gap between parked cars")
    n_facade_styles: int = param(8, ge=1, le=32, help="distinct facade textures")
    n_tree_styles: int = param(4, ge=1, le=16, help="distinct tree textures")
    n_parked_models: int = param(6, ge=1, le=64, help="distinct parked-car models")
    margin_m: float = param(
        320.0, unit="m", ge=0.0, help="objects extend this far past the drive (draw distance)"
    )
    tunnel_width_m: float = param(
        0.5, unit="m", ge=0.1, help="walkway between kerb and tunnel wall"
    )
    tunnel_height_m: float = param(5.5, unit="m", gt=3.0, help="ceiling above the road")
    tunnel_light_spacing_m: float = param(8.0, unit="m", gt=1.0, help="ceiling lamps")

    def validate(self, where: str = "SceneConfig") -> None:
        check_ranges(self, where)
        lo, hi = self.setback_m
        if not 2.0 <= lo <= hi:
            raise ConfigError(f"{where}.setback_m = {self.setback_m}: need 2 <= min <= max")
        cycle = self.dash_length_m + self.dash_gap_m
        if abs(self.texture_period_m / cycle - round(self.texture_period_m / cycle)) > 1e-9:
            raise ConfigError(
                f"{where}.texture_period_m = {self.texture_period_m} m must be a multiple of the "
                f"dash cycle {cycle} m (dash_length_m + dash_gap_m)"
            )

    # -- cross-section --------------------------------------------------------------
    @property
    def kerb_right_y(self) -> float:
        """Y of the right kerb (the ego lane is centred at Y = 0)."""
        return -(0.5 * self.lane_width_m + self.shoulder_m)

    @property
    def kerb_left_y(self) -> float:
        """Y of the left kerb, beyond the oncoming lane centred at Y = lane width."""
        return 1.5 * self.lane_width_m + self.shoulder_m


# ----------------------------------------------------------------------------------------
# Textures
# ----------------------------------------------------------------------------------------
_PYR_KERNEL = np.array([1.0, 3.0, 3.0, 1.0], dtype=np.float32) / 8.0


def _pyr_down(img: U8) -> U8:
    """Half-size image whose pixel i is centred on level-0 coordinate 2i + 0.5.

    `cv2.pyrDown` centres pixel i on 2i, which would shift coarser levels by
    half a texel per level; an even [1 3 3 1]/8 kernel keeps every level
    aligned with the texel-edge convention the renderer uses.
    """
    blurred = cv2.sepFilter2D(img, -1, _PYR_KERNEL, _PYR_KERNEL, anchor=(1, 1))
    return np.ascontiguousarray(blurred[::2, ::2])


@dataclass(frozen=True)
class Texture:
    """A texture with its mip pyramid (BGR, or BGRA with a binary-ish alpha)."""

    name: str
    levels: tuple[U8, ...]
    has_alpha: bool
    mean_bgr: tuple[int, int, int]

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of level 0 in texels."""
        return (int(self.levels[0].shape[1]), int(self.levels[0].shape[0]))

    @classmethod
    def build(cls, name: str, image: U8, *, min_size: int = 4) -> Texture:
        """Wrap ``image`` (H, W, 3|4) uint8 and precompute its pyramid."""
        img = np.ascontiguousarray(image, dtype=np.uint8)
        if img.ndim != 3 or img.shape[2] not in (3, 4):
            raise ValueError(f"texture {name}: need (H, W, 3|4) uint8, got {img.shape}")
        levels = [img]
        while min(levels[-1].shape[:2]) >= 2 * min_size:
            levels.append(_pyr_down(levels[-1]))
        rgb = img[..., :3].reshape(-1, 3)
        if img.shape[2] == 4:
            sel = img[..., 3].reshape(-1) > 127
            rgb = rgb[sel] if np.any(sel) else rgb
        mean = rgb.mean(axis=0)
        return cls(
            name=name,
            levels=tuple(levels),
            has_alpha=img.shape[2] == 4,
            mean_bgr=(int(mean[0]), int(mean[1]), int(mean[2])),
        )


def _divisor_near(n: int, target: int) -> int:
    """The divisor of n nearest to target (so periodic noise tiles exactly)."""
    divs = np.array([d for d in range(1, n + 1) if n % d == 0])
    return int(divs[np.argmin(np.abs(np.log(divs / max(target, 1))))])


def _value_noise(rng: np.random.Generator, rows: int, cols: int, cell: int, periodic: bool) -> F32:
    """Smooth noise with unit standard deviation and feature size ~``cell`` texels.

    With ``periodic`` the columns wrap exactly (the texture tiles along the road).
    """
    if periodic:
        cell = _divisor_near(cols, cell)
        nc = cols // cell
    else:
        cell = max(1, cell)
        nc = cols // cell + 3
    nr = rows // cell + 3
    grid = rng.standard_normal((nr, nc)).astype(np.float32)
    if periodic:
        grid = np.concatenate([grid[:, -2:], grid, grid[:, :2]], axis=1)
    up = cv2.resize(grid, (grid.shape[1] * cell, nr * cell), interpolation=cv2.INTER_CUBIC)
    c0 = 2 * cell if periodic else cell
    out = up[cell : cell + rows, c0 : c0 + cols]
    std = float(out.std()) or 1.0
    return np.ascontiguousarray(out / std, dtype=np.float32)


def _fbm(
    rng: np.random.Generator,
    rows: int,
    cols: int,
    octaves: Sequence[tuple[int, float]],
    periodic: bool = False,
) -> F32:
    """Sum of value-noise octaves given as (cell size in texels, amplitude)."""
    out = np.zeros((rows, cols), np.float32)
    for cell, amp in octaves:
        out += amp * _value_noise(rng, rows, cols, cell, periodic)
    return out


def _speckle(rng: np.random.Generator, rows: int, cols: int, density: float) -> F32:
    """Sparse +-1 specks (aggregate stones), one texel each, slightly blurred."""
    n = int(density * rows * cols)
    img = np.zeros((rows, cols), np.float32)
    r = rng.integers(0, rows, n)
    c = rng.integers(0, cols, n)
    img[r, c] = rng.choice(np.array([-1.0, 1.0], np.float32), n) * rng.uniform(0.5, 1.0, n).astype(
        np.float32
    )
    return np.asarray(cv2.GaussianBlur(img, (3, 3), 0.6), np.float32)


def _colourise(base_bgr: Sequence[float], shade: F32) -> U8:
    """base colour * (1 + shade) per channel, clipped to uint8."""
    base = np.asarray(base_bgr, np.float32).reshape(1, 1, 3)
    return np.clip(base * (1.0 + shade[..., None]), 0, 255).astype(np.uint8)


def _wrapped(cols: int, xs: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Copies of a shape's x coordinates shifted by -cols, 0, +cols (seamless tiling)."""
    return [xs - cols, xs, xs + cols]


def _road_texture(cfg: SceneConfig, rng: np.random.Generator) -> tuple[U8, float, float]:
    """Asphalt with grain, aggregate, cracks, patches, wheel tracks and lane markings.

    Rows run from the left kerb (row 0) to the right kerb; columns along +X over one
    period. Returns (image, texel along X, texel along Y).
    """
    y_top, y_bot = cfg.kerb_left_y, cfg.kerb_right_y
    rows = round((y_top - y_bot) / cfg.road_texel_m)
    cols = round(cfg.texture_period_m / cfg.road_texel_m)
    ts, tt = cfg.texture_period_m / cols, (y_top - y_bot) / rows

    def row(y: float) -> float:
        return (y_top - y) / tt

    shade = _fbm(rng, rows, cols, [(400, 0.05), (90, 0.05), (18, 0.04), (4, 0.05)], True)
    shade += 0.35 * _speckle(rng, rows, cols, 0.05)
    shade += 0.12 * _speckle(rng, rows, cols, 0.15)
    # polished wheel tracks in both lanes (slightly darker, smoother)
    yy = (y_top - (np.arange(rows) + 0.5) * tt).astype(np.float32)
    for centre in (0.0, cfg.lane_width_m):
        for off in (-0.8, 0.8):
            shade -= (0.06 * np.exp(-(((yy - centre - off) / 0.3) ** 2)))[:, None]
    img = _colourise((92, 94, 96), shade)

    # patches (resealed rectangles) with darker joints
    n_patches = max(1, round(cfg.texture_period_m / 14.0))
    for _ in range(n_patches):
        x0 = rng.uniform(0, cols)
        w = rng.uniform(0.8, 3.5) / ts
        y0 = rng.uniform(y_bot + 0.5, y_top - 1.5)
        h = rng.uniform(0.6, 2.0) / tt
        tone = rng.uniform(0.72, 0.9)
        for xs in _wrapped(cols, np.array([x0, x0 + w, x0 + w, x0])):
            pts = np.stack([xs, np.array([row(y0), row(y0), row(y0) - h, row(y0) - h])], axis=1)
            poly = np.round(pts * 16).astype(np.int32)
            patch = np.zeros((rows, cols), np.uint8)
            cv2.fillConvexPoly(patch, poly, 255, lineType=cv2.LINE_AA, shift=4)
            m = patch.astype(np.float32)[..., None] / 255.0
            img = (img * (1 - m) + img * tone * m).astype(np.uint8)
            cv2.polylines(img, [poly], True, (45, 46, 48), 2, cv2.LINE_AA, shift=4)

    # cracks: random walks, mostly along the road, some transverse
    n_cracks = round(cfg.texture_period_m / 3.0)
    for _ in range(n_cracks):
        n = int(rng.integers(8, 40))
        ang0 = rng.choice([0.0, math.pi / 2]) + rng.normal(0, 0.3)
        ang = ang0 + np.cumsum(rng.normal(0, 0.35, n))
        step = rng.uniform(0.04, 0.1) / ts
        xs = rng.uniform(0, cols) + np.cumsum(step * np.cos(ang))
        ys = rng.uniform(0, rows) + np.cumsum(step * np.sin(ang) * ts / tt)
        for xw in _wrapped(cols, xs):
            pts = np.round(np.stack([xw, ys], axis=1) * 16).astype(np.int32)
            cv2.polylines(img, [pts], False, (38, 38, 40), 1, cv2.LINE_AA, shift=4)

    # lane markings (paint with wear)
    paint = np.zeros((rows, cols), np.uint8)

    def stripe(x0: float, x1: float, yc: float, width: float) -> None:
        r0, r1 = row(yc + width / 2), row(yc - width / 2)
        for xs in _wrapped(cols, np.array([x0 / ts, x1 / ts, x1 / ts, x0 / ts])):
            pts = np.stack([xs, np.array([r0, r0, r1, r1])], axis=1)
            cv2.fillConvexPoly(
                paint, np.round(pts * 16).astype(np.int32), 255, lineType=cv2.LINE_AA, shift=4
            )

    stripe(0.0, cfg.texture_period_m, -0.5 * cfg.lane_width_m, 0.15)
    stripe(0.0, cfg.texture_period_m, 1.5 * cfg.lane_width_m, 0.15)
    cycle = cfg.dash_length_m + cfg.dash_gap_m
    for k in range(round(cfg.texture_period_m / cycle)):
        stripe(k * cycle, k * cycle + cfg.dash_length_m, 0.5 * cfg.lane_width_m, 0.12)
    wear = np.clip(0.85 + 0.25 * _fbm(rng, rows, cols, [(30, 0.6), (5, 0.4)], True), 0.0, 1.0)
    a = (paint.astype(np.float32) / 255.0 * wear)[..., None]
    white = np.array([222, 226, 228], np.float32).reshape(1, 1, 3)
    img = (img.astype(np.float32) * (1 - a) + white * a).astype(np.uint8)
    return img, ts, tt


def _verge_texture(
    cfg: SceneConfig, rng: np.random.Generator, left: bool
) -> tuple[U8, float, float]:
    """Paving slabs by the kerb, then a gravel strip and grass; row 0 at the kerb side
    nearest the left (i.e. rows run towards -Y like the road texture)."""
    width = cfg.verge_m
    rows = round(width / cfg.ground_texel_m)
    cols = round(cfg.texture_period_m / cfg.ground_texel_m)
    ts, tt = cfg.texture_period_m / cols, width / rows
    # distance from the kerb for each row
    d = (np.arange(rows) + 0.5) * tt
    if left:
        d = d[::-1]  # left verge: row 0 is the outer edge (largest Y), the last row the kerb
    d = d.astype(np.float32)
    grass = _colourise(
        (48, 104, 82), _fbm(rng, rows, cols, [(60, 0.12), (10, 0.12), (2, 0.18)], True)
    )
    gravel = _colourise((120, 128, 136), _fbm(rng, rows, cols, [(20, 0.06), (1, 0.22)], True))
    slab_shade = _fbm(rng, rows, cols, [(40, 0.05), (2, 0.06)], True)
    slabs = _colourise((150, 156, 160), slab_shade)
    # slab joints every 0.5 m (along X) x 0.5 m (across), staggered per course
    xs = (np.arange(cols) + 0.5) * ts
    course = np.floor(d / 0.5).astype(np.int32)
    jx = ((xs[None, :] + 0.25 * (course[:, None] % 2)) % 0.5) < 0.02
    jy = (d % 0.5)[:, None] < 0.02
    slabs[jx | jy] = (96, 100, 104)
    # individual slab tone
    tone = rng.uniform(0.9, 1.1, (int(d.max() / 0.5) + 2, int(cfg.texture_period_m / 0.5) + 2))
    sx = np.floor((xs[None, :] + 0.25 * (course[:, None] % 2)) / 0.5).astype(np.int32) % (
        tone.shape[1] - 1
    )
    slabs = np.clip(slabs * tone[course[:, None], sx][..., None], 0, 255).astype(np.uint8)
    img = grass.copy()
    sel_slab = d < cfg.sidewalk_m
    sel_gravel = (d >= cfg.sidewalk_m) & (d < cfg.sidewalk_m + 0.6)
    img[sel_slab] = slabs[sel_slab]
    img[sel_gravel] = gravel[sel_gravel]
    return img, ts, tt


def _kerb_texture(cfg: SceneConfig, rng: np.random.Generator) -> tuple[U8, float, float]:
    """Concrete kerb stones 1 m long (the kerb's vertical face)."""
    texel = 0.01
    rows = max(4, round(cfg.kerb_height_m / texel))
    cols = round(cfg.texture_period_m / texel)
    img = _colourise((168, 172, 175), _fbm(rng, rows, cols, [(20, 0.05), (1, 0.08)], True))
    xs = np.arange(cols) * texel
    img[:, (xs % 1.0) < 0.012] = (90, 92, 95)
    img[-2:, :] = (60, 62, 64)
    return img, cfg.texture_period_m / cols, cfg.kerb_height_m / rows


def _facade_texture(rng: np.random.Generator, texel: float, width_m: float, height_m: float) -> U8:
    """A building front: wall with grain, floors of framed windows, a ground-floor shop band."""
    cols, rows = round(width_m / texel), round(height_m / texel)
    palette = [
        (180, 196, 214),
        (150, 160, 170),
        (120, 140, 190),
        (200, 205, 205),
        (90, 110, 150),
        (170, 180, 150),
        (140, 150, 160),
        (205, 215, 225),
    ]
    base = palette[int(rng.integers(len(palette)))]
    img = _colourise(base, _fbm(rng, rows, cols, [(80, 0.05), (12, 0.04), (1, 0.05)]))
    if rng.random() < 0.4:  # brick courses
        yy = np.arange(rows) * texel
        img[(yy % 0.3) < 0.025] = np.clip(np.asarray(base) * 0.75, 0, 255).astype(np.uint8)

    def px(v: float) -> int:
        return round(v / texel)

    floor_h = rng.uniform(2.8, 3.4)
    win_w, win_h = rng.uniform(0.9, 1.6), rng.uniform(1.2, 1.7)
    pitch = rng.uniform(win_w + 0.8, win_w + 2.2)
    frame_col = (235, 235, 235) if rng.random() < 0.6 else (60, 60, 70)
    n_cols = max(1, int((width_m - 1.0) // pitch))
    x_start = 0.5 * (width_m - (n_cols - 1) * pitch)
    ground = rng.random() < 0.6
    n_floors = max(1, int((height_m - 0.8) // floor_h))
    for f in range(n_floors):
        y_bottom = height_m - f * floor_h - 0.9  # sill above this floor's level
        if f == 0 and ground:
            # shop front: large dark glazing with mullions and a door
            y0, y1 = height_m - 3.0, height_m - 0.3
            cv2.rectangle(img, (px(0.6), px(y0)), (px(width_m - 0.6), px(y1)), (50, 45, 40), -1)
            for k in range(int((width_m - 1.2) // 2.0) + 1):
                xm = 0.6 + k * 2.0
                cv2.line(img, (px(xm), px(y0)), (px(xm), px(y1)), (170, 170, 170), 2)
            cv2.rectangle(
                img,
                (px(0.6), px(y0 - 0.5)),
                (px(width_m - 0.6), px(y0 - 0.1)),
                tuple(int(c) for c in rng.integers(30, 220, 3)),
                -1,
            )
            continue
        y1 = y_bottom
        y0 = y1 - win_h
        if y0 < 0.3:
            break
        for k in range(n_cols):
            xc = x_start + k * pitch
            x0, x1 = xc - win_w / 2, xc + win_w / 2
            glass = np.array([90, 80, 70]) + rng.integers(-25, 40, 3)
            if rng.random() < 0.3:  # sky reflection
                glass = np.array([170, 150, 120]) + rng.integers(-20, 20, 3)
            p0, p1 = (px(x0), px(y0)), (px(x1), px(y1))
            cv2.rectangle(img, p0, p1, frame_col, -1)
            cv2.rectangle(
                img,
                (p0[0] + 2, p0[1] + 2),
                (p1[0] - 2, p1[1] - 2),
                tuple(int(c) for c in glass),
                -1,
            )
            xm = (p0[0] + p1[0]) // 2
            cv2.line(img, (xm, p0[1]), (xm, p1[1]), frame_col, 1)
            if rng.random() < 0.35:  # curtain
                cv2.rectangle(
                    img,
                    (p0[0] + 2, p0[1] + 2),
                    (xm - 1, p0[1] + (p1[1] - p0[1]) // 2),
                    tuple(int(c) for c in rng.integers(120, 240, 3)),
                    -1,
                )
            cv2.line(img, (p0[0] - 2, p1[1] + 1), (p1[0] + 2, p1[1] + 1), (200, 200, 200), 2)
    # cornice and plinth
    cv2.rectangle(img, (0, 0), (cols - 1, px(0.35)), (110, 115, 120), -1)
    cv2.rectangle(img, (0, rows - px(0.3)), (cols - 1, rows - 1), (80, 84, 90), -1)
    return img


def _side_wall_texture(
    rng: np.random.Generator, texel: float, depth_m: float, height_m: float
) -> U8:
    """A building's end wall: plaster with a few small windows."""
    cols, rows = max(8, round(depth_m / texel)), max(8, round(height_m / texel))
    base = (int(rng.integers(120, 200)), int(rng.integers(120, 200)), int(rng.integers(120, 210)))
    img = _colourise(base, _fbm(rng, rows, cols, [(60, 0.06), (8, 0.04), (1, 0.04)]))
    for _ in range(int(rng.integers(0, 5))):
        x0 = rng.uniform(0.5, max(0.6, depth_m - 1.2))
        y0 = rng.uniform(0.5, max(0.6, height_m - 2.0))
        cv2.rectangle(
            img,
            (round(x0 / texel), round(y0 / texel)),
            (round((x0 + 0.8) / texel), round((y0 + 1.1) / texel)),
            (70, 65, 60),
            -1,
        )
    cv2.rectangle(img, (0, rows - round(0.3 / texel)), (cols - 1, rows - 1), (80, 84, 90), -1)
    return img


def _tree_texture(rng: np.random.Generator, texel: float, width_m: float, height_m: float) -> U8:
    """A street tree seen from the road: trunk and a leafy crown, BGRA (alpha = foliage)."""
    cols, rows = round(width_m / texel), round(height_m / texel)
    crown_h = height_m * rng.uniform(0.55, 0.72)
    alpha = np.zeros((rows, cols), np.float32)
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float32) * texel
    for _ in range(int(rng.integers(5, 9))):
        cx = rng.uniform(0.3, 0.7) * width_m
        cy = rng.uniform(0.15, 0.75) * crown_h
        r = rng.uniform(0.22, 0.38) * width_m
        alpha = np.maximum(alpha, 1.0 - ((xx - cx) ** 2 + (yy - cy) ** 2) / r**2)
    alpha += 0.45 * _fbm(rng, rows, cols, [(max(2, round(0.5 / texel)), 0.6), (3, 0.4)])
    leaves = alpha > 0.25
    shade = _fbm(rng, rows, cols, [(round(0.8 / texel), 0.12), (3, 0.2), (1, 0.15)])
    shade -= 0.35 * (yy / crown_h)  # lower crown in its own shadow
    greens = [(40, 110, 70), (50, 120, 90), (35, 95, 60), (60, 130, 110)]
    img = _colourise(greens[int(rng.integers(len(greens)))], shade)
    bgra = np.zeros((rows, cols, 4), np.uint8)
    bgra[..., :3] = img
    bgra[..., 3] = np.where(leaves, 255, 0).astype(np.uint8)
    # trunk
    tw = rng.uniform(0.25, 0.4)
    x0, x1 = round((width_m - tw) / 2 / texel), round((width_m + tw) / 2 / texel)
    y0 = round(crown_h * 0.7 / texel)
    trunk = _colourise((50, 70, 90), _fbm(rng, rows - y0, x1 - x0, [(4, 0.15), (1, 0.1)]))
    under = bgra[y0:, x0:x1]
    keep = under[..., 3] > 0
    trunk_bgra = np.concatenate([trunk, np.full((*trunk.shape[:2], 1), 255, np.uint8)], axis=2)
    under[~keep] = trunk_bgra[~keep]
    return bgra


def _fence_texture(rng: np.random.Generator, texel: float, length_m: float, height_m: float) -> U8:
    """Wooden picket fence, BGRA (gaps between slats transparent)."""
    cols, rows = round(length_m / texel), round(height_m / texel)
    img = _colourise((70, 110, 150), _fbm(rng, rows, cols, [(6, 0.1), (1, 0.08)]))
    alpha = np.zeros((rows, cols), np.uint8)
    slat, gap = 0.1, 0.05
    xs = np.arange(cols) * texel
    alpha[:, (xs % (slat + gap)) < slat] = 255
    for yr in (0.25, 0.8):  # rails
        r0 = round(yr * height_m / texel)
        alpha[r0 : r0 + round(0.08 / texel), :] = 255
        img[r0 : r0 + round(0.08 / texel), :] = (50, 80, 110)
    # pointed tops
    tip = round(0.08 / texel)
    for k in range(tip):
        alpha[k, np.abs((xs % (slat + gap)) - slat / 2) > (k + 1) / tip * slat / 2] = 0
    return np.dstack([img, alpha])


def _sky_texture(rng: np.random.Generator, cols: int, rows: int, horizon_row: float) -> U8:
    """Blue gradient with soft clouds above the horizon, hazy far ground below it."""
    t = np.clip((horizon_row - np.arange(rows, dtype=np.float32)) / horizon_row, -1.0, 1.0)
    top = np.array([200, 150, 95], np.float32)  # BGR deep blue
    hor = np.array([228, 214, 196], np.float32)
    ground = np.array([120, 135, 130], np.float32)
    k = np.clip(t, 0, 1)[:, None, None] ** 0.6
    sky = hor * (1 - k) + top * k
    below = (t < 0)[:, None, None]
    sky = np.where(below, ground + (hor - ground) * np.exp(8 * t)[:, None, None], sky)
    img = np.broadcast_to(sky, (rows, cols, 3)).astype(np.float32).copy()
    clouds = _fbm(rng, rows, cols, [(120, 0.6), (40, 0.3), (12, 0.15), (4, 0.08)])
    cover = np.clip((clouds - 0.3) * 1.2, 0, 1) * np.clip(t * 4, 0, 1)[:, None]
    white = np.array([245, 243, 240], np.float32)
    img = img * (1 - cover[..., None]) + white * cover[..., None]
    img *= (1.0 - 0.12 * np.clip(clouds - 0.8, 0, 1))[..., None]  # cloud undersides
    return np.clip(img, 0, 255).astype(np.uint8)


def _tunnel_texture(
    rng: np.random.Generator, period_m: float, height_m: float, texel: float
) -> tuple[U8, float, float]:
    """Dark, smooth concrete lining with faint panel joints (little to track on)."""
    rows = max(8, round(height_m / texel))
    cols = round(period_m / texel)
    img = _colourise((58, 60, 62), _fbm(rng, rows, cols, [(60, 0.05), (6, 0.02)], True))
    xs = np.arange(cols) * (period_m / cols)
    img[:, (xs % 6.0) < 0.03] = (52, 54, 56)
    return img, period_m / cols, height_m / rows


# ----------------------------------------------------------------------------------------
# Vehicle textures
# ----------------------------------------------------------------------------------------
_BODY_COLOURS = [
    (235, 235, 235),
    (190, 190, 192),
    (30, 30, 32),
    (40, 40, 180),
    (150, 80, 30),
    (90, 90, 95),
    (60, 110, 60),
    (20, 140, 220),
    (120, 40, 40),
    (160, 170, 180),
]


@dataclass(frozen=True)
class VehicleTextures:
    """Faces of one vehicle's body box. ``rear``/``front``: width x body height;
    ``side``: length x body height (front of the car at the right). Lamp rectangles
    are (x0, y0, x1, y1) fractions of the rear/front face, for night-time emission."""

    rear: Texture
    front: Texture
    side: Texture
    body_bgr: tuple[int, int, int]
    tail_lamps: tuple[tuple[float, float, float, float], ...]
    head_lamps: tuple[tuple[float, float, float, float], ...]


def _plate(rng: np.random.Generator, w: int, h: int) -> U8:
    """A white EU-style number plate with black characters."""
    plate = np.full((h, w, 3), 238, np.uint8)
    cv2.rectangle(plate, (0, 0), (w - 1, h - 1), (20, 20, 20), max(1, h // 14))
    strip = max(2, w // 11)
    plate[1:-1, 1:strip] = (150, 50, 10)
    letters = string.ascii_uppercase.replace("O", "").replace("I", "")
    txt = (
        f"{int(rng.integers(1, 10))}"
        + "".join(rng.choice(list(letters), 2))
        + " "
        + "".join(str(int(d)) for d in rng.integers(0, 10, 4))
    )
    scale = cv2.getFontScaleFromHeight(cv2.FONT_HERSHEY_DUPLEX, int(h * 0.62), 2)
    (tw, th), _ = cv2.getTextSize(txt, cv2.FONT_HERSHEY_DUPLEX, scale, 2)
    sx = (w - strip - tw) // 2 + strip
    cv2.putText(
        plate,
        txt,
        (max(strip + 1, sx), (h + th) // 2),
        cv2.FONT_HERSHEY_DUPLEX,
        scale,
        (15, 15, 15),
        2,
        cv2.LINE_AA,
    )
    return plate


def make_vehicle_textures(appearance: int, shape: VehicleShape) -> VehicleTextures:
    """Procedural, deterministic faces for a vehicle of the given appearance seed.

    The rear has a rear window with a reflection, tail lights with reflector
    structure, a number plate with characters, a bumper with a crease and
    reflectors and vertical shading, so that point grids a few pixels apart and
    LK tracking find gradients in both directions.
    """
    rng = np.random.default_rng(np.random.SeedSequence([appearance & 0xFFFFFFFF, 0x7EC1]))
    body = _BODY_COLOURS[int(rng.integers(len(_BODY_COLOURS)))]
    body_h = max(0.3, shape.height_m - shape.ground_clearance_m)
    texel = 0.005
    W, H = max(16, round(shape.width_m / texel)), max(16, round(body_h / texel))

    def y(f: float) -> int:
        return round(f * H)

    def x(f: float) -> int:
        return round(f * W)

    vshade = np.linspace(0.12, -0.18, H, dtype=np.float32)[:, None] * np.ones((1, W), np.float32)
    hshade = -0.1 * (np.linspace(-1, 1, W, dtype=np.float32) ** 4)[None, :]
    grain = _fbm(rng, H, W, [(40, 0.015), (2, 0.025)])
    dark = tuple(int(c * 0.5) for c in body)

    def face(kind: str) -> tuple[U8, tuple[tuple[float, float, float, float], ...]]:
        img = _colourise(body, vshade + hshade + grain)
        win_top, win_bot = 0.07, 0.42 if kind == "rear" else 0.45
        # window (trapezoid: narrower at the top) with a sky reflection gradient
        pts = np.array(
            [
                [x(0.16), y(win_top)],
                [x(0.84), y(win_top)],
                [x(0.93), y(win_bot)],
                [x(0.07), y(win_bot)],
            ],
            np.int32,
        )
        wmask = np.zeros((H, W), np.uint8)
        cv2.fillConvexPoly(wmask, pts, 255, cv2.LINE_AA)
        refl = np.linspace(1.0, 0.0, H, dtype=np.float32)[:, None] ** 2
        glass = np.dstack([40 + 90 * refl, 38 + 80 * refl, 35 + 60 * refl]) * np.ones((1, W, 1))
        glass += 12 * _fbm(rng, H, W, [(30, 0.7), (6, 0.3)])[..., None]
        a = (wmask.astype(np.float32) / 255.0)[..., None]
        img = (img * (1 - a) + np.clip(glass, 0, 255) * a).astype(np.uint8)
        cv2.polylines(img, [pts], True, (20, 20, 20), max(1, W // 150), cv2.LINE_AA)
        if kind == "rear":  # wiper and third brake light
            cv2.line(img, (x(0.5), y(win_bot) - 2), (x(0.3), y(win_bot - 0.12)), (15, 15, 15), 2)
            cv2.rectangle(
                img, (x(0.42), y(win_top) + 2), (x(0.58), y(win_top) + 6), (30, 30, 170), -1
            )
        lamps: list[tuple[float, float, float, float]] = []
        ly0, ly1 = win_bot + 0.05, win_bot + 0.2
        for lx0, lx1 in ((0.03, 0.25), (0.75, 0.97)):
            p0, p1 = (x(lx0), y(ly0)), (x(lx1), y(ly1))
            cv2.rectangle(img, p0, p1, (180, 180, 185), -1)  # chrome rim
            inner0, inner1 = (p0[0] + 3, p0[1] + 3), (p1[0] - 3, p1[1] - 3)
            if kind == "rear":
                cv2.rectangle(img, inner0, inner1, (30, 25, 165), -1)
                midx = (inner0[0] + inner1[0]) // 2
                cv2.rectangle(
                    img, (midx - 4, inner0[1] + 2), (midx + 4, inner1[1] - 2), (60, 60, 230), -1
                )
                cv2.rectangle(
                    img,
                    (inner0[0] + 2, inner1[1] - 8),
                    (inner0[0] + 14, inner1[1] - 2),
                    (210, 210, 215),
                    -1,
                )  # reversing lamp
                for k in range(inner0[1] + 4, inner1[1] - 2, 5):  # reflector ribs
                    cv2.line(img, (inner0[0] + 1, k), (inner1[0] - 1, k), (20, 15, 130), 1)
            else:
                cv2.rectangle(img, inner0, inner1, (210, 215, 220), -1)
                cx_, cy_ = (inner0[0] + inner1[0]) // 2, (inner0[1] + inner1[1]) // 2
                cv2.circle(
                    img, (cx_, cy_), max(2, (inner1[1] - inner0[1]) // 3), (250, 250, 250), -1
                )
                cv2.circle(
                    img, (cx_, cy_), max(2, (inner1[1] - inner0[1]) // 3), (120, 120, 120), 1
                )
            lamps.append((lx0, ly0, lx1, ly1))
        if kind == "front":  # grille
            g0, g1 = (x(0.3), y(ly0)), (x(0.7), y(ly1 + 0.04))
            cv2.rectangle(img, g0, g1, (25, 25, 28), -1)
            for k in range(g0[1] + 4, g1[1], 7):
                cv2.line(img, (g0[0] + 2, k), (g1[0] - 2, k), (90, 90, 95), 2)
        else:  # badge
            cv2.ellipse(
                img, (x(0.5), y(ly0 + 0.07)), (x(0.05), y(0.025)), 0, 0, 360, (200, 200, 205), 2
            )
        # number plate 0.52 x 0.11 m
        pw, ph = round(0.52 / texel), round(0.11 / texel)
        px0, py0 = (W - pw) // 2, y(ly1 + 0.06)
        if py0 + ph < H - 4 and pw < W:
            img[py0 : py0 + ph, px0 : px0 + pw] = _plate(rng, pw, ph)
        # bumper with crease and reflectors, dark sill
        b0 = y(0.8)
        bumper = dark if rng.random() < 0.5 else tuple(int(c * 0.85) for c in body)
        img[b0 : y(0.97)] = (img[b0 : y(0.97)] * 0.3 + np.asarray(bumper) * 0.7).astype(np.uint8)
        cv2.line(img, (x(0.02), b0), (x(0.98), b0), (25, 25, 25), 2, cv2.LINE_AA)
        cv2.line(img, (x(0.05), y(0.9)), (x(0.95), y(0.9)), (60, 60, 60), 1, cv2.LINE_AA)
        if kind == "rear":
            for rx in (0.08, 0.86):
                cv2.rectangle(img, (x(rx), y(0.86)), (x(rx + 0.06), y(0.89)), (20, 20, 150), -1)
            cv2.circle(img, (x(0.22), y(0.985)), max(2, W // 60), (25, 25, 25), -1)  # exhaust
        img[y(0.97) :] = (18, 18, 18)
        return img, tuple(lamps)

    rear, tail = face("rear")
    front, head = face("front")

    L = max(16, round(shape.length_m / 0.01))
    sh = max(8, round(body_h / 0.01))
    side = _colourise(
        body,
        np.linspace(0.1, -0.15, sh, dtype=np.float32)[:, None]
        + _fbm(rng, sh, L, [(30, 0.015), (2, 0.02)]),
    )
    # windows (front of the car at the right), B-pillar, door seams, handles, wheel arches
    w_top, w_bot = round(0.07 * sh), round(0.42 * sh)
    xa, xb = round(0.2 * L), round(0.8 * L)
    cv2.rectangle(side, (xa, w_top), (xb, w_bot), (50, 45, 40), -1)
    cv2.line(side, ((xa + xb) // 2, w_top), ((xa + xb) // 2, w_bot), (20, 20, 20), 4)
    for fx in (0.3, 0.52, 0.74):
        cv2.line(side, (round(fx * L), w_bot), (round(fx * L), round(0.85 * sh)), (25, 25, 25), 1)
        cv2.rectangle(
            side,
            (round((fx + 0.03) * L), round(0.5 * sh)),
            (round((fx + 0.07) * L), round(0.54 * sh)),
            (30, 30, 30),
            -1,
        )
    r = round(0.38 / 0.01)
    for ax in (0.9, shape.length_m - 0.9):
        cv2.circle(side, (round(ax / 0.01), sh + r // 3), r, (15, 15, 15), -1)
    side[-3:] = (18, 18, 18)
    return VehicleTextures(
        rear=Texture.build(f"vehicle{appearance}-rear", rear),
        front=Texture.build(f"vehicle{appearance}-front", front),
        side=Texture.build(f"vehicle{appearance}-side", side),
        body_bgr=body,
        tail_lamps=tail,
        head_lamps=head,
    )


# ----------------------------------------------------------------------------------------
# Layout
# ----------------------------------------------------------------------------------------
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

    road_img, road_ts, _ = _road_texture(cfg, r_tex)
    t_road = add_tex("road", doubled(road_img))
    vr_img, v_ts, _ = _verge_texture(cfg, r_tex, left=False)
    t_vr = add_tex("verge-right", doubled(vr_img))
    vl_img, _, _ = _verge_texture(cfg, r_tex, left=True)
    t_vl = add_tex("verge-left", doubled(vl_img))
    kerb_img, kerb_ts, _ = _kerb_texture(cfg, r_tex)
    t_kerb = add_tex("kerb", doubled(kerb_img))
    tun_img, tun_ts, _ = _tunnel_texture(r_tex, cfg.texture_period_m, cfg.tunnel_height_m, 0.04)
    t_tun = add_tex("tunnel-wall", doubled(tun_img))
    ceil_w = cfg.kerb_left_y - cfg.kerb_right_y + 2 * cfg.tunnel_width_m
    ceil_img, ceil_ts, _ = _tunnel_texture(r_tex, cfg.texture_period_m, ceil_w, 0.04)
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
        facades.append((add_tex(f"facade{k}", _facade_texture(r_facade, ftex, w, h)), w, h))
    side_walls = [
        add_tex(f"endwall{k}", _side_wall_texture(r_facade, ftex, 12.0, 19.0)) for k in range(3)
    ]
    trees: list[tuple[int, float, float]] = []
    for k in range(cfg.n_tree_styles):
        w, h = float(r_tree.uniform(3.5, 5.5)), float(r_tree.uniform(6.0, 9.0))
        trees.append((add_tex(f"tree{k}", _tree_texture(r_tree, 0.025, w, h)), w, h))
    t_fence = add_tex("fence", _fence_texture(r_tree, 0.01, 4.0, 1.4))
    sky_cols, sky_rows, step = 1200, 560, 2.5 / 1200
    horizon_row = 1.0 / step  # tan_el_max = 1.0
    t_sky = add_tex("sky", _sky_texture(r_sky, sky_cols, sky_rows, horizon_row))
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
