"""A lead finder that returns a box given by the user (CLI or config) for the first frame.

It cannot re-acquire: once the box has been handed to the tracker, ``find``
returns nothing (``last_reason`` says so), and a lost track stays lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from roadpreview.camera import CameraModel
from roadpreview.configtools import param
from roadpreview.errors import ConfigError
from roadpreview.vision.base import U8, Detection, FrameContext


@dataclass(frozen=True)
class BoxFinderConfig:
    """The user's box of the lead vehicle in the first frame."""

    box: tuple[float, float, float, float] = param(
        (0.0, 0.0, 0.0, 0.0), unit="px", help="x0, y0, x1, y1 of the lead in the first frame"
    )
    edge_sigma_px: float = param(3.0, unit="px", gt=0.0, help="how exactly it was drawn")

    def validate(self, where: str = "BoxFinderConfig") -> None:
        x0, y0, x1, y1 = self.box
        if not all(math.isfinite(v) for v in self.box) or x1 <= x0 or y1 <= y0:
            raise ConfigError(f"{where}.box = {list(self.box)}: need x0 < x1 and y0 < y1 (px)")


class BoxLeadFinder:
    """Hands the user's box to the tracker once."""

    name = "box"
    #: the user's box is the lead however near (the tracker's min_distance_m does not apply)
    lead_at_any_distance: ClassVar[bool] = True

    def __init__(self, camera: CameraModel, config: BoxFinderConfig | None = None) -> None:
        self.camera = camera
        self.config = config or BoxFinderConfig()
        self.config.validate()
        x0, y0, x1, y1 = self.config.box
        if x1 <= 0 or y1 <= 0 or x0 >= camera.width or y0 >= camera.height:
            raise ConfigError(
                f"box = {list(self.config.box)}: outside the {camera.width}x{camera.height} image"
            )
        self.last_reason = ""
        self._used = False

    def find(self, frame_bgr: U8, context: FrameContext | None = None) -> list[Detection]:
        if self._used:
            self.last_reason = "the user's box was used on the first frame; cannot re-acquire"
            return []
        self._used = True
        self.last_reason = ""
        return [Detection(self.config.box, 1.0, "user", edge_sigma_px=self.config.edge_sigma_px)]

    def observe(self, frame_bgr: U8, context: FrameContext | None = None) -> None:
        return None

    def reset(self) -> None:
        self._used = False
