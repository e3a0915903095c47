"""The vision step per frame: lead finder + lead tracker + background tracker.

``VisionFrontEnd.process(t, frame)`` prepares the frame once (grey, reduced
image), runs the finder when there is no target or every ``redetect_s`` (to
see cut-ins and the other vehicles to mask; a sliced finder's run is spread
over the next frames, see `VisionFrontEnd._finder_step`), tracks the lead, and
tracks the background outside every vehicle box. A missing, black or corrupt frame gives
a falsy lead observation and no correspondences, with the reason, never an
exception; the trackers then continue from the last good frame.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from roadpreview.camera import CameraModel
from roadpreview.configtools import check_ranges, param
from roadpreview.vision import FINDERS, finder_class, make_finder
from roadpreview.vision.background import (
    BackgroundConfig,
    BackgroundCorrespondences,
    BackgroundTracker,
)
from roadpreview.vision.base import U8, Box, Detection, FrameContext, LeadFinder
from roadpreview.vision.tracker import LeadObservation, LeadTrackerConfig, LeadVehicleTracker


@dataclass(frozen=True)
class VisionConfig:
    """Settings of the vision front end (``[vision]`` in the configuration)."""

    finder: str = param(
        "motion", choices=tuple(FINDERS), help="built-in motion finder needs no model"
    )
    finder_options: dict[str, Any] = field(default_factory=dict)
    small_width_px: int = param(
        640, unit="px", ge=160, le=1920, help="background and motion work at this width (budget)"
    )
    redetect_s: float = param(
        0.3,
        unit="s",
        gt=0.0,
        help="run the finder this often while tracking (cut-ins, masks); ~2 ms/frame amortised",
    )
    finder_spread_s: float = param(
        0.09,
        unit="s",
        ge=0.0,
        le=1.0,
        help="a sliced finder's run (motion: 3 slices of ~7 ms) is spread over the frames "
        "due within this time of it: 3 frames at 30 fps, 2 at 15-20 fps, 1 at 10 fps "
        "(0: all in one frame); its detections apply on the last, moved with the lead",
    )
    detection_ttl_s: float = param(
        0.5, unit="s", gt=0.0, help="other vehicles' boxes mask the background this long"
    )
    detection_growth_per_s: float = param(
        0.5, ge=0.0, help="their boxes grow by this fraction per second of age (they move)"
    )
    min_frame_std: float = param(
        2.0, ge=0.0, help="a frame with less grey-level spread is blank (black, covered)"
    )
    tracker: LeadTrackerConfig = field(default_factory=LeadTrackerConfig)
    background: BackgroundConfig = field(default_factory=BackgroundConfig)

    def validate(self, where: str = "vision") -> None:
        check_ranges(self, where)
        self.tracker.validate(f"{where}.tracker")
        self.background.validate(f"{where}.background")


@dataclass(frozen=True)
class FrameVision:
    """Everything the vision step saw in one frame.

    ``detections`` are the finder's results handed to the tracker on this frame, found
    on frame ``detected_index`` (earlier when the finder's run was spread over frames;
    None when none were handed over); ``finder_ran``: the finder worked on this frame
    (a whole run or a slice). ``timings_ms`` holds the duration of each part (finder,
    lead, background, total) when the front end was given a clock, else it is empty.
    """

    t: float
    index: int
    lead: LeadObservation
    background: BackgroundCorrespondences
    detections: tuple[Detection, ...] = ()
    finder_ran: bool = False
    detected_index: int | None = None
    reason: str = ""
    timings_ms: dict[str, float] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return not self.reason


class VisionFrontEnd:
    """Turns frames into lead observations and background correspondences.

    ``clock`` (e.g. ``time.perf_counter``) is only for profiling: when given,
    every `FrameVision` carries the time spent in each part.
    """

    def __init__(
        self,
        camera: CameraModel,
        config: VisionConfig | None = None,
        *,
        finder: LeadFinder | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        self.camera = camera
        self.config = config or VisionConfig()
        self.config.validate()
        # what the front end adapts to is declared by the finder's class (`LeadFinder`)
        cls = finder_class(self.config.finder)
        options = dict(self.config.finder_options)
        if getattr(cls, "shares_small_image", False):
            options.setdefault("small_width_px", self.config.small_width_px)
        self.finder: LeadFinder = finder or make_finder(self.config.finder, camera, **options)
        tracker_cfg = self.config.tracker
        if getattr(cls, "lead_at_any_distance", False):
            tracker_cfg = replace(tracker_cfg, min_distance_m=0.0)
        self.tracker = LeadVehicleTracker(camera, tracker_cfg)
        self.background = BackgroundTracker(self.config.background)
        self._clock = clock
        self.reset()

    def reset(self) -> None:
        """Start a new sequence."""
        job = getattr(self, "_job", None)
        if job is not None:
            job.close()
        self.finder.reset()
        self.tracker.reset()
        self.background.reset()
        self._index = 0
        self._last_find_t = -math.inf
        self._prev_t = -math.inf
        self._others: list[tuple[float, Detection]] = []
        self._job: Generator[None, None, list[Detection]] | None = None
        self._job_index = 0
        self._job_t = 0.0
        self._job_frames_left = 0

    def check_frame(self, frame: object) -> str:
        """Why ``frame`` cannot be used ('' when it can)."""
        cam = self.camera
        if frame is None:
            return "no frame"
        if not isinstance(frame, np.ndarray):
            return f"frame is a {type(frame).__name__}, not an image array"
        if frame.dtype != np.uint8:
            return f"frame has dtype {frame.dtype}, expected uint8"
        if frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] != 3):
            return f"frame has shape {frame.shape}, expected (H, W, 3) BGR"
        if frame.shape[:2] != (cam.height, cam.width):
            return (
                f"frame is {frame.shape[1]}x{frame.shape[0]}, the camera is "
                f"{cam.width}x{cam.height}"
            )
        return ""

    def process(self, t: float, frame: U8 | None, *, pitch_rad: float = 0.0) -> FrameVision:
        """One frame (BGR uint8, the camera's size) at time ``t`` (s).

        ``pitch_rad`` is the camera's current pitch relative to rest if known
        (it places the horizon for the motion finder and the ground distance).
        """
        clock = self._clock
        t0 = clock() if clock else 0.0
        index = self._index
        self._index += 1
        reason = self.check_frame(frame)
        image = None if reason else frame  # a uint8 (H, W, 3) array of the camera's size
        ctx: FrameContext | None = None
        if image is not None:
            ctx = FrameContext.from_frame(
                image,
                t=t,
                index=index,
                small_width=self.config.small_width_px,
                pitch_rad=pitch_rad,
            )
            _, std = cv2.meanStdDev(ctx.small)
            if float(std[0, 0]) < self.config.min_frame_std:
                reason = "blank frame (black or uniform)"
        if reason or ctx is None or image is None:
            return FrameVision(
                t=t,
                index=index,
                lead=LeadObservation.none(t, reason, track_id=self.tracker._track_id),
                background=BackgroundCorrespondences.empty(t, index, reason),
                reason=reason,
            )

        # the finder: when there is no target, else every redetect_s
        t1 = clock() if clock else 0.0
        detections, detected_index, ran = self._finder_step(t, index, image, ctx)
        t2 = clock() if clock else 0.0
        lead = self.tracker.update(ctx, detections, detected_index=detected_index)
        t3 = clock() if clock else 0.0
        boxes = self._vehicle_boxes(
            t, self._job_t if detections is not None else t, detections, lead
        )
        bg = self.background.update(ctx, boxes)
        t4 = clock() if clock else 0.0
        timings = (
            {
                "finder": (t2 - t1) * 1e3,
                "lead": (t3 - t2) * 1e3,
                "background": (t4 - t3) * 1e3,
                "total": (t4 - t0) * 1e3,
            }
            if clock
            else {}
        )
        return FrameVision(
            t=t,
            index=index,
            lead=lead,
            background=bg,
            detections=tuple(detections or ()),
            finder_ran=ran,
            detected_index=detected_index,
            timings_ms=timings,
        )

    def _finder_step(
        self, t: float, index: int, frame: U8, ctx: FrameContext
    ) -> tuple[list[Detection] | None, int | None, bool]:
        """Start, continue or finish the finder's run on this frame.

        ``(detections, detected_index, ran)``: the detections completed on this frame and
        the index of the frame they were found on (None, None when none completed), and
        whether the finder worked. A finder with ``find_steps`` (the motion finder) has its
        run spread over the frames due within ``finder_spread_s`` of it: the number of
        frames is fixed when the run starts from the last frame interval, one slice per
        frame, all that is left on the last. Which frame does what depends only on the
        frames' time stamps, never on the time taken: replay and daemon agree.
        """
        cfg = self.config
        dt = t - self._prev_t
        self._prev_t = t
        due = not self.tracker.active or (t - self._last_find_t) >= 0.999 * cfg.redetect_s
        if self._job is None:
            if not due:
                self.finder.observe(frame, ctx)
                return None, None, False
            self._last_find_t = self._job_t = t
            self._job_index = index
            steps = getattr(self.finder, "find_steps", None)
            frames = 1 + int(cfg.finder_spread_s / dt) if dt > 0.0 else 1
            if steps is None or frames <= 1:
                return self.finder.find(frame, ctx), index, True
            self._job = steps(frame, ctx)
            self._job_frames_left = frames
        else:
            self.finder.observe(frame, ctx)  # the history goes on meanwhile
        self._job_frames_left -= 1
        try:
            next(self._job)
            while self._job_frames_left <= 0:  # the last frame of the run: finish it
                next(self._job)
        except StopIteration as stop:
            self._job = None
            return list(stop.value), self._job_index, True
        return None, None, True

    def _vehicle_boxes(
        self,
        t: float,
        t_detected: float,
        detections: list[Detection] | None,
        lead: LeadObservation,
    ) -> list[Box]:
        """The lead's box and every recent detection (grown with age: they move)."""
        cfg = self.config
        if detections is not None:
            self._others = [(t_detected, d) for d in detections]
        self._others = [(td, d) for td, d in self._others if t - td <= cfg.detection_ttl_s]
        boxes: list[Box] = []
        for td, d in self._others:  # a handful of detections
            g = cfg.detection_growth_per_s * (t - td)
            x0, y0, x1, y1 = d.box
            w, h = x1 - x0, y1 - y0
            boxes.append((x0 - g * w, y0 - g * h, x1 + g * w, y1 + g * h))
        if lead.box is not None:
            boxes.append(lead.box)
        return boxes
