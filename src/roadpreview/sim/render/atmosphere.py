"""Light and air between the scene and the camera: Koschmieder fog, the headlights' low
beam over the ambient (night, tunnel) light with the lamps' glow, and what the auto
exposure meters."""

from __future__ import annotations

import math
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.sim.render.config import RenderConfig

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

#: fog transmittance t = exp(-k d) tabulated on 255 sqrt(k d / KD_MAX)
_FOG_KD_MAX = 6.5
_FOG_T = np.exp(-_FOG_KD_MAX * (np.arange(256) / 255.0) ** 2).astype(np.float32)
_FOG_1MT = (1.0 - _FOG_T).astype(np.float32)


def headlight_beam(cfg: RenderConfig, mount: F64, xn: F32, yn: F32, ray_len: F32) -> F32:
    """Low-beam pattern in the image (fixed: lamps and camera ride on the same body).

    ``xn``, ``yn``: normalised image coordinates of the pixels; ``ray_len`` the
    length of their rays at unit depth; ``mount`` the camera's mount rotation.
    """
    rays = np.stack([xn, yn, np.ones_like(xn)], axis=-1) @ mount  # body-aligned
    az = np.arctan2(rays[..., 0], rays[..., 2])
    el = np.arctan2(-rays[..., 1], rays[..., 2])
    spread = math.radians(cfg.headlight_spread_deg)
    cut = math.radians(cfg.headlight_cutoff_deg)
    horiz = np.exp(-((az / spread) ** 2))
    vert = np.where(el < cut, 1.0, np.exp(-(((el - cut) / 0.01) ** 2)))
    # illumination = gain * beam * (d_ref / d)^2 with d = ray_len / invz
    b = cfg.headlight_gain * horiz * vert * cfg.headlight_ref_m**2 / ray_len**2
    return b.astype(np.float32)


def exposure_gain(cfg: RenderConfig, ambient: float, lights_on: bool) -> float:
    """Exposure x gain over daylight: the manual offset, times the auto gain towards
    daylight brightness (metering the ambient light and the low beam on the road ahead),
    capped by ``max_gain``."""
    gain = float(2.0**cfg.exposure_ev)
    if cfg.auto_exposure:
        metered = ambient
        if lights_on:
            metered += cfg.headlight_gain * (cfg.headlight_ref_m / cfg.metering_distance_m) ** 2
        gain *= float(np.clip(1.0 / max(metered, 1e-9), 1.0, cfg.max_gain))
    return gain


class Atmosphere:
    """Fog and artificial light for images of one size.

    Parameters
    ----------
    cfg
        Fog colour, headlights, lamp glow, gamma.
    ray_len
        (H, W) length of each pixel's ray at unit depth: distance = ray_len / (1/z).
    beam
        (H, W) the headlights' illumination at unit inverse depth (`headlight_beam`).
    """

    def __init__(self, cfg: RenderConfig, ray_len: F32, beam: F32) -> None:
        self.cfg = cfg
        self.H, self.W = ray_len.shape
        self.ray_len = ray_len
        self.beam = beam
        self._airlight_cache: dict[tuple[int, int, int], U8] = {}

    def _airlight(self, colour: tuple[int, int, int]) -> U8:
        img = self._airlight_cache.get(colour)
        if img is None:
            img = np.empty((self.H, self.W, 3), np.uint8)
            cv2.rectangle(img, (0, 0), (self.W - 1, self.H - 1), colour, -1)
            self._airlight_cache = {colour: img}
        return img

    def fog(self, img: U8, invz: F32, k_fog: float) -> U8:
        """Koschmieder: I = J t + A (1 - t), t = exp(-k d), d = |ray| / (1/z)."""
        # k d on a square-root scale to 8 bits (steps of <= 1.5 % in t where contrast
        # is left), then t and 1 - t by table: 3x faster than a float exp
        kd = cv2.divide(self.ray_len, invz, scale=k_fog / _FOG_KD_MAX)
        idx = cv2.convertScaleAbs(cv2.sqrt(kd), alpha=255.0)  # saturates at k d > max
        t = cv2.LUT(idx, _FOG_T)
        airlight = self._airlight(self.cfg.airlight_bgr)
        return np.asarray(cv2.blendLinear(img, airlight, t, cv2.LUT(idx, _FOG_1MT)), np.uint8)

    def light(self, img: U8, invz: F32, emission: U8 | None, ambient: float, gain: float) -> U8:
        """Per-pixel light = ambient + headlights (falling off as 1/d^2), then the lamps'
        emission and its glow added.

        The display value scales by (light * gain)^(1/gamma) for a power-law response.
        """
        cfg = self.cfg
        inv_g = 1.0 / cfg.gamma
        inv2 = cv2.multiply(invz, invz)
        light = np.asarray(cv2.multiply(inv2, self.beam), np.float32)
        np.minimum(light, 8.0, out=light)
        light += ambient
        # a Python float is a cv2 scalar (product in double, rounded once); opencv's stubs
        # before 4.11 lack that overload, later ones have it: Any fits both
        lg = cv2.multiply(light, cast("Any", gain))
        root = cv2.sqrt(lg)  # in [0, 4] mapped to 0..255
        idx = cv2.convertScaleAbs(root, alpha=255.0 / 4.0)
        table = np.clip(64.0 * ((np.arange(256) * 4.0 / 255.0) ** 2) ** inv_g, 0, 255).astype(
            np.uint8
        )
        s = cv2.LUT(idx, table)
        out = cv2.multiply(img, cv2.merge([s, s, s]), scale=1.0 / 64.0)
        if emission is not None:
            out = cv2.add(out, emission)
            sig = cfg.lamp_glow_sigma * self.H
            small = cv2.resize(
                emission, (max(1, self.W // 4), max(1, self.H // 4)), interpolation=cv2.INTER_AREA
            )
            small = cv2.GaussianBlur(small, (0, 0), max(0.5, sig / 4))
            glow = cv2.resize(small, (self.W, self.H), interpolation=cv2.INTER_LINEAR)
            out = cv2.addWeighted(out, 1.0, glow, cfg.lamp_glow_gain, 0.0)
        return np.asarray(out, np.uint8)
