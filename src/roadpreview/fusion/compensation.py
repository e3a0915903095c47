"""Paper eq. (4): the lead vehicle's image row corrected for the ego camera's pitch."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview.errors import InputDataError


def compensation(y: ArrayLike, phi: ArrayLike, f: float) -> NDArray[np.float64]:
    """y_c = y - f tan(phi)  (paper eq. 4), element-wise with numpy broadcasting.

    ``y`` is the lead's vertical image position (px, v down), ``phi`` the
    camera pitch (rad, nose up positive, e.g. `FusedPitch.phi`), ``f`` the
    focal length in pixels (``CameraModel`` fy). A camera pitching nose up by
    phi moves the scene down by f tan(phi) (``docs/method.md``); subtracting it
    leaves the lead's own motion. NaN in ``y`` or ``phi`` (no lead, no pitch)
    stays NaN. Raises `InputDataError` for a focal length that is not a positive
    finite number or a pitch at or beyond ±90 degrees.
    """
    if not (isinstance(f, (int, float, np.floating)) and math.isfinite(f) and f > 0):
        raise InputDataError(f"compensation: focal length f = {f!r} px must be positive")
    yy = np.asarray(y, dtype=np.float64)
    pp = np.asarray(phi, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        if np.any(np.abs(pp) >= 0.5 * math.pi):
            raise InputDataError("compensation: |phi| must be below pi/2 rad (a pitch, not a turn)")
    out: NDArray[np.float64] = yy - float(f) * np.tan(pp)
    return out
