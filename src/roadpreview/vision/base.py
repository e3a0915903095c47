"""The lead-finder interface and the value types the vision front end passes around.

A *lead finder* looks at a frame and returns the vehicles it sees as `Detection`
boxes; the lead tracker picks the one nearest the image centre (the paper's
rule) and tracks it. Finding nothing is normal (an empty list), not an error.
Conventions are those of ``docs/method.md``: image u to the right, v (the
paper's y) down, pixels with the origin at the top-left pixel centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import cv2
import numpy as np
from numpy.typing import NDArray

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
#: (x0, y0, x1, y1) in pixels, x0 < x1, y0 < y1
Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class Detection:
    """One vehicle seen in a frame.

    ``box`` is (x0, y0, x1, y1) in full-resolution pixels; ``score`` in [0, 1];
    ``class_name`` the model's class ("car", "bus", "truck") or, for the motion
    finder, what the motion says ("vehicle" moving with or away from the ego,
    "oncoming", "obstacle" standing in the ego lane). ``mask`` is an optional
    full-frame boolean mask (instance segmentation). ``edge_sigma_px`` is the
    1-sigma uncertainty of each box edge, used for the distance's uncertainty;
    ``bottom_sigma_px`` that of the bottom edge when it is less certain than the
    sides (None: ``edge_sigma_px``), e.g. a shadow line that may lie below the contact.
    """

    box: Box
    score: float
    class_name: str
    mask: NDArray[np.bool_] | None = None
    edge_sigma_px: float = 3.0
    bottom_sigma_px: float | None = None

    @property
    def width(self) -> float:
        return self.box[2] - self.box[0]

    @property
    def height(self) -> float:
        return self.box[3] - self.box[1]


@dataclass(frozen=True)
class FrameContext:
    """A frame prepared once per step and shared by the finder and the trackers.

    ``gray`` is the full-resolution grey image, ``small`` the same image
    reduced by ``scale`` (``small`` pixel = ``scale`` x full pixel, centres
    aligned as cv2.resize does). ``pitch_rad`` is the camera's current pitch
    relative to its rest attitude when the caller knows it (nose up positive;
    it moves the horizon down by f tan(pitch)), 0 otherwise.
    """

    t: float
    index: int
    gray: U8
    small: U8
    scale: float
    pitch_rad: float = 0.0

    @classmethod
    def from_frame(
        cls,
        frame_bgr: U8,
        *,
        t: float = 0.0,
        index: int = 0,
        small_width: int = 640,
        pitch_rad: float = 0.0,
    ) -> FrameContext:
        """Grey conversion and the reduced image (area averaging, never enlarged)."""
        gray = frame_bgr if frame_bgr.ndim == 2 else cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2GRAY)
        gray = np.ascontiguousarray(gray, dtype=np.uint8)
        scale, small = reduce_image(gray, small_width)
        return cls(t=t, index=index, gray=gray, small=small, scale=scale, pitch_rad=pitch_rad)


def reduce_image(gray: U8, width: int) -> tuple[float, U8]:
    """``(scale, image)``: ``gray`` area-averaged to about ``width`` columns (scale <= 1)."""
    h, w = gray.shape[:2]
    if w <= width:
        return 1.0, gray
    scale = width / w
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    # the exact scale of the integer size (x and y may differ by < 0.5 px out of hundreds)
    scale = size[0] / w
    return scale, np.asarray(cv2.resize(gray, size, interpolation=cv2.INTER_AREA), np.uint8)


def to_full(points_small: NDArray[np.floating], scale: float) -> F64:
    """Small-image pixel coordinates to full-resolution ones (pixel centres aligned)."""
    return (np.asarray(points_small, np.float64) + 0.5) / scale - 0.5


def to_small(points_full: NDArray[np.floating], scale: float) -> F64:
    """Full-resolution pixel coordinates to small-image ones."""
    return (np.asarray(points_full, np.float64) + 0.5) * scale - 0.5


def box_to_full(box_small: Box, scale: float, width: int, height: int) -> Box:
    """A small-image box in full-resolution pixels, clamped to a ``width`` x ``height`` image."""
    lo = to_full(np.array([box_small[:2]]), scale)[0]
    hi = to_full(np.array([box_small[2:]]), scale)[0]
    return (
        float(max(lo[0], 0.0)),
        float(max(lo[1], 0.0)),
        float(min(hi[0], width - 1.0)),
        float(min(hi[1], height - 1.0)),
    )


@runtime_checkable
class LeadFinder(Protocol):
    """Finds vehicles in a frame; the tracker picks the lead among them.

    ``find`` is called on frames where (re)detection is wanted and ``observe``
    on every other frame, so that a finder that needs history (the motion
    finder compares with an earlier frame) can keep it. Both take the shared
    `FrameContext` (built from the frame when None). Normal failure is an empty
    list, with ``last_reason`` saying why.

    Optional, read by the front end when present: ``find_steps(frame, context)``, a
    generator doing ``find`` in slices (the front end spreads them over frames); and
    two class attributes it reads before building the finder (False when absent):
    ``shares_small_image`` (the finder's config has ``small_width_px`` and works on the
    front end's reduced image: it gets the front end's width unless its options set
    one) and ``lead_at_any_distance`` (its detection is the lead however near: the
    tracker's ``min_distance_m`` does not apply, e.g. the user's box).
    """

    #: registry name (`roadpreview.vision.FINDERS`: "motion", "onnx", "box")
    name: str
    #: why the last ``find`` returned nothing ("" when it found something)
    last_reason: str

    def find(self, frame_bgr: U8, context: FrameContext | None = None) -> list[Detection]:
        """The vehicles in ``frame_bgr`` (full-resolution boxes), best first or any order."""
        ...

    def observe(self, frame_bgr: U8, context: FrameContext | None = None) -> None:
        """A frame on which ``find`` is not called (keep history if needed)."""
        ...

    def reset(self) -> None:
        """Forget any history (new sequence)."""
        ...


# -- box helpers (a handful of boxes: plain Python is fine) ---------------------------
def box_iou(a: Box, b: Box) -> float:
    """Intersection over union of two boxes (0 when disjoint or degenerate)."""
    ix = min(a[2], b[2]) - max(a[0], b[0])
    iy = min(a[3], b[3]) - max(a[1], b[1])
    if ix <= 0.0 or iy <= 0.0:
        return 0.0
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0.0 else 0.0


def clip_box(box: Box, width: int, height: int) -> Box | None:
    """``box`` clipped to the image; None when nothing of it is left (or not finite)."""
    if not all(math.isfinite(v) for v in box):
        return None
    x0 = min(max(box[0], 0.0), width - 1.0)
    y0 = min(max(box[1], 0.0), height - 1.0)
    x1 = min(max(box[2], 0.0), width - 1.0)
    y1 = min(max(box[3], 0.0), height - 1.0)
    if x1 - x0 < 1.0 or y1 - y0 < 1.0:
        return None
    return (x0, y0, x1, y1)
