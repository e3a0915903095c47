"""Is a decoded video frame the scene, or decoder garbage? A content-jump check on thumbnails.

A damaged video decodes into frames that are not the scene: after undecodable frames,
a predictive codec (MPEG-4, H.264) builds every frame up to the next key frame on a
reference it never received ("ghosts": the scene of a second ago plus today's
residuals), and bytes that decode without error give smeared blocks. Either way the
content jumps in a way the ego's motion cannot explain. The measure: both frames as
64 x 36 grey thumbnails (area average), the mean brightness change removed (exposure),
the mean absolute difference in grey levels (`content_jump`).

Threshold (`JUMP_GREY`), measured on clean drives: consecutive frames of simulated
drives (demo, controlled; 320x180 to 640x360, 30 fps) differ by at most 7.7 grey
levels, the 78 real KITTI frames (10 fps: three times a 30 fps camera's motion per
frame) by at most 9.4; a damaged MPEG-4 stream's key frame after its ghosts jumps by
12.6 to 24 against the last good frame, and garbage against the frame before it
similarly. 12 lies between.

`FrameIntegrity` is the rule a video source applies frame by frame:

* trusted (the normal state): a frame is good unless it jumps against the last good
  frame by more than `JUMP_GREY` (then it is corrupt and trust is lost);
* after an undecodable frame or a corrupt one, trust is lost: frames are dropped until
  the picture is re-anchored, i.e. a jump against the frame before (the key frame
  that ends the ghosts, or garbage ending) followed by a frame consistent with it, which
  is good; after `max_untrusted` frames without such a jump (a still scene, where
  ghosts equal the scene) the first frame consistent with the one before is good.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.types import Image

#: thumbnail size (width, height) for the jump measure
THUMB_SIZE = (64, 36)
#: content jump (mean abs grey difference, brightness removed) that ego motion does not make
JUMP_GREY = 12.0

Thumb = NDArray[np.float32]


def thumbnail(image: Image) -> Thumb:
    """``image`` (BGR or grey, uint8) as a `THUMB_SIZE` grey float32 thumbnail."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    small = cv2.resize(grey, THUMB_SIZE, interpolation=cv2.INTER_AREA)
    return small.astype(np.float32)


def content_jump(a: Thumb, b: Thumb) -> float:
    """Mean absolute grey difference between two thumbnails, their mean difference (a
    brightness or exposure change) removed; grey levels (0-255)."""
    d = b - a
    return float(np.mean(np.abs(d - np.mean(d))))


class Verdict(str, Enum):
    """What `FrameIntegrity.check` makes of a frame."""

    GOOD = "good"
    CORRUPT = "corrupt"  #: jumps against the last good frame (trust lost)
    UNTRUSTED = "untrusted"  #: after damage, before the picture is re-anchored


@dataclass
class FrameIntegrity:
    """The frame-by-frame rule of the module docstring. ``check`` each decoded frame's
    thumbnail in order and call ``undecodable`` for a frame that could not be decoded."""

    threshold: float = JUMP_GREY
    max_untrusted: int = 60  #: frames dropped at most without a re-anchoring jump (2 s)
    last_jump: float = 0.0  #: the last frame's jump against its reference, grey levels
    _good: Thumb | None = field(default=None, repr=False)
    _prev: Thumb | None = field(default=None, repr=False)  #: the last decoded frame
    _trusted: bool = True
    _anchor: Thumb | None = field(default=None, repr=False)  #: a jump's frame, to confirm
    _dropped: int = 0  #: frames dropped since trust was lost

    @property
    def trusted(self) -> bool:
        return self._trusted

    def undecodable(self) -> None:
        """A frame could not be decoded: the decoder's references are broken."""
        self._lose_trust()

    def _lose_trust(self) -> None:
        if self._trusted:
            self._trusted = False
            self._dropped = 0
            self._anchor = None

    def check(self, thumb: Thumb) -> Verdict:
        """The verdict on the next decoded frame (module docstring)."""
        prev, self._prev = self._prev, thumb
        if self._trusted:
            if self._good is None:
                self._good = thumb
                return Verdict.GOOD
            self.last_jump = content_jump(self._good, thumb)
            if self.last_jump > self.threshold:
                self._lose_trust()
                self._dropped = 1
                return Verdict.CORRUPT
            self._good = thumb
            return Verdict.GOOD
        self._dropped += 1
        self.last_jump = content_jump(prev, thumb) if prev is not None else np.inf
        if self._anchor is not None and content_jump(self._anchor, thumb) <= self.threshold:
            return self._regain(thumb)
        self._anchor = None
        if self.last_jump > self.threshold:
            self._anchor = thumb  # a jump: the new picture, if the next frame agrees
        elif self._dropped > self.max_untrusted:
            return self._regain(thumb)
        return Verdict.UNTRUSTED

    def _regain(self, thumb: Thumb) -> Verdict:
        self._trusted = True
        self._anchor = None
        self._good = thumb
        return Verdict.GOOD
