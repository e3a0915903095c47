"""Procedural faces of vehicles (rear, front, side) with lamps, windows and number plates."""

from __future__ import annotations

import string
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.sim.scene.mipmap import Texture
from roadpreview.sim.scene.noise import colourise, fbm
from roadpreview.sim.types import VehicleShape

U8 = NDArray[np.uint8]

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
    grain = fbm(rng, H, W, [(40, 0.015), (2, 0.025)])
    dark = tuple(int(c * 0.5) for c in body)

    def face(kind: str) -> tuple[U8, tuple[tuple[float, float, float, float], ...]]:
        img = colourise(body, vshade + hshade + grain)
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
        glass += 12 * fbm(rng, H, W, [(30, 0.7), (6, 0.3)])[..., None]
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
    side = colourise(
        body,
        np.linspace(0.1, -0.15, sh, dtype=np.float32)[:, None]
        + fbm(rng, sh, L, [(30, 0.015), (2, 0.02)]),
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
