"""The compensation model, over arrays: paper eq. (4), the lead vehicle's image row corrected
for the ego camera's pitch, and our extension for the camera's heave (``docs/method.md``,
"Heave"). The streaming stage (`roadpreview.compensation.stage`) and the evaluation's error
budget (its truth substitutions) both compute y_c here."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview.errors import InputDataError


def heave_term_px(heave_m: ArrayLike, distance_m: ArrayLike, f: float) -> NDArray[np.float64]:
    """f Δz / d: how far a camera that rose by ``heave_m`` (m, up +) moves a target at
    ``distance_m`` (m) down in the image (px, v down). 0 where either is unknown (NaN) or
    the distance is not positive: no heave term is applied there."""
    h = np.asarray(heave_m, dtype=np.float64)
    d = np.asarray(distance_m, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.isfinite(h) & np.isfinite(d) & (d > 0)
        out: NDArray[np.float64] = np.where(ok, float(f) * h / np.where(ok, d, 1.0), 0.0)
    return out


def compensation(
    y: ArrayLike,
    phi: ArrayLike,
    f: float,
    *,
    heave_m: ArrayLike | None = None,
    distance_m: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """y_c = y - f tan(phi)  (paper eq. 4), element-wise with numpy broadcasting.

    ``y`` is the lead's vertical image position (px, v down), ``phi`` the
    camera pitch (rad, nose up positive, e.g. `FusedPitch.phi`), ``f`` the
    focal length in pixels (``CameraModel`` fy). A camera pitching nose up by
    phi moves the scene down by f tan(phi) (``docs/method.md``); subtracting it
    leaves the lead's own motion. NaN in ``y`` or ``phi`` (no lead, no pitch)
    stays NaN. Raises `InputDataError` for a focal length that is not a positive
    finite number or a pitch at or beyond ±90 degrees.

    With ``heave_m`` (the camera's vertical displacement Δz, m, up +, e.g. from
    `roadpreview.fusion.heave.HeaveObserver`) and ``distance_m`` (the lead's distance d)
    the camera's heave is removed too: ``y_c = y - f tan(phi) - f Δz / d``. Where Δz
    or d is unknown (NaN) no heave term is applied (`heave_term_px`).
    """
    if not (isinstance(f, (int, float, np.floating)) and math.isfinite(f) and f > 0):
        raise InputDataError(f"compensation: focal length f = {f!r} px must be positive")
    yy = np.asarray(y, dtype=np.float64)
    pp = np.asarray(phi, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        if np.any(np.abs(pp) >= 0.5 * math.pi):
            raise InputDataError("compensation: |phi| must be below pi/2 rad (a pitch, not a turn)")
    out: NDArray[np.float64] = yy - float(f) * np.tan(pp)
    if heave_m is not None and distance_m is not None:
        out = out - heave_term_px(heave_m, distance_m, float(f))
    return out


def compensate(
    y: ArrayLike, phi: ArrayLike, f: float, heave_px: ArrayLike = 0.0
) -> NDArray[np.float64]:
    """y_c = y - f tan(phi) - heave_px: `compensation` with the heave term already in pixels
    (`heave_term_px`, or the pipeline's held `HeaveTerm`). NaN in any input stays NaN."""
    return compensation(y, phi, f) - np.asarray(heave_px, dtype=np.float64)
