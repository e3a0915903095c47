"""`Texture`: an image with the mip pyramid the renderer samples it from."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

U8 = NDArray[np.uint8]

_PYR_KERNEL = np.array([1.0, 3.0, 3.0, 1.0], dtype=np.float32) / 8.0


def _pyr_down(img: U8) -> U8:
    """Half-size image whose pixel i is centred on level-0 coordinate 2i + 0.5.

    `cv2.pyrDown` centres pixel i on 2i, which would shift coarser levels by
    half a texel per level; an even [1 3 3 1]/8 kernel keeps every level
    aligned with the texel-edge convention the renderer uses.
    """
    blurred = cv2.sepFilter2D(img, -1, _PYR_KERNEL, _PYR_KERNEL, anchor=(1, 1))
    return np.ascontiguousarray(blurred[::2, ::2])


@dataclass(frozen=True)
class Texture:
    """A texture with its mip pyramid (BGR, or BGRA with a binary-ish alpha)."""

    name: str
    levels: tuple[U8, ...]
    has_alpha: bool
    mean_bgr: tuple[int, int, int]

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of level 0 in texels."""
        return (int(self.levels[0].shape[1]), int(self.levels[0].shape[0]))

    @classmethod
    def build(cls, name: str, image: U8, *, min_size: int = 4) -> Texture:
        """Wrap ``image`` (H, W, 3|4) uint8 and precompute its pyramid."""
        img = np.ascontiguousarray(image, dtype=np.uint8)
        if img.ndim != 3 or img.shape[2] not in (3, 4):
            raise ValueError(f"texture {name}: need (H, W, 3|4) uint8, got {img.shape}")
        levels = [img]
        while min(levels[-1].shape[:2]) >= 2 * min_size:
            levels.append(_pyr_down(levels[-1]))
        rgb = img[..., :3].reshape(-1, 3)
        if img.shape[2] == 4:
            sel = img[..., 3].reshape(-1) > 127
            rgb = rgb[sel] if np.any(sel) else rgb
        mean = rgb.mean(axis=0)
        return cls(
            name=name,
            levels=tuple(levels),
            has_alpha=img.shape[2] == 4,
            mean_bgr=(int(mean[0]), int(mean[1]), int(mean[2])),
        )
