"""Procedural noise for the textures: value noise, fractal sums of it, specks, colouring."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]


def _divisor_near(n: int, target: int) -> int:
    """The divisor of n nearest to target (so periodic noise tiles exactly)."""
    divs = np.array([d for d in range(1, n + 1) if n % d == 0])
    return int(divs[np.argmin(np.abs(np.log(divs / max(target, 1))))])


def value_noise(rng: np.random.Generator, rows: int, cols: int, cell: int, periodic: bool) -> F32:
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


def fbm(
    rng: np.random.Generator,
    rows: int,
    cols: int,
    octaves: Sequence[tuple[int, float]],
    periodic: bool = False,
) -> F32:
    """Sum of value-noise octaves given as (cell size in texels, amplitude)."""
    out = np.zeros((rows, cols), np.float32)
    for cell, amp in octaves:
        out += amp * value_noise(rng, rows, cols, cell, periodic)
    return out


def speckle(rng: np.random.Generator, rows: int, cols: int, density: float) -> F32:
    """Sparse +-1 specks (aggregate stones), one texel each, slightly blurred."""
    n = int(density * rows * cols)
    img = np.zeros((rows, cols), np.float32)
    r = rng.integers(0, rows, n)
    c = rng.integers(0, cols, n)
    img[r, c] = rng.choice(np.array([-1.0, 1.0], np.float32), n) * rng.uniform(0.5, 1.0, n).astype(
        np.float32
    )
    return np.asarray(cv2.GaussianBlur(img, (3, 3), 0.6), np.float32)


def colourise(base_bgr: Sequence[float], shade: F32) -> U8:
    """base colour * (1 + shade) per channel, clipped to uint8."""
    base = np.asarray(base_bgr, np.float32).reshape(1, 1, 3)
    return np.clip(base * (1.0 + shade[..., None]), 0, 255).astype(np.uint8)
