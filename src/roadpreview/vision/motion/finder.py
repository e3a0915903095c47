"""The built-in lead finder without a model: vehicles are what the static-scene flow cannot explain.

Between an earlier frame and the current one (``baseline_s`` apart), corners
are tracked by LK with a forward-backward check on the reduced image. The
camera's rotation between the two frames is fitted with the project's robust
pitch estimator (pitch and yaw, vehicles are its outliers) and removed; what is
left of a static point's motion is the expansion from the focus of expansion
(FOE) by the ego's forward motion::

    x' - foe = (1 + e) (x - foe),   e = Δ / (Z - Δ)

with Z the point's depth and Δ the ego's travel. A point of the flat road at
row v (y = v - v_horizon below the horizon) has Z = f h / y, so the road
expands by ``e_g(y) = k y / (f - k y)`` with ``k = Δ / h`` (h the camera
height). k is fitted to the points robustly (a Cauchy cost over a 1-D grid of
k; points that hardly move are left out, since they say nothing about k).

A rigid object at distance d moving along the road expands by e = (closing
speed x time) / d, the same for all its points. With the road's expansion at
the object's lowest point (its contact with the road) as reference,
``ratio = e_object / e_g(bottom)`` is 0 for a vehicle keeping its distance,
below 1 for one pulling away, 1 for a static object and above 1 for one
coming towards us; a static object's points above its base expand faster than
the road behind them. Non-road points are grouped into spatially connected
clusters with one common expansion; a cluster is reported as

* ``vehicle``: ratio < ``ratio_slow`` (moves with or away from us: the lead),
* ``oncoming``: ratio > ``ratio_fast`` and *floating*: its expansion would put
  a static object's base far below its lowest point,
* ``obstacle``: static-looking but standing in the ego lane (a stopped lead),

and boxed (the cluster's hull grown by half a sampling cell). The lead window's
box is fitted to the image by `fit_rear` (symmetric side edges, the bottom's
shadow line, a width that fits the flat-road distance of that bottom). The tracker
picks the lead among them. When the ego hardly moves there is no parallax and
nothing is found (``last_reason`` says so): the tracker keeps its target.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Generator
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.pitch.robust_lm import RobustPitchConfig, RobustPitchEstimator
from roadpreview.vision.base import F64, U8, Box, Detection, FrameContext, box_to_full
from roadpreview.vision.features import corner_strength, grid_features, track_fb
from roadpreview.vision.motion.clusters import ClusterRecord, find_clusters
from roadpreview.vision.motion.config import MotionFinderConfig
from roadpreview.vision.motion.egomotion import (
    ViewGeometry,
    fit_road,
    point_motion,
    road_expansion,
)
from roadpreview.vision.motion.rear import RearFit, fit_rear, refine_sides
from roadpreview.vision.motion.window import LeadWindow, find_lead_window


@dataclass
class _History:
    t: float
    index: int
    small: U8


@dataclass
class MotionDiagnostics:
    """What the last `MotionLeadFinder.find` measured (for tests and tuning)."""

    k: float = math.nan
    road_points: int = 0
    points: int = 0
    baseline_frames: int = 0
    pitch_rad: float = math.nan
    yaw_rad: float = math.nan
    clusters: list[ClusterRecord] = field(default_factory=list)
    rear: RearFit | None = None
    #: per point: positions ``a``, expansion ``e``, residual ``res`` and its ``tol``, ``odd``
    arrays: dict[str, F64 | NDArray[np.bool_]] = field(default_factory=dict)


class MotionLeadFinder:
    """Finds vehicles by their motion relative to the static scene (no model needed)."""

    name = "motion"
    #: works on the front end's reduced image: takes its small_width_px
    shares_small_image: ClassVar[bool] = True

    def __init__(self, camera: CameraModel, config: MotionFinderConfig | None = None) -> None:
        self.camera = camera
        self.config = config or MotionFinderConfig()
        self.config.validate()
        self._rear_fit = self.config.rear_fit()
        self.last_reason = ""
        self.diagnostics = MotionDiagnostics()
        self._history: deque[_History] = deque()
        self._index = 0
        self._rotation = RobustPitchEstimator(
            camera, RobustPitchConfig(dof="pitch_yaw", min_correspondences=12)
        )
        self._cam_small: CameraModel | None = None

    def reset(self) -> None:
        self._history.clear()
        self._rotation.reset()
        self.last_reason = ""

    # -- history ----------------------------------------------------------------------
    def _context(self, frame_bgr: U8, context: FrameContext | None) -> FrameContext:
        if context is not None:
            return context
        ctx = FrameContext.from_frame(
            frame_bgr,
            t=float(self._index),
            index=self._index,
            small_width=self.config.small_width_px,
        )
        self._index += 1
        return ctx

    def _remember(self, ctx: FrameContext) -> None:
        hist = self._history
        if hist and ctx.t <= hist[-1].t:  # time went back: a new sequence
            hist.clear()
        hist.append(_History(ctx.t, ctx.index, ctx.small))
        keep = 2.0 * self.config.baseline_s
        while len(hist) > 2 and ctx.t - hist[1].t >= keep:
            hist.popleft()

    def observe(self, frame_bgr: U8, context: FrameContext | None = None) -> None:
        self._remember(self._context(frame_bgr, context))

    def _reference(self, t: float) -> _History | None:
        best = None
        target = t - self.config.baseline_s
        for h in self._history:  # a handful of frames
            if h.t < t and (best is None or abs(h.t - target) < abs(best.t - target)):
                best = h
        return best

    def _small_camera(self, small: U8) -> CameraModel:
        h, w = small.shape
        cam = self._cam_small
        if cam is None or cam.width != w or cam.height != h:
            cam = self.camera.scaled(w, h)
            self._cam_small = cam
            self._rotation = RobustPitchEstimator(
                cam, RobustPitchConfig(dof="pitch_yaw", min_correspondences=12)
            )
        return cam

    # -- finding ----------------------------------------------------------------------
    def find(self, frame_bgr: U8, context: FrameContext | None = None) -> list[Detection]:
        return run_steps(self.find_steps(frame_bgr, context))

    def find_steps(
        self, frame_bgr: U8, context: FrameContext | None = None
    ) -> Generator[None, None, list[Detection]]:
        """`find` in three slices of similar cost, for the front end to spread over
        consecutive frames: it yields after the corners' flow (slice 1) and after the
        motion analysis (slice 2: rotation, road, clusters, lead window); the rear fit is
        slice 3, and the generator returns the detections. Everything is computed from
        this frame and its reference: when the slices run does not change the result.
        The history is updated at once (later frames go to `observe`)."""
        ctx = self._context(frame_bgr, context)
        ref = self._reference(ctx.t)
        self._remember(ctx)
        self.diagnostics = MotionDiagnostics()
        if ref is None or ctx.t - ref.t < 0.5 * self.config.baseline_s:
            # one frame of history is too little parallax: a box found then is unreliable
            self.last_reason = "motion finder needs an earlier frame (baseline_s of history)"
            return []
        if ref.small.shape != ctx.small.shape:
            self.last_reason = "frame size changed"
            return []
        self.diagnostics.baseline_frames = ctx.index - ref.index
        dets = yield from self._find_steps(ref.small, ctx.small, ctx)
        self.last_reason = "" if dets else (self.last_reason or "no vehicle moves unlike the scene")
        return dets

    def _find_steps(
        self, img0: U8, img1: U8, ctx: FrameContext
    ) -> Generator[None, None, list[Detection]]:
        cfg = self.config
        cam = self._small_camera(img1)
        h, w = img1.shape
        f = cam.fy
        t = cam.t
        foe = np.array([cam.fx * t[0] / t[2] + cam.cx, cam.fy * t[1] / t[2] + cam.cy])
        v_h = float(foe[1] + f * math.tan(ctx.pitch_rad))
        hgt = self.camera.mount_height_m

        # corners: coarse everywhere from just above the horizon down, fine near the FOE
        top = int(max(0.0, v_h - cfg.above_horizon * h))
        # the strength only where corners are taken (a 3x3 derivative and a 3x3 block: rows
        # from 2 below the crop's edge on are those of the whole image)
        strength = np.zeros(img0.shape, np.float32)
        r_c = max(0, top - 3)
        strength[r_c:] = corner_strength(img0[r_c:])
        border = cfg.lk_window_px // 2 + 1
        p_coarse, _ = grid_features(
            strength, cfg.cell_px, cfg.min_corner, border=border, roi=(0, top, w, h)
        )
        fx0 = int(foe[0] - cfg.fine_half_width * w)
        fx1 = int(foe[0] + cfg.fine_half_width * w)
        fy0 = int(max(0.0, v_h - 0.02 * h))
        fy1 = int(min(h, v_h + cfg.fine_below * h))
        p_fine, _ = grid_features(
            strength, cfg.fine_cell_px, cfg.min_corner, border=border, roi=(fx0, fy0, fx1, fy1)
        )
        if p_fine.shape[0]:  # drop coarse points inside the fine zone
            in_fine = (
                (p_coarse[:, 0] >= fx0)
                & (p_coarse[:, 0] < fx1)
                & (p_coarse[:, 1] >= fy0)
                & (p_coarse[:, 1] < fy1)
            )
            p_coarse = p_coarse[~in_fine]
        p0 = np.concatenate([p_coarse, p_fine])
        self.diagnostics.points = int(p0.shape[0])
        if p0.shape[0] < 2 * cfg.min_points:
            self.last_reason = f"too little texture ({p0.shape[0]} corners)"
            return []
        flow = track_fb(
            img0, img1, p0, win=cfg.lk_window_px, levels=cfg.lk_levels, max_fb_px=cfg.max_fb_px
        )
        a = p0[flow.ok].astype(np.float64)
        b = flow.p1[flow.ok].astype(np.float64)
        if a.shape[0] < 2 * cfg.min_points:
            self.last_reason = f"too few tracked corners ({a.shape[0]})"
            return []
        yield  # end of slice 1: the flow

        # the camera's rotation between the frames (vehicles are outliers), then remove it
        self._rotation.reset()
        rot = self._rotation.estimate(a, b)
        if not rot:
            self.last_reason = f"rotation fit failed: {rot.reason}"
            return []
        self.diagnostics.pitch_rad, self.diagnostics.yaw_rad = rot.phi, rot.yaw
        geom = ViewGeometry(f=f, foe=foe, v_horizon=v_h, height_m=hgt)
        pts = point_motion(a, b, cam, rot.phi, rot.yaw, geom, cfg.max_perp_px)

        # the road's expansion per unit height below the horizon: k = Δ / h
        road = fit_road(pts, geom, cfg)
        self.diagnostics.road_points = road.road_points
        if not road:
            self.last_reason = road.reason
            return []
        k = road.k
        self.diagnostics.k = k
        e_g = road_expansion(k, pts.y, f)
        res = pts.rn * (pts.e - e_g)  # px: + faster than the road (standing, closer), - slower
        tol = 3.0 * cfg.noise_px + 0.25 * np.abs(pts.rn * e_g)
        below = pts.y > 1.0
        moving_odd = pts.usable & below & ((np.abs(res) > tol) | ~pts.radial)
        self.diagnostics.arrays = {"a": a, "e": pts.e, "res": res, "odd": moving_odd, "tol": tol}
        clusters = find_clusters(
            pts, moving_odd, k, geom, ctx.small, ctx.scale, self.camera.size, cfg
        )
        self.diagnostics.clusters.extend(clusters.records)
        if clusters.reason:
            self.last_reason = clusters.reason
        dets = clusters.detections
        window = find_lead_window(pts, res, tol, k, geom, h, cfg)
        if window is not None:
            yield  # end of slice 2: the motion analysis; slice 3 fits the lead's rear
            lead = self._lead_detection(window, v_h, f, ctx)
            # the window search is more complete than a cluster of the same vehicle
            dets = [d for d in dets if _overlap(d.box, lead.box) < 0.3] + [lead]
        if dets:
            self.last_reason = ""
        return dets

    def _lead_detection(
        self, window: LeadWindow, v_h: float, f: float, ctx: FrameContext
    ) -> Detection:
        """The lead window's box fitted to the image (`fit_rear`, else symmetric edges)."""
        cfg = self.config
        rough, dist = window.rough, window.distance_m
        fit = self._fit_rear(ctx.small, rough, v_h, f)
        if fit is not None:
            box_s = fit.box
        else:
            box_s = refine_sides(
                ctx.small,
                rough,
                dist,
                f,
                min_width_m=cfg.min_vehicle_width_m,
                max_width_m=cfg.max_refine_width_m,
                pad_px=0.25 * cfg.cell_px,
            )
            # a vehicle's rear is at least 0.8 times as tall as it is wide
            top_v = min(rough[1], rough[3] - 0.8 * (box_s[2] - box_s[0]))
            box_s = (box_s[0], top_v, box_s[2], rough[3])
        self.diagnostics.clusters.append(
            ClusterRecord(
                n=window.n,
                box_small=box_s,
                e=window.e,
                ratio=window.ratio,
                distance_m=dist,
                lateral_m=window.lateral_m,
                kind="lead-window",
            )
        )
        box = box_to_full(box_s, ctx.scale, self.camera.width, self.camera.height)
        kind = "vehicle" if window.slow else "obstacle"
        score = float(np.clip(1.0 - window.ratio, 0.05, 1.0))
        bw = box[2] - box[0]
        return Detection(
            box,
            score,
            kind,
            edge_sigma_px=max(2.0 / ctx.scale, 0.05 * bw),
            bottom_sigma_px=None if fit is None else cfg.rear_bottom_sigma * bw,
        )

    def _fit_rear(self, img: U8, rough: Box, v_h: float, f: float) -> RearFit | None:
        """`fit_rear` with this finder's settings; None when the edges are too weak."""
        cfg = self.config
        fit = fit_rear(
            img,
            rough,
            v_horizon=v_h,
            f=f,
            height_m=self.camera.mount_height_m,
            config=self._rear_fit,
        )
        self.diagnostics.rear = fit
        if fit is None or fit.edge < cfg.rear_min_edge:
            return None
        return fit


def run_steps(steps: Generator[None, None, list[Detection]]) -> list[Detection]:
    """Run a sliced find (``find_steps``) to the end; its detections."""
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return list(stop.value)


def _overlap(a: Box, b: Box) -> float:
    """Intersection over the smaller box's area."""
    ix = min(a[2], b[2]) - max(a[0], b[0])
    iy = min(a[3], b[3]) - max(a[1], b[1])
    if ix <= 0 or iy <= 0:
        return 0.0
    small = min((a[2] - a[0]) * (a[3] - a[1]), (b[2] - b[0]) * (b[3] - b[1]))
    return ix * iy / small if small > 0 else 0.0
