"""Typed input samples decoded from CAN (or read from an IMU CSV), in roadpreview's conventions.

Rates follow ``docs/method.md``: roll positive when the left side rises,
pitch positive when the nose rises, yaw positive when turning left, rad/s.
Accelerations are specific force in ISO 8855 body axes (x forward, y left,
z up; +9.81 m/s² on z at rest), m/s². A quantity a frame does not carry is
NaN: IMU rates and accelerations often come in separate messages.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.errors import InputDataError

Array = NDArray[np.float64]

#: multiply ISO 8855 body rates [wx, wy, wz] by this to get [roll, pitch(nose up), yaw] rates
RATE_SIGNS = np.array([1.0, -1.0, 1.0])


@dataclass(frozen=True)
class ImuMeasurements:
    """What an IMU delivers: stamped samples in its own axes (ISO 8855: x fwd, y left, z up)."""

    t_s: Array  #: (n,) sensor time stamps, s
    gyro_rad_s: Array  #: (n, 3) angular rate about x, y, z, rad/s, right-handed
    accel_m_s2: Array  #: (n, 3) specific force along x, y, z, m/s² (gravity included)

    def __post_init__(self) -> None:
        n = len(self.t_s)
        for name in ("gyro_rad_s", "accel_m_s2"):
            if getattr(self, name).shape != (n, 3):
                raise InputDataError(
                    f"IMU {name}: shape {getattr(self, name).shape}, expected ({n}, 3)"
                )

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def rates_rad_s(self) -> Array:
        """(n, 3) [roll rate, pitch rate (nose up +), yaw rate] in roadpreview's convention."""
        rates: Array = self.gyro_rad_s * RATE_SIGNS
        return rates
