"""Procedural textures of the static world: asphalt with markings, verges, kerbs, facades,
end walls, trees, fences, sky and tunnel lining, drawn from a random generator."""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.sim.scene.config import SceneConfig
from roadpreview.sim.scene.noise import colourise, fbm, speckle

U8 = NDArray[np.uint8]


def _wrapped(cols: int, xs: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Copies of a shape's x coordinates shifted by -cols, 0, +cols (seamless tiling)."""
    return [xs - cols, xs, xs + cols]


def road_texture(cfg: SceneConfig, rng: np.random.Generator) -> tuple[U8, float, float]:
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

    shade = fbm(rng, rows, cols, [(400, 0.05), (90, 0.05), (18, 0.04), (4, 0.05)], True)
    shade += 0.35 * speckle(rng, rows, cols, 0.05)
    shade += 0.12 * speckle(rng, rows, cols, 0.15)
    # polished wheel tracks in both lanes (slightly darker, smoother)
    yy = (y_top - (np.arange(rows) + 0.5) * tt).astype(np.float32)
    for centre in (0.0, cfg.lane_width_m):
        for off in (-0.8, 0.8):
            shade -= (0.06 * np.exp(-(((yy - centre - off) / 0.3) ** 2)))[:, None]
    img = colourise((92, 94, 96), shade)

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
    wear = np.clip(0.85 + 0.25 * fbm(rng, rows, cols, [(30, 0.6), (5, 0.4)], True), 0.0, 1.0)
    a = (paint.astype(np.float32) / 255.0 * wear)[..., None]
    white = np.array([222, 226, 228], np.float32).reshape(1, 1, 3)
    img = (img.astype(np.float32) * (1 - a) + white * a).astype(np.uint8)
    return img, ts, tt


def verge_texture(
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
    grass = colourise(
        (48, 104, 82), fbm(rng, rows, cols, [(60, 0.12), (10, 0.12), (2, 0.18)], True)
    )
    gravel = colourise((120, 128, 136), fbm(rng, rows, cols, [(20, 0.06), (1, 0.22)], True))
    slab_shade = fbm(rng, rows, cols, [(40, 0.05), (2, 0.06)], True)
    slabs = colourise((150, 156, 160), slab_shade)
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


def kerb_texture(cfg: SceneConfig, rng: np.random.Generator) -> tuple[U8, float, float]:
    """Concrete kerb stones 1 m long (the kerb's vertical face)."""
    texel = 0.01
    rows = max(4, round(cfg.kerb_height_m / texel))
    cols = round(cfg.texture_period_m / texel)
    img = colourise((168, 172, 175), fbm(rng, rows, cols, [(20, 0.05), (1, 0.08)], True))
    xs = np.arange(cols) * texel
    img[:, (xs % 1.0) < 0.012] = (90, 92, 95)
    img[-2:, :] = (60, 62, 64)
    return img, cfg.texture_period_m / cols, cfg.kerb_height_m / rows


def facade_texture(rng: np.random.Generator, texel: float, width_m: float, height_m: float) -> U8:
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
    img = colourise(base, fbm(rng, rows, cols, [(80, 0.05), (12, 0.04), (1, 0.05)]))
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


def side_wall_texture(
    rng: np.random.Generator, texel: float, depth_m: float, height_m: float
) -> U8:
    """A building's end wall: plaster with a few small windows."""
    cols, rows = max(8, round(depth_m / texel)), max(8, round(height_m / texel))
    base = (int(rng.integers(120, 200)), int(rng.integers(120, 200)), int(rng.integers(120, 210)))
    img = colourise(base, fbm(rng, rows, cols, [(60, 0.06), (8, 0.04), (1, 0.04)]))
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


def tree_texture(rng: np.random.Generator, texel: float, width_m: float, height_m: float) -> U8:
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
    alpha += 0.45 * fbm(rng, rows, cols, [(max(2, round(0.5 / texel)), 0.6), (3, 0.4)])
    leaves = alpha > 0.25
    shade = fbm(rng, rows, cols, [(round(0.8 / texel), 0.12), (3, 0.2), (1, 0.15)])
    shade -= 0.35 * (yy / crown_h)  # lower crown in its own shadow
    greens = [(40, 110, 70), (50, 120, 90), (35, 95, 60), (60, 130, 110)]
    img = colourise(greens[int(rng.integers(len(greens)))], shade)
    bgra = np.zeros((rows, cols, 4), np.uint8)
    bgra[..., :3] = img
    bgra[..., 3] = np.where(leaves, 255, 0).astype(np.uint8)
    # trunk
    tw = rng.uniform(0.25, 0.4)
    x0, x1 = round((width_m - tw) / 2 / texel), round((width_m + tw) / 2 / texel)
    y0 = round(crown_h * 0.7 / texel)
    trunk = colourise((50, 70, 90), fbm(rng, rows - y0, x1 - x0, [(4, 0.15), (1, 0.1)]))
    under = bgra[y0:, x0:x1]
    keep = under[..., 3] > 0
    trunk_bgra = np.concatenate([trunk, np.full((*trunk.shape[:2], 1), 255, np.uint8)], axis=2)
    under[~keep] = trunk_bgra[~keep]
    return bgra


def fence_texture(rng: np.random.Generator, texel: float, length_m: float, height_m: float) -> U8:
    """Wooden picket fence, BGRA (gaps between slats transparent)."""
    cols, rows = round(length_m / texel), round(height_m / texel)
    img = colourise((70, 110, 150), fbm(rng, rows, cols, [(6, 0.1), (1, 0.08)]))
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


def sky_texture(rng: np.random.Generator, cols: int, rows: int, horizon_row: float) -> U8:
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
    clouds = fbm(rng, rows, cols, [(120, 0.6), (40, 0.3), (12, 0.15), (4, 0.08)])
    cover = np.clip((clouds - 0.3) * 1.2, 0, 1) * np.clip(t * 4, 0, 1)[:, None]
    white = np.array([245, 243, 240], np.float32)
    img = img * (1 - cover[..., None]) + white * cover[..., None]
    img *= (1.0 - 0.12 * np.clip(clouds - 0.8, 0, 1))[..., None]  # cloud undersides
    out: U8 = np.clip(img, 0, 255).astype(np.uint8)
    return out


def tunnel_texture(
    rng: np.random.Generator, period_m: float, height_m: float, texel: float
) -> tuple[U8, float, float]:
    """Dark, smooth concrete lining with faint panel joints (little to track on)."""
    rows = max(8, round(height_m / texel))
    cols = round(period_m / texel)
    img = colourise((58, 60, 62), fbm(rng, rows, cols, [(60, 0.05), (6, 0.02)], True))
    xs = np.arange(cols) * (period_m / cols)
    img[:, (xs % 6.0) < 0.03] = (52, 54, 56)
    return img, period_m / cols, height_m / rows
