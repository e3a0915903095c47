"""Background correspondences for the pitch estimator, and a texture / quality measure.

Good features to track (Shi–Tomasi, grid-bucketed so that points cover the
image) are picked outside every vehicle box and the lead's box on a reduced
image, and tracked from a *key frame* to the current frame by pyramidal LK
(starting from the previous frame's position) with a forward-backward check:
long-term tracks as MFT gives in the paper, without the drift of chained
frame-to-frame flow. The key is renewed when too few tracks survive or it is
too old. Each frame yields the key-frame pairs (x_key, x_cur) and the
frame-to-frame pairs (x_prev, x_cur_ff) of the same tracks, in full-resolution
pixels. Tracks that enter a vehicle box are dropped every frame.

The quality measure (count, spread over a coarse grid of cells, median
forward-backward error) decides ``textured``: the fusion uses it to tell that
vision has failed (fog, night, tunnel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.configtools import check_ranges, param
from roadpreview.vision.base import F32, F64, U8, Box, FrameContext, to_full, to_small
from roadpreview.vision.features import corner_strength, grid_features, inside, track_fb


@dataclass(frozen=True)
class BackgroundConfig:
    """Settings of `BackgroundTracker` (pixels of the reduced image unless stated)."""

    max_points: int = param(
        250, ge=12, help="tracks per key frame: 250 x ~10 us of LK fits the 12 ms budget"
    )
    cell_px: int = param(
        20, ge=4, le=128, unit="px", help="bucketing cell: at most one feature per cell"
    )
    min_corner: float = param(
        5e-4,
        gt=0.0,
        help="Shi–Tomasi min eigenvalue (OpenCV's 8-bit scale); weaker corners drift",
    )
    lk_window_px: int = param(13, ge=5, le=41, unit="px", help="LK window")
    lk_levels: int = param(
        2, ge=0, le=6, help="pyramid levels; the search starts at the previous position"
    )
    max_fb_px: float = param(0.3, unit="px", gt=0.0, help="forward-backward check (0.6 px at 720p)")
    min_tracks: int = param(60, ge=8, help="renew the key frame when fewer tracks survive")
    min_survival: float = param(
        0.5, gt=0.0, lt=1.0, help="renew the key frame when fewer of its tracks survive"
    )
    max_key_age_s: float = param(
        1.0, unit="s", gt=0.0, help="renew the key frame when older (scale change, occlusion)"
    )
    vehicle_margin: float = param(
        0.1, ge=0.0, help="vehicle boxes are grown by this fraction before masking"
    )
    quality_grid: tuple[int, int] = param(
        (8, 6), help="coarse cells (columns, rows) for the spread of the points"
    )
    min_points_textured: int = param(
        30, ge=1, help="fewer tracked points: not textured (vision failed)"
    )
    min_spread: float = param(
        0.2, ge=0.0, le=1.0, help="fewer occupied coarse cells (fraction): not textured"
    )
    max_fb_median_px: float = param(
        0.2, unit="px", gt=0.0, help="median forward-backward error above this: not textured"
    )

    def validate(self, where: str = "BackgroundConfig") -> None:
        check_ranges(self, where)


@dataclass(frozen=True)
class TextureQuality:
    """How well the background could be tracked in a frame."""

    n_points: int = 0
    spread: float = 0.0
    fb_median_px: float = math.nan
    n_features: int = 0
    textured: bool = False
    reason: str = ""

    def __bool__(self) -> bool:
        return self.textured


@dataclass(frozen=True)
class BackgroundCorrespondences:
    """Background point pairs for the pitch estimator, in full-resolution pixels.

    ``x_key`` -> ``x_cur``: long-term tracks from the key frame (time
    ``key_t``, frame ``key_index``) to this frame; ``x_prev`` -> ``x_cur_ff``:
    the same tracks between the previous frame and this one. ``key_renewed``
    says that this frame becomes the key frame for the following frames (the
    pairs of this frame still refer to the old key). Falsy when not textured
    or empty; ``reason`` says why.
    """

    t: float
    index: int
    key_t: float
    key_index: int
    x_key: F64
    x_cur: F64
    x_prev: F64
    x_cur_ff: F64
    quality: TextureQuality
    key_renewed: bool = False
    reason: str = ""

    def __bool__(self) -> bool:
        return not self.reason and self.quality.textured and self.x_key.shape[0] > 0

    @classmethod
    def empty(cls, t: float, index: int, reason: str) -> BackgroundCorrespondences:
        z = np.empty((0, 2), np.float64)
        return cls(
            t=t,
            index=index,
            key_t=math.nan,
            key_index=-1,
            x_key=z,
            x_cur=z,
            x_prev=z,
            x_cur_ff=z,
            quality=TextureQuality(reason=reason),
            reason=reason,
        )


def vehicle_mask(shape: tuple[int, int], boxes: list[Box], scale: float, margin: float) -> U8:
    """255 where background is allowed, 0 inside every (grown, scaled) vehicle box."""
    m = np.full(shape, 255, np.uint8)
    for b in boxes:  # a handful of boxes
        w, h = b[2] - b[0], b[3] - b[1]
        lo = to_small(np.array([[b[0] - margin * w, b[1] - margin * h]]), scale)[0]
        hi = to_small(np.array([[b[2] + margin * w, b[3] + margin * h]]), scale)[0]
        cv2.rectangle(m, (int(lo[0]), int(lo[1])), (math.ceil(hi[0]), math.ceil(hi[1])), 0, -1)
    return m


class BackgroundTracker:
    """Key-frame LK tracks of background features; one `update` per frame."""

    def __init__(self, config: BackgroundConfig | None = None) -> None:
        self.config = config or BackgroundConfig()
        self.config.validate()
        self.reset()

    def reset(self) -> None:
        self._key_img: U8 | None = None
        self._key_t = math.nan
        self._key_index = -1
        self._key_pts: F32 = np.empty((0, 2), np.float32)
        self._cur_pts: F32 = np.empty((0, 2), np.float32)
        self._n_key = 0
        self._n_features = 0
        self._prev_shape: tuple[int, int] | None = None

    def _renew(self, ctx: FrameContext, mask: U8) -> None:
        cfg = self.config
        img = ctx.small
        h, w = img.shape
        cell = cfg.cell_px
        # a cell size giving about 1.5x max_points cells, never below the configured one
        cell = max(cell, int(math.sqrt(h * w / (1.5 * cfg.max_points))))
        pts, val = grid_features(
            corner_strength(img),
            cell,
            cfg.min_corner,
            mask=mask,
            border=cfg.lk_window_px // 2 + 1,
        )
        if pts.shape[0] > cfg.max_points:
            pts = pts[np.argsort(-val, kind="stable")[: cfg.max_points]]
        self._key_img = img
        self._key_t = ctx.t
        self._key_index = ctx.index
        self._key_pts = pts
        self._cur_pts = pts.copy()
        self._n_key = pts.shape[0]
        self._n_features = pts.shape[0]

    def update(self, ctx: FrameContext, vehicle_boxes: list[Box]) -> BackgroundCorrespondences:
        """Track the key frame's features into this frame; renew the key when needed."""
        cfg = self.config
        img = ctx.small
        h, w = img.shape
        mask = vehicle_mask((h, w), vehicle_boxes, ctx.scale, cfg.vehicle_margin)
        if self._key_img is None or self._prev_shape != img.shape:
            self._prev_shape = img.shape
            self._renew(ctx, mask)
            q = self._quality(self._cur_pts, np.zeros(self._cur_pts.shape[0], np.float32), (w, h))
            z = np.empty((0, 2), np.float64)
            return BackgroundCorrespondences(
                t=ctx.t,
                index=ctx.index,
                key_t=ctx.t,
                key_index=ctx.index,
                x_key=z,
                x_cur=z,
                x_prev=z,
                x_cur_ff=z,
                quality=q,
                key_renewed=True,
                reason="first key frame" if q.textured else q.reason,
            )
        key_pts, prev_pts = self._key_pts, self._cur_pts
        flow = track_fb(
            self._key_img,
            img,
            key_pts,
            win=cfg.lk_window_px,
            levels=cfg.lk_levels,
            max_fb_px=cfg.max_fb_px,
            guess=prev_pts,
        )
        ok = flow.ok & inside(flow.p1, w, h, 1.0)
        if ok.any():  # drop tracks that entered a vehicle box
            p = flow.p1[ok]
            xi = np.clip(p[:, 0].round().astype(np.int64), 0, w - 1)
            yi = np.clip(p[:, 1].round().astype(np.int64), 0, h - 1)
            on_vehicle = mask[yi, xi] == 0
            ok[np.nonzero(ok)[0][on_vehicle]] = False
        cur = flow.p1[ok]
        key = key_pts[ok]
        prev = prev_pts[ok]
        q = self._quality(cur, flow.fb_error[ok], (w, h))
        s = ctx.scale
        out = BackgroundCorrespondences(
            t=ctx.t,
            index=ctx.index,
            key_t=self._key_t,
            key_index=self._key_index,
            x_key=to_full(key, s),
            x_cur=to_full(cur, s),
            x_prev=to_full(prev, s),
            x_cur_ff=to_full(cur, s),
            quality=q,
            reason="" if q.textured else q.reason,
        )
        self._key_pts, self._cur_pts = key, cur
        survivors = cur.shape[0]
        if (
            survivors < cfg.min_tracks
            or survivors < cfg.min_survival * self._n_key
            or ctx.t - self._key_t >= cfg.max_key_age_s
        ):
            self._renew(ctx, mask)
            out = BackgroundCorrespondences(**{**out.__dict__, "key_renewed": True})
        return out

    def _quality(self, pts: F32, fb: NDArray[np.float32], size: tuple[int, int]) -> TextureQuality:
        cfg = self.config
        n = int(pts.shape[0])
        gx, gy = cfg.quality_grid
        w, h = size
        if n:
            cx = np.clip((pts[:, 0] * gx / w).astype(np.int64), 0, gx - 1)
            cy = np.clip((pts[:, 1] * gy / h).astype(np.int64), 0, gy - 1)
            spread = np.unique(cy * gx + cx).size / (gx * gy)
            fbm = float(np.median(fb))
        else:
            spread, fbm = 0.0, math.nan
        reasons = []
        if n < cfg.min_points_textured:
            reasons.append(f"too few background points ({n} < {cfg.min_points_textured})")
        if spread < cfg.min_spread:
            reasons.append(f"points cover {spread:.0%} of the image (< {cfg.min_spread:.0%})")
        if n and fbm > cfg.max_fb_median_px:
            reasons.append(f"median forward-backward error {fbm:.2f} px")
        textured = not reasons
        return TextureQuality(
            n_points=n,
            spread=float(spread),
            fb_median_px=fbm,
            n_features=self._n_features,
            textured=textured,
            reason="; ".join(reasons),
        )
