"""The camera's optics and sensor: the lens PSF with the vertical motion blur of the pitch
rate, exposure and gamma, and signal-dependent shot + read noise."""

from __future__ import annotations

import math
from statistics import NormalDist

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.sim.render.config import RenderConfig

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

#: standard normal quantiles of the 256 byte values: Gaussian noise by table lookup
_GAUSS_Q = np.array([NormalDist().inv_cdf((k + 0.5) / 256.0) for k in range(256)])


def gauss_kernel(sigma: float) -> F32:
    """A normalised Gaussian kernel of std ``sigma`` px over +-3 sigma (at least +-1 px)."""
    if sigma <= 0:
        return np.array([1.0], np.float32)
    r = max(1, math.ceil(3.0 * sigma))
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    out: F32 = (k / k.sum()).astype(np.float32)
    return out


def box_kernel(length: float) -> F64:
    """A centred box of (fractional) length in pixels, integrated over each pixel."""
    r = math.ceil(length / 2 + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    lo = np.maximum(x - 0.5, -length / 2)
    hi = np.minimum(x + 0.5, length / 2)
    w = np.clip(hi - lo, 0, None)
    out: F64 = w / w.sum()
    return out


def blur(img: U8, cfg: RenderConfig, fy: float, pitch_rate: float) -> U8:
    """Vertical motion blur (``pitch_rate`` rad/s over the exposure) and the lens PSF, one pass."""
    blur_px = abs(fy * pitch_rate * cfg.exposure_time_s) if cfg.motion_blur else 0.0
    sigma = cfg.optics_blur_sigma_px
    if blur_px > 0.3:
        g = gauss_kernel(sigma)
        ky = np.convolve(g, box_kernel(blur_px)).astype(np.float32)
        return np.asarray(cv2.sepFilter2D(img, -1, g, ky), np.uint8)
    if sigma > 0:  # the fixed-point Gaussian is ~3x faster than a float kernel
        r = max(1, math.ceil(2.5 * sigma))
        return np.asarray(cv2.GaussianBlur(img, (2 * r + 1, 2 * r + 1), sigma), np.uint8)
    return img


def expose(img: U8, cfg: RenderConfig, expo: float) -> U8:
    """Scale the linear signal (display value^gamma) by ``expo`` and re-encode."""
    if abs(expo - 1.0) <= 1e-6:
        return img
    inv_g = 1.0 / cfg.gamma
    lut = np.clip(255.0 * ((np.arange(256) / 255.0) ** cfg.gamma * expo) ** inv_g, 0, 255)
    return np.asarray(cv2.LUT(img, np.round(lut).astype(np.uint8)), np.uint8)


class SensorNoise:
    """Shot + read noise, signal dependent, drawn by inverse-CDF lookup of random bytes.

    For display value D the linear signal is y = (D/255)^gamma; the pixel
    collected y/gain * full_well electrons; its std in display units is the
    electron std through the response's slope (capped by a linear toe as in
    sRGB, slope 12.92, where the power law's slope is infinite).
    """

    def __init__(self, cfg: RenderConfig, width: int, height: int) -> None:
        self.cfg = cfg
        #: scratch (reused: allocating 2 x 5.5 MB per frame costs page faults)
        self._buf = (
            np.empty((height, width, 3), np.int16),
            np.empty((height, width, 3), np.int16),
        )

    def add(self, img: U8, gain: float, rng: np.random.Generator) -> U8:
        """``img`` (H, W, 3) with noise for the sensor ``gain``, drawn from ``rng``."""
        cfg = self.cfg
        y = (np.arange(256) / 255.0) ** cfg.gamma
        electrons = y / gain * cfg.full_well_e
        sigma_y = gain * np.sqrt(electrons + cfg.read_noise_e**2) / cfg.full_well_e
        with np.errstate(divide="ignore"):
            slope = np.where(y > 0, (1.0 / cfg.gamma) * y ** (1.0 / cfg.gamma - 1.0), np.inf)
        slope = np.minimum(slope, 12.92)
        sigma_d = 255.0 * sigma_y * slope
        sig_tab = np.clip(np.round(sigma_d * 64.0), 0, 32767).astype(np.int16)
        g_tab = np.round(_GAUSS_Q * 64.0).astype(np.int16)
        n = img.size
        raw = rng.bit_generator.random_raw((n + 7) // 8)
        u8 = np.asarray(raw).view(np.uint8)[:n].reshape(img.shape)
        g, sig = self._buf
        cv2.LUT(u8, g_tab, dst=g)
        cv2.LUT(img, sig_tab, dst=sig)
        cv2.multiply(g, sig, dst=g, scale=1.0 / 4096.0, dtype=cv2.CV_16S)
        return np.asarray(cv2.add(img, g, dtype=cv2.CV_8U), np.uint8)
