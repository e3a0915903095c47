"""Typed input samples decoded from CAN (or read from an IMU CSV), in roadpreview's conventions.

Rates follow ``docs/method.md``: roll positive when the left side rises,
pitch positive when the nose rises, yaw positive when turning left, rad/s.
Accelerations are specific force in ISO 8855 body axes (x forward, y left,
z up; +9.81 m/s² on z at rest), m/s². A quantity a frame does not carry is
NaN: IMU rates and accelerations often come in separate messages.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roadpreview.errors import ConfigError, InputDataError
from roadpreview.types import ImuSample

Array = NDArray[np.float64]

#: multiply ISO 8855 body rates [wx, wy, wz] by this to get [roll, pitch(nose up), yaw] rates
RATE_SIGNS = np.array([1.0, -1.0, 1.0])


@dataclass(frozen=True)
class ImuMeasurements:
    """What an IMU delivers: stamped samples in its own axes (ISO 8855: x fwd, y left, z up)."""

    t_s: Array  #: (n,) sensor time stamps, s
    gyro_rad_s: Array  #: (n, 3) angular rate about x, y, z, rad/s, right-handed
    accel_m_s2: Array  #: (n, 3) specific force along x, y, z, m/s² (gravity included)
    #: rows the reader skipped, by reason (``skipped_bad_line``)
    problems: Counter[str] = field(default_factory=Counter, compare=False)

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


@dataclass(frozen=True)
class ImuMount:
    """How the IMU sits in the car and how late its clock is (``roadpreview calibrate``).

    ``rotation`` takes vectors in the IMU's axes (as its signals or CSV columns give them,
    read as ISO 8855 x, y, z) to the car's body axes (ISO 8855: x forward, y left, z up).
    ``time_offset_s`` is the IMU stamp minus the camera time of the same instant (positive:
    the stamps lag); it is subtracted from every stamp. A mapping's ``[mount]`` table::

        [mount]
        rotation = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # body <- IMU
        time_offset_s = 0.060
    """

    rotation: Array = field(default_factory=lambda: np.eye(3))
    time_offset_s: float = 0.0
    source: str = field(default="<mount>", compare=False)

    def __post_init__(self) -> None:
        R = np.asarray(self.rotation, dtype=np.float64)
        where = f"{self.source}: mount.rotation"
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ConfigError(f"{where}: must be a 3x3 matrix of finite numbers")
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0.0:
            raise ConfigError(f"{where}: not a rotation (orthonormal, determinant +1)")
        if not math.isfinite(self.time_offset_s) or abs(self.time_offset_s) > 1.0:
            raise ConfigError(
                f"{self.source}: mount.time_offset_s = {self.time_offset_s}: must be within ±1 s"
            )
        object.__setattr__(self, "rotation", R)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = "<mount>") -> ImuMount:
        """The ``[mount]`` table; `ConfigError` names the file and the key."""
        unknown = sorted(set(data) - {"rotation", "time_offset_s"})
        if unknown:
            raise ConfigError(
                f"{source}: unknown key mount.{unknown[0]} (known: rotation, time_offset_s)"
            )
        try:
            rotation = np.asarray(data.get("rotation", np.eye(3)), dtype=np.float64)
            offset = float(data.get("time_offset_s", 0.0))
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{source}: mount: {exc}") from None
        return cls(rotation=rotation, time_offset_s=offset, source=source)

    def to_dict(self) -> dict[str, Any]:
        return {
            "rotation": [[float(v) for v in row] for row in self.rotation],
            "time_offset_s": float(self.time_offset_s),
        }

    def apply(self, meas: ImuMeasurements) -> ImuMeasurements:
        """The measurements in the body's axes, stamps on the camera's clock."""
        R = self.rotation
        return ImuMeasurements(
            meas.t_s - self.time_offset_s,
            meas.gyro_rad_s @ R.T,
            meas.accel_m_s2 @ R.T,
            meas.problems,
        )

    def apply_sample(self, sample: ImuSample) -> ImuSample:
        """One sample (roadpreview's rates, ISO specific force) in the body's axes, its stamp
        on the camera's clock. A component that needs a missing (NaN) input stays NaN; the
        others are computed from what is there (a message with only some of the rates)."""
        R = self.rotation
        used = np.abs(R) > 1e-12
        w = np.asarray(sample.rates_rad_s, dtype=np.float64) * RATE_SIGNS
        a = np.asarray(sample.accel_m_s2, dtype=np.float64)
        out = []
        for v in (w, a):  # two vectors
            missing = np.isnan(v)
            body = R @ np.where(missing, 0.0, v)
            body[(used & missing[None, :]).any(axis=1)] = np.nan
            out.append(body)
        rates = out[0] * RATE_SIGNS
        acc = out[1]
        return ImuSample(
            sample.t_s - self.time_offset_s,
            (float(rates[0]), float(rates[1]), float(rates[2])),
            (float(acc[0]), float(acc[1]), float(acc[2])),
            sample.source,
        )
