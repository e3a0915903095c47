"""Tracking the lead vehicle: a grid of LK points over it, its vertical trajectory y(t).

The target is the detection nearest the image centre (the paper's rule): the
box whose columns are nearest the column of the focus of expansion, and among
boxes that span it the nearest vehicle (lowest box bottom). A grid of points
(6 px spacing, at most 400) over the inner part of the box, or over the mask,
is tracked frame to frame by pyramidal Lucas–Kanade with a forward-backward
check, on a crop around the box. Points that fail, leave the box or move
inconsistently with the rest are dropped: a similarity motion (translation,
scale, in-plane rotation) is fitted to the points' displacements by
iteratively reweighted least squares, and points farther than 3 MADs from it
are outliers.

y(t) without jumps: y is the vertical position of an *anchor*, initially the
mean v of the seeded grid, moved every frame by the fitted motion of the valid
points (for a pure translation that is their mean displacement). Dropping
points or re-seeding a new grid changes which points are averaged but never
moves the anchor, so y(t) stays continuous; the same holds for the anchors of
the left and right halves (y_left, y_right), whose difference shows roll (a
one-sided pothole). Only a new target (re-acquisition, cut-in) restarts y,
and that frame says so (``target_changed``).

Distance: from the box width with a known vehicle width (``d = f W / w``) and
from the ground contact (``d = f h / (v_bottom - v_horizon)``, minus the rear
overhang), each with its uncertainty, fused by inverse variance.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.configtools import check_ranges, param
from roadpreview.vision.base import (
    F32,
    F64,
    Box,
    Detection,
    FrameContext,
    box_iou,
    clip_box,
)
from roadpreview.vision.features import corner_strength, track_fb


@dataclass(frozen=True)
class LeadTrackerConfig:
    """Settings of `LeadVehicleTracker` (full-resolution pixels)."""

    grid_spacing_px: float = param(6.0, unit="px", ge=2.0, help="the paper's 6 px grid")
    max_points: int = param(400, ge=10, help="the paper's N = 400; the spacing grows beyond")
    min_grid_spacing_px: float = param(
        3.0, unit="px", ge=1.0, help="small (far) boxes get a denser grid down to this"
    )
    min_seed_points: int = param(16, ge=4, help="aim for at least this many points on a box")
    inner_margin: float = param(
        0.12, ge=0.0, lt=0.5, help="grid over the box less this fraction on each side"
    )
    min_texture: float = param(
        2e-5, ge=0.0, help="grid points on flatter image (min eigenvalue) are not tracked"
    )
    lk_window_px: int = param(15, ge=5, le=41, unit="px", help="LK window")
    lk_levels: int = param(2, ge=0, le=5, help="pyramid levels (the lead moves little)")
    max_fb_px: float = param(0.5, unit="px", gt=0.0, help="forward-backward check")
    outlier_mads: float = param(3.0, gt=0.0, help="residual beyond this many MADs: dropped")
    min_outlier_px: float = param(0.3, unit="px", gt=0.0, help="floor of the outlier threshold")
    reseed_fraction: float = param(
        0.5, gt=0.0, lt=1.0, help="re-seed the grid when fewer of the seeded points remain"
    )
    min_points: int = param(6, ge=3, help="fewer valid points: the track is lost")
    min_inlier_fraction: float = param(
        0.3, gt=0.0, le=1.0, help="fewer inliers of the tracked points: the track is lost"
    )
    search_margin: float = param(
        0.5, ge=0.0, help="crop around the box for LK, a fraction of its size"
    )
    min_box_px: float = param(8.0, unit="px", gt=0.0, help="smaller detections are ignored")
    min_distance_m: float = param(
        5.0,
        unit="m",
        ge=0.0,
        le=50.0,
        help="a detection whose bottom is nearer than this on the flat road is not taken as"
        " the lead (a vehicle tracked already may come closer). What the motion finder reports"
        " there is road: entering a fog bank, or with the horizon off, it boxed the road below a"
        " real lead at 17-23 m as an 'obstacle' at 1-4.3 m, which the centre rule prefers (the"
        " nearest box); a 720p camera at 1.3 m with f = 706 px sees the road from 2.5 m on."
        " 0 with the box finder: the user's box is the lead",
    )
    min_ttc_s: float = param(
        1.0,
        unit="s",
        ge=0.0,
        le=10.0,
        help="a target whose points spread apart as a time to contact below this (their"
        " scale's growth rate, smoothed over ttc_smoothing_s, above 1 / min_ttc_s) is no lead"
        " to preview: the road or a parked car the ego runs up to, which the motion finder"
        " boxed (on the wild set: road patches tracked from 5 m down to 1 m, the row moving"
        " 100-200 px in a second) - or an emergency, which is not the preview's. Track lost;"
        " 0: no check",
    )
    ttc_smoothing_s: float = param(
        0.2, unit="s", gt=0.0, le=2.0, help="time constant of the scale-rate smoothing"
    )
    match_iou: float = param(0.3, gt=0.0, le=1.0, help="a detection this close is the target")
    max_box_width_frac: float = param(
        0.6,
        gt=0.0,
        le=1.0,
        help="a tracked box wider than this share of the image is no car ahead: track lost",
    )
    box_refresh: float = param(
        0.5, ge=0.0, le=1.0, help="weight of a matching detection's box in the tracked box"
    )
    refresh_size_gate: float = param(
        0.15,
        ge=0.0,
        help="a matching detection whose width differs from the tracked box's by more than this"
        " fraction is not blended in (the points' own scale change carries the box): a lead"
        " pitching over a bump swells the motion finder's box by 25-40 % for about a second,"
        " which the width cue would read as the gap closing by 4-5 m",
    )
    refresh_size_persist_s: float = param(
        1.5,
        unit="s",
        gt=0.0,
        help="a size disagreement that lasts this long is real (the tracked box drifted):"
        " detections are blended in again",
    )
    cut_in_confirmations: int = param(
        2, ge=1, help="finder runs that must agree before switching to another vehicle"
    )
    centre_tolerance: float = param(
        0.05, ge=0.0, help="boxes this close (fraction of width) to the centre column span it"
    )
    vehicle_width_m: float = param(1.8, unit="m", gt=0.5, le=3.0, help="a typical car's width")
    vehicle_width_std_m: float = param(
        0.12, unit="m", ge=0.0, help="spread of car widths (1.65-1.95 m)"
    )
    width_section_ahead_m: float = param(
        0.8,
        unit="m",
        ge=0.0,
        le=3.0,
        help="a real car is widest at its rear wheel arches, this far ahead of the rear face "
        "(0 for the simulator's box-shaped vehicles)",
    )
    rear_overhang_m: float = param(
        0.9,
        unit="m",
        ge=0.0,
        le=3.0,
        help="the box bottom is the rear tyres' contact, this far ahead of the rear face",
    )
    pitch_std_rad: float = param(
        0.01, unit="rad", ge=0.0, help="uncertainty of the horizon (pitch, road grade): 0.6 deg"
    )
    height_std_m: float = param(
        0.05, unit="m", ge=0.0, help="uncertainty of the camera height above the road"
    )

    def validate(self, where: str = "LeadTrackerConfig") -> None:
        check_ranges(self, where)


@dataclass(frozen=True)
class LeadObservation:
    """The lead vehicle in one frame.

    ``y`` is the robust mean vertical image position of the tracked points
    (px, down positive; see the module docstring for continuity), ``y_left``
    and ``y_right`` the same for the left and right halves. ``box`` is the
    tracked box, ``n_valid`` the number of points that passed every check.
    ``distance_m`` is the fused distance to the lead's rear face with its
    1-sigma ``distance_std_m``; ``distance_width_m`` and
    ``distance_ground_m`` are the two cues (NaN when unavailable).
    ``track_id`` changes with every new target; ``target_changed`` is True on
    the first frame of a new target. Falsy when there is no target; ``reason``
    says why.
    """

    t: float
    y: float = math.nan
    y_left: float = math.nan
    y_right: float = math.nan
    box: Box | None = None
    n_valid: int = 0
    distance_m: float = math.nan
    distance_std_m: float = math.inf
    distance_width_m: float = math.nan
    distance_ground_m: float = math.nan
    track_id: int = 0
    target_changed: bool = False
    reseeded: bool = False
    class_name: str = ""
    reason: str = ""

    def __bool__(self) -> bool:
        return not self.reason and math.isfinite(self.y) and self.box is not None

    @classmethod
    def none(cls, t: float, reason: str, track_id: int = 0) -> LeadObservation:
        """A falsy observation: no target in this frame, and why."""
        return cls(t=t, reason=reason, track_id=track_id)


def target_key(det: Detection, column: float, tolerance: float) -> tuple[int, float]:
    """Sort key of the paper's "nearest the image centre": boxes spanning the centre
    column first, nearest (lowest bottom) first; then by the gap to the column."""
    x0, _, x1, y1 = det.box
    gap = max(x0 - column, column - x1, 0.0)
    if gap <= tolerance * (x1 - x0):
        return (0, -y1)
    return (1, gap)


def choose_target(
    detections: list[Detection],
    camera: CameraModel,
    *,
    horizon_v: float,
    min_box_px: float = 8.0,
    tolerance: float = 0.05,
    classes: tuple[str, ...] | None = None,
    min_distance_m: float = 0.0,
) -> int | None:
    """Index of the detection nearest the image centre, below the horizon and no nearer than
    ``min_distance_m`` on the flat road (its bottom row); None if none."""
    column = camera.fx * camera.t[0] / camera.t[2] + camera.cx
    # rows below horizon_v + f h / d_min are nearer than d_min on a flat road
    lowest = (
        horizon_v + camera.fy * camera.mount_height_m / min_distance_m
        if min_distance_m > 0.0
        else math.inf
    )
    best: tuple[tuple[int, float], int] | None = None
    for i, d in enumerate(detections):  # a handful of detections
        if classes is not None and d.class_name not in classes:
            continue
        if d.width < min_box_px or d.height < min_box_px or not horizon_v < d.box[3] <= lowest:
            continue
        key = target_key(d, column, tolerance)
        if best is None or key < best[0]:
            best = (key, i)
    return None if best is None else best[1]


def fit_similarity(
    p: F64, d: F64, iterations: int = 3
) -> tuple[NDArray[np.float64], NDArray[np.float64], F64]:
    """Robust fit of ``d = t + s (p - c) + w perp(p - c)`` to displacements ``d`` at ``p``.

    Returns (params [tx, ty, s, w, cx, cy], residual norms, weights). IRLS with
    Tukey-like weights from the MAD of the residuals; vectorised over points.
    """
    c = np.median(p, axis=0)
    X = p[:, 0] - c[0]
    Y = p[:, 1] - c[1]
    n = p.shape[0]
    # rows: dx = tx + s X - w Y ; dy = ty + s Y + w X
    A = np.zeros((2 * n, 4))
    A[0::2, 0] = 1.0
    A[1::2, 1] = 1.0
    A[0::2, 2] = X
    A[1::2, 2] = Y
    A[0::2, 3] = -Y
    A[1::2, 3] = X
    b = d.reshape(-1)
    w = np.ones(n)
    theta = np.array([np.median(d[:, 0]), np.median(d[:, 1]), 0.0, 0.0])
    res = np.linalg.norm(d - theta[:2], axis=1)
    for _ in range(iterations):
        scale = max(1.4826 * float(np.median(res)), 0.05)
        u = res / (4.685 * scale)
        w = np.where(u < 1.0, (1.0 - u * u) ** 2, 0.0)
        if np.count_nonzero(w) < 3:
            break
        ww = np.repeat(w, 2)
        Aw = A * ww[:, None]
        try:
            theta = np.linalg.solve(Aw.T @ A + 1e-9 * np.eye(4), Aw.T @ b)
        except np.linalg.LinAlgError:
            break
        res = np.linalg.norm((A @ theta - b).reshape(-1, 2), axis=1)
    return np.concatenate([theta, c]), res, w


def _move(model: NDArray[np.float64], x: float, y: float) -> tuple[float, float]:
    """Displacement of point (x, y) under the fitted similarity."""
    tx, ty, s, w, cx, cy = model
    X, Y = x - cx, y - cy
    return (tx + s * X - w * Y, ty + s * Y + w * X)


class LeadVehicleTracker:
    """Tracks the lead vehicle's grid of points and reports a `LeadObservation` per frame.

    Call `update` once per frame with the frame's `FrameContext` and the
    finder's detections when the finder ran on that frame (None otherwise).
    """

    def __init__(self, camera: CameraModel, config: LeadTrackerConfig | None = None) -> None:
        self.camera = camera
        self.config = config or LeadTrackerConfig()
        self.config.validate()
        self._track_id = 0
        self._prev_gray: NDArray[np.uint8] | None = None
        self._active = False
        self._class = ""
        self._edge_sigma = 3.0
        self._bottom_sigma: float | None = None
        self._pending: tuple[Box, int] | None = None
        self.reset()

    @property
    def active(self) -> bool:
        """Whether a target is being tracked."""
        return self._active

    @property
    def box(self) -> Box | None:
        return self._box if self._active else None

    def reset(self) -> None:
        """Drop the target (a new sequence)."""
        self._active = False
        self._points: F32 = np.empty((0, 2), np.float32)
        self._n_seeded = 0
        self._box: Box = (0.0, 0.0, 0.0, 0.0)
        self._size_gated_since = math.nan  # first refresh of a running size disagreement
        self._growth = 0.0  # smoothed growth rate of the points' scale, 1/s
        self._growth_t = math.nan
        self._anchor = (math.nan, math.nan)
        self._anchor_l = (math.nan, math.nan)
        self._anchor_r = (math.nan, math.nan)
        self._prev_gray = None
        self._pending = None
        #: (frame index, track id, box) of the last frames, for `carry_forward`
        self._boxes: deque[tuple[int, int, Box]] = deque(maxlen=8)

    # -- helpers ----------------------------------------------------------------------
    def horizon_v(self, pitch_rad: float = 0.0) -> float:
        """Row of the horizon: the FOE's row moved down by f tan(pitch)."""
        cam = self.camera
        return float(cam.fy * cam.t[1] / cam.t[2] + cam.cy + cam.fy * math.tan(pitch_rad))

    def _grid(self, gray: NDArray[np.uint8], box: Box, mask: NDArray[np.bool_] | None) -> F32:
        """Grid points over the mask, or the inner part of the box, on textured pixels."""
        cfg = self.config
        x0, y0, x1, y1 = box
        m = cfg.inner_margin
        if mask is None:
            x0, x1 = x0 + m * (x1 - x0), x1 - m * (x1 - x0)
            y0, y1 = y0 + m * (y1 - y0), y1 - m * (y1 - y0)
        w, h = max(x1 - x0, 1.0), max(y1 - y0, 1.0)
        step = cfg.grid_spacing_px
        if w * h / step**2 > cfg.max_points:
            step = math.sqrt(w * h / cfg.max_points)
        elif w * h / step**2 < cfg.min_seed_points:
            step = max(cfg.min_grid_spacing_px, math.sqrt(w * h / cfg.min_seed_points))
        xs = np.arange(x0 + 0.5 * (w % step), x1 + 1e-9, step)
        ys = np.arange(y0 + 0.5 * (h % step), y1 + 1e-9, step)
        gx, gy = np.meshgrid(xs, ys)
        pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
        H, W = gray.shape
        xi = np.clip(np.round(pts[:, 0]).astype(np.int64), 0, W - 1)
        yi = np.clip(np.round(pts[:, 1]).astype(np.int64), 0, H - 1)
        if mask is not None:
            pts = pts[mask[yi, xi]]
            xi, yi = xi[mask[yi, xi]], yi[mask[yi, xi]]
        # texture: skip points on flat paint (LK cannot anchor them)
        r0, r1 = int(max(yi.min(initial=0) - 2, 0)), int(min(yi.max(initial=0) + 3, H))
        c0, c1 = int(max(xi.min(initial=0) - 2, 0)), int(min(xi.max(initial=0) + 3, W))
        if pts.shape[0] and r1 - r0 > 4 and c1 - c0 > 4:
            s = corner_strength(gray[r0:r1, c0:c1])
            strong = s[yi - r0, xi - c0] > cfg.min_texture
            if np.count_nonzero(strong) >= cfg.min_seed_points:
                pts = pts[strong]
        if pts.shape[0] > cfg.max_points:
            keep = np.linspace(0, pts.shape[0] - 1, cfg.max_points).round().astype(np.int64)
            pts = pts[keep]
        return pts.astype(np.float32)

    def _seed(self, gray: NDArray[np.uint8], box: Box, mask: NDArray[np.bool_] | None) -> bool:
        pts = self._grid(gray, box, mask)
        if pts.shape[0] < self.config.min_points:
            return False
        self._points = pts
        self._n_seeded = pts.shape[0]
        return True

    def _start(self, ctx: FrameContext, det: Detection) -> bool:
        box = clip_box(det.box, self.camera.width, self.camera.height)
        if box is None or not self._seed(ctx.gray, box, det.mask):
            return False
        self._track_id += 1
        self._active = True
        self._box = box
        self._class = det.class_name
        self._edge_sigma = det.edge_sigma_px
        self._bottom_sigma = det.bottom_sigma_px
        pts = self._points.astype(np.float64)
        mx = float(np.median(pts[:, 0]))
        left, right = pts[pts[:, 0] < mx], pts[pts[:, 0] >= mx]
        self._anchor = (float(pts[:, 0].mean()), float(pts[:, 1].mean()))
        ml = left.mean(axis=0) if left.size else pts.mean(axis=0)
        mr = right.mean(axis=0) if right.size else pts.mean(axis=0)
        self._anchor_l = (float(ml[0]), float(ml[1]))
        self._anchor_r = (float(mr[0]), float(mr[1]))
        self._pending = None
        self._size_gated_since = math.nan
        self._growth, self._growth_t = 0.0, ctx.t
        return True

    # -- per frame --------------------------------------------------------------------
    def update(
        self,
        ctx: FrameContext,
        detections: list[Detection] | None = None,
        *,
        detected_index: int | None = None,
    ) -> LeadObservation:
        """Track into this frame; acquire or switch target using ``detections`` if given.

        ``detected_index``: the frame the detections were found on when it is an earlier
        one (a finder run spread over frames); a detection of the tracked target there is
        moved with the target's box from that frame to this one (`carry_forward`).
        """
        cfg = self.config
        prev = self._prev_gray
        self._prev_gray = ctx.gray
        horizon = self.horizon_v(ctx.pitch_rad)
        lost_reason = ""
        reseeded = False
        if self._active and prev is not None and prev.shape == ctx.gray.shape:
            lost_reason, reseeded = self._track(prev, ctx)
            if lost_reason:
                self._active = False
        elif self._active:
            self._active = False
            lost_reason = "frame size changed"

        changed = False
        if detections is not None:
            if detected_index is not None and detected_index != ctx.index:
                detections = self.carry_forward(detections, detected_index)
            best = choose_target(
                detections,
                self.camera,
                horizon_v=horizon,
                min_box_px=cfg.min_box_px,
                tolerance=cfg.centre_tolerance,
                classes=self._lead_classes(detections),
                min_distance_m=cfg.min_distance_m,
            )
            if best is not None:
                changed = self._consider(ctx, detections, best)
        if not self._active:
            return LeadObservation.none(
                ctx.t, lost_reason or "no lead vehicle found", track_id=self._track_id
            )
        self._boxes.append((ctx.index, self._track_id, self._box))
        return self._observation(ctx, changed, reseeded and not changed)

    def carry_forward(self, detections: list[Detection], index: int) -> list[Detection]:
        """Detections found on the earlier frame ``index``, in the current frame: the one
        on the tracked target then (the best IoU with its box then, at least
        ``match_iou``) is moved and scaled as the target's box was since; the others are
        returned as they are (their motion is unknown). Unchanged when that frame's box
        is not known (the target was acquired since, or lost)."""
        then = next((b for i, tid, b in self._boxes if i == index and tid == self._track_id), None)
        if not self._active or then is None or not detections:
            return detections
        ious = [box_iou(d.box, then) for d in detections]
        j = int(np.argmax(ious))
        if ious[j] < self.config.match_iou:
            return detections
        now = self._box
        sx = (now[2] - now[0]) / max(then[2] - then[0], 1e-9)
        sy = (now[3] - now[1]) / max(then[3] - then[1], 1e-9)
        x0, y0, x1, y1 = detections[j].box
        box = (
            now[0] + (x0 - then[0]) * sx,
            now[1] + (y0 - then[1]) * sy,
            now[0] + (x1 - then[0]) * sx,
            now[1] + (y1 - then[1]) * sy,
        )
        out = list(detections)
        out[j] = replace(detections[j], box=box)
        return out

    @staticmethod
    def _lead_classes(detections: list[Detection]) -> tuple[str, ...] | None:
        # the motion finder's oncoming vehicles are never a lead
        if any(d.class_name == "oncoming" for d in detections):
            return tuple({d.class_name for d in detections} - {"oncoming"})
        return None

    def _consider(self, ctx: FrameContext, detections: list[Detection], best: int) -> bool:
        """Acquire, refresh or (after confirmation) switch to the best detection."""
        cfg = self.config
        det = detections[best]
        if not self._active:
            return self._start(ctx, det)
        # the current target among the detections?
        ious = [box_iou(self._box, d.box) for d in detections]
        j = int(np.argmax(ious)) if ious else -1
        if j == best and ious[j] >= cfg.match_iou:
            self._pending = None
            self._refresh(det, ctx.t)
            return False
        # the target still tracked competes by the same rule: a detection that is not
        # nearer the centre than it is another vehicle, not a cut-in
        column = self.camera.fx * self.camera.t[0] / self.camera.t[2] + self.camera.cx
        current = Detection(self._box, 1.0, self._class)
        if target_key(det, column, cfg.centre_tolerance) >= target_key(
            current, column, cfg.centre_tolerance
        ):
            self._pending = None
            if j >= 0 and ious[j] >= cfg.match_iou:
                self._refresh(detections[j], ctx.t)
            return False
        # another vehicle is now nearest the centre (cut-in): confirm before switching
        if self._pending is not None and box_iou(self._pending[0], det.box) >= cfg.match_iou:
            count = self._pending[1] + 1
        else:
            count = 1
        self._pending = (det.box, count)
        if count >= cfg.cut_in_confirmations:
            return self._start(ctx, det)
        if j >= 0 and ious[j] >= cfg.match_iou:
            self._refresh(detections[j], ctx.t)
        return False

    def _refresh(self, det: Detection, t: float) -> None:
        """Blend a matching detection's box into the tracked one (points stay), unless its
        size disagrees (`LeadTrackerConfig.refresh_size_gate`) for less than
        `LeadTrackerConfig.refresh_size_persist_s`."""
        cfg = self.config
        a = cfg.box_refresh
        box = clip_box(det.box, self.camera.width, self.camera.height)
        if box is None:
            return
        w_old = self._box[2] - self._box[0]
        w_new = box[2] - box[0]
        if w_old > 0.0 and abs(w_new / w_old - 1.0) > cfg.refresh_size_gate:
            if math.isnan(self._size_gated_since):
                self._size_gated_since = t
            if t - self._size_gated_since < cfg.refresh_size_persist_s:
                return
        else:
            self._size_gated_since = math.nan
        o = self._box
        self._box = (
            (1 - a) * o[0] + a * box[0],
            (1 - a) * o[1] + a * box[1],
            (1 - a) * o[2] + a * box[2],
            (1 - a) * o[3] + a * box[3],
        )
        self._edge_sigma = det.edge_sigma_px
        self._bottom_sigma = det.bottom_sigma_px

    def _track(self, prev: NDArray[np.uint8], ctx: FrameContext) -> tuple[str, bool]:
        """Move the points, fit the motion, move anchors and box; '' or why it was lost."""
        cfg = self.config
        gray = ctx.gray
        H, W = gray.shape
        x0, y0, x1, y1 = self._box
        mx = cfg.search_margin * (x1 - x0) + cfg.lk_window_px
        my = cfg.search_margin * (y1 - y0) + cfg.lk_window_px
        c0, r0 = int(max(x0 - mx, 0)), int(max(y0 - my, 0))
        c1, r1 = int(min(x1 + mx + 1, W)), int(min(y1 + my + 1, H))
        if c1 - c0 < 8 or r1 - r0 < 8:
            return "the lead left the image", False
        off = np.array([c0, r0], np.float32)
        p0 = self._points
        flow = track_fb(
            np.ascontiguousarray(prev[r0:r1, c0:c1]),
            np.ascontiguousarray(gray[r0:r1, c0:c1]),
            p0 - off,
            win=cfg.lk_window_px,
            levels=cfg.lk_levels,
            max_fb_px=cfg.max_fb_px,
        )
        p1 = flow.p1 + off
        ok = flow.ok
        if np.count_nonzero(ok) < cfg.min_points:
            return f"track lost ({int(np.count_nonzero(ok))} points passed LK)", False
        a = p0[ok].astype(np.float64)
        b = p1[ok].astype(np.float64)
        model, res, _ = fit_similarity(a, b - a)
        scale = max(1.4826 * float(np.median(res)), 1e-3)
        inl = res <= max(cfg.outlier_mads * scale, cfg.min_outlier_px)
        # points must stay inside the (moved) box
        nb = self._moved_box(model)
        bx = b[:, 0]
        by = b[:, 1]
        inl &= (bx >= nb[0]) & (bx <= nb[2]) & (by >= nb[1]) & (by <= nb[3])
        n_in = int(np.count_nonzero(inl))
        if n_in < cfg.min_points or n_in < cfg.min_inlier_fraction * p0.shape[0]:
            return f"track lost ({n_in} of {p0.shape[0]} points consistent)", False
        if n_in < a.shape[0]:  # refit on the inliers only
            model, _, _ = fit_similarity(a[inl], b[inl] - a[inl])
            nb = self._moved_box(model)
        for name in ("_anchor", "_anchor_l", "_anchor_r"):
            ax, ay = getattr(self, name)
            dx, dy = _move(model, ax, ay)
            setattr(self, name, (ax + dx, ay + dy))
        box = clip_box(nb, W, H)
        if box is None or (box[2] - box[0]) < 2 or (box[3] - box[1]) < 2:
            return "the lead left the image", False
        if box[2] - box[0] > cfg.max_box_width_frac * W:
            return "track lost (the box grew over the road)", False
        if cfg.min_ttc_s > 0.0 and self._expanding(float(model[2]), ctx.t):
            return f"track lost (time to contact {1.0 / self._growth:.2f} s: not a lead)", False
        self._box = box
        self._points = b[inl].astype(np.float32)
        if n_in < cfg.reseed_fraction * self._n_seeded and self._seed(gray, self._box, None):
            return "", True
        return "", False

    def _expanding(self, scale_step: float, t: float) -> bool:
        """Update the smoothed growth rate of the points' scale (1/s) with this frame's scale
        step; True when it implies a time to contact below ``min_ttc_s``."""
        cfg = self.config
        dt = t - self._growth_t
        self._growth_t = t
        if not 0.0 < dt < 1.0:
            return False
        a = min(1.0, dt / cfg.ttc_smoothing_s)
        self._growth += a * (scale_step / dt - self._growth)
        return self._growth * cfg.min_ttc_s > 1.0

    def _moved_box(self, model: NDArray[np.float64]) -> Box:
        x0, y0, x1, y1 = self._box
        d0 = _move(model, x0, y0)
        d1 = _move(model, x1, y1)
        return (x0 + d0[0], y0 + d0[1], x1 + d1[0], y1 + d1[1])

    # -- output -----------------------------------------------------------------------
    def _observation(self, ctx: FrameContext, changed: bool, reseeded: bool) -> LeadObservation:
        d, sd, dw, dg = self.distance(
            self._box, self._edge_sigma, ctx.pitch_rad, bottom_sigma_px=self._bottom_sigma
        )
        return LeadObservation(
            t=ctx.t,
            y=self._anchor[1],
            y_left=self._anchor_l[1],
            y_right=self._anchor_r[1],
            box=self._box,
            n_valid=int(self._points.shape[0]),
            distance_m=d,
            distance_std_m=sd,
            distance_width_m=dw,
            distance_ground_m=dg,
            track_id=self._track_id,
            target_changed=changed,
            reseeded=reseeded,
            class_name=self._class,
        )

    def distance(
        self,
        box: Box,
        edge_sigma_px: float,
        pitch_rad: float = 0.0,
        *,
        bottom_sigma_px: float | None = None,
    ) -> tuple[float, float, float, float]:
        """(fused distance, its std, width cue, ground cue) in metres for ``box``.

        Width: ``d = fx W / w - width_section_ahead_m``; a box touching the left
        or right image edge is cut and gives no width cue. Ground: the bottom
        edge is the rear tyres' contact: ``d = fy h / (v_b - v_horizon) -
        overhang``; a box touching the bottom edge gives no ground cue.
        Variances by first-order propagation; ``bottom_sigma_px`` (default
        ``edge_sigma_px``) is the bottom edge's uncertainty.
        """
        cfg = self.config
        cam = self.camera
        x0, _y0, x1, y1 = box
        w = x1 - x0
        cues: list[tuple[float, float]] = []
        dw = dg = math.nan
        if x0 > 1.0 and x1 < cam.width - 2.0 and w > 1.0:
            dw = cam.fx * cfg.vehicle_width_m / w - cfg.width_section_ahead_m
            rel = math.hypot(
                cfg.vehicle_width_std_m / cfg.vehicle_width_m, math.sqrt(2.0) * edge_sigma_px / w
            )
            cues.append((dw, dw * rel))
        y = y1 - self.horizon_v(pitch_rad)
        if y1 < cam.height - 2.0 and y > 1.0:
            hgt = cam.mount_height_m
            contact = cam.fy * hgt / y
            dg = contact - cfg.rear_overhang_m
            if dg > 0.5:
                sb = edge_sigma_px if bottom_sigma_px is None else bottom_sigma_px
                sv = math.hypot(sb, cam.fy * cfg.pitch_std_rad)
                sd = math.hypot(contact * sv / y, contact * cfg.height_std_m / hgt)
                cues.append((dg, math.hypot(sd, 0.2)))
            else:
                dg = math.nan
        if not cues:
            return math.nan, math.inf, dw, dg
        wts = [1.0 / (s * s) for _, s in cues]
        d = sum(v * q for (v, _), q in zip(cues, wts, strict=True)) / sum(wts)
        return d, 1.0 / math.sqrt(sum(wts)), dw, dg
