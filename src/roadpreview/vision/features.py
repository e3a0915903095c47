"""Shared low-level vision: grid-bucketed corners and forward-backward Lucas–Kanade.

Everything here is vectorised over points (numpy and OpenCV calls on arrays).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.vision.base import F32, U8

#: LK stops after this many iterations or a step below 0.01 px
_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.01)


def corner_strength(gray: U8, block: int = 3) -> F32:
    """Shi–Tomasi minimum eigenvalue per pixel (what goodFeaturesToTrack ranks by)."""
    return np.asarray(cv2.cornerMinEigenVal(gray, block, ksize=3), np.float32)


def grid_features(
    strength: F32,
    cell: int,
    threshold: float,
    *,
    mask: U8 | None = None,
    border: int = 0,
    roi: tuple[int, int, int, int] | None = None,
) -> tuple[F32, F32]:
    """The strongest corner of every ``cell`` x ``cell`` block above ``threshold``.

    Grid bucketing: at most one point per cell, so points cover the image
    instead of piling up on one tree. ``mask`` (0 = excluded), ``border``
    (pixels kept free at the image edge) and ``roi`` (x0, y0, x1, y1) restrict
    where points may lie. Returns (N, 2) float32 (x, y) and their strengths.
    Vectorised: the strength map is reshaped into cells and arg-maxed.
    """
    h, w = strength.shape
    x0, y0, x1, y1 = roi if roi is not None else (0, 0, w, h)
    x0, y0 = max(x0, border), max(y0, border)
    x1, y1 = min(x1, w - border), min(y1, h - border)
    ny, nx = (y1 - y0) // cell, (x1 - x0) // cell
    if nx <= 0 or ny <= 0:
        return np.empty((0, 2), np.float32), np.empty(0, np.float32)
    s = strength[y0 : y0 + ny * cell, x0 : x0 + nx * cell]
    if mask is not None:
        s = np.where(mask[y0 : y0 + ny * cell, x0 : x0 + nx * cell] > 0, s, 0.0)
    blocks = s.reshape(ny, cell, nx, cell).transpose(0, 2, 1, 3).reshape(ny, nx, cell * cell)
    idx = np.argmax(blocks, axis=2)
    val = np.take_along_axis(blocks, idx[..., None], axis=2)[..., 0]
    gy, gx = np.mgrid[0:ny, 0:nx]
    ok = val > threshold
    px = (x0 + gx * cell + idx % cell)[ok]
    py = (y0 + gy * cell + idx // cell)[ok]
    return np.stack([px, py], axis=1).astype(np.float32), val[ok].astype(np.float32)


@dataclass(frozen=True)
class FlowResult:
    """Points tracked from one image to another.

    ``p1`` are the positions in the second image, ``ok`` the points that
    passed LK's status in both directions and the forward-backward check,
    ``fb_error`` the forward-backward distance (px, inf where LK failed).
    """

    p1: F32
    ok: NDArray[np.bool_]
    fb_error: F32


def track_fb(
    img0: U8,
    img1: U8,
    p0: F32,
    *,
    win: int,
    levels: int,
    max_fb_px: float,
    guess: F32 | None = None,
) -> FlowResult:
    """Pyramidal LK from ``img0`` to ``img1`` and back, with the forward-backward check.

    ``guess`` (positions in ``img1``) starts the forward search there
    (OPTFLOW_USE_INITIAL_FLOW); the backward search starts at ``p0``.
    """
    n = p0.shape[0]
    if n == 0:
        e = np.empty((0, 2), np.float32)
        return FlowResult(e, np.zeros(0, bool), np.empty(0, np.float32))
    a = np.ascontiguousarray(p0, np.float32).reshape(-1, 1, 2)
    size = (win, win)
    if guess is not None:
        g = np.ascontiguousarray(guess, np.float32).reshape(-1, 1, 2).copy()
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(
            img0,
            img1,
            a,
            g,
            winSize=size,
            maxLevel=levels,
            criteria=_CRITERIA,
            flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        )
    else:
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(
            img0, img1, a, a.copy(), winSize=size, maxLevel=levels, criteria=_CRITERIA
        )
    back = a.copy()
    pb, st2, _ = cv2.calcOpticalFlowPyrLK(
        img1,
        img0,
        p1,
        back,
        winSize=size,
        maxLevel=levels,
        criteria=_CRITERIA,
        flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
    )
    p1 = p1.reshape(-1, 2)
    fb = np.linalg.norm(pb.reshape(-1, 2) - a.reshape(-1, 2), axis=1).astype(np.float32)
    good = (st1.ravel() == 1) & (st2.ravel() == 1) & np.isfinite(p1).all(axis=1)
    fb = np.where(good, fb, np.float32(np.inf)).astype(np.float32)
    ok = good & (fb <= max_fb_px)
    return FlowResult(np.asarray(p1, np.float32), ok, fb)


def inside(
    points: NDArray[np.floating], width: int, height: int, margin: float = 0.0
) -> NDArray[np.bool_]:
    """Points at least ``margin`` pixels inside a ``width`` x ``height`` image."""
    x, y = points[:, 0], points[:, 1]
    return (x >= margin) & (y >= margin) & (x <= width - 1 - margin) & (y <= height - 1 - margin)
