"""Pinhole camera geometry: intrinsics K, the calibrated forward direction t, mounting.

Conventions (see ``docs/method.md``): camera coordinates are OpenCV's, x to
the right, y down, z along the optical axis; image y grows downwards. The
forward direction ``t`` is the unit vector, in camera coordinates, along which
the vehicle travels when its body is at rest; it is what the pitch estimator's
epipolar model uses for the translation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview._tomlio import dump_toml, load_toml
from roadpreview.errors import ConfigError

_FIELDS = ("width", "height", "fx", "fy", "cx", "cy", "forward", "mount_height_m")


@dataclass(frozen=True)
class CameraModel:
    """A calibrated pinhole camera mounted on a vehicle.

    Parameters
    ----------
    width, height
        Image size in pixels.
    fx, fy
        Focal lengths in pixels.
    cx, cy
        Principal point in pixels (inside the image).
    forward
        Calibrated forward direction t, a unit 3-vector in camera
        coordinates (x right, y down, z optical axis).
    mount_height_m
        Height of the optical centre above the road at rest, in metres.
    source
        Where the calibration came from (file name), used in error messages.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    forward: tuple[float, float, float] = (0.0, 0.0, 1.0)
    mount_height_m: float = 1.3
    source: str = field(default="<camera>", compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "forward", tuple(float(v) for v in self.forward))
        self.validate()

    # -- construction -------------------------------------------------------------
    @classmethod
    def from_fov(
        cls,
        width: int,
        height: int,
        vfov_deg: float,
        *,
        forward: tuple[float, float, float] = (0.0, 0.0, 1.0),
        mount_height_m: float = 1.3,
    ) -> CameraModel:
        """Square pixels, principal point at the image centre, focal length from
        the vertical field of view: ``f = (height / 2) / tan(vfov / 2)``.

        The paper's 1920x1080 camera with a 54 deg vertical field of view gives
        f = 1060 px (the paper quotes 1066 px, i.e. 53.7 deg).
        """
        if not 0.0 < vfov_deg < 180.0:
            raise ConfigError(f"vfov_deg: must be in (0, 180) deg, got {vfov_deg!r}")
        f = (height / 2.0) / math.tan(math.radians(vfov_deg) / 2.0)
        return cls(
            width=int(width),
            height=int(height),
            fx=f,
            fy=f,
            cx=(width - 1) / 2.0,
            cy=(height - 1) / 2.0,
            forward=forward,
            mount_height_m=mount_height_m,
        )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = "<camera>") -> CameraModel:
        """Build from a mapping (the ``[camera]`` table of a TOML file)."""
        unknown = sorted(set(data) - set(_FIELDS))
        if unknown:
            raise ConfigError(
                f"{source}: unknown camera field(s) {unknown}; expected some of {list(_FIELDS)}"
            )
        required = ("width", "height", "fx", "fy", "cx", "cy")
        missing = [k for k in required if k not in data]
        if missing:
            raise ConfigError(f"{source}: missing camera field(s) {missing}")
        try:
            kwargs: dict[str, Any] = {
                "width": int(data["width"]),
                "height": int(data["height"]),
                "fx": float(data["fx"]),
                "fy": float(data["fy"]),
                "cx": float(data["cx"]),
                "cy": float(data["cy"]),
            }
            if "forward" in data:
                fwd = [float(v) for v in data["forward"]]
                if len(fwd) != 3:
                    raise ConfigError(f"{source}: camera.forward must have 3 components")
                kwargs["forward"] = (fwd[0], fwd[1], fwd[2])
            if "mount_height_m" in data:
                kwargs["mount_height_m"] = float(data["mount_height_m"])
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ConfigError):
                raise
            raise ConfigError(f"{source}: camera field has the wrong type: {exc}") from None
        return cls(**kwargs, source=source)

    @classmethod
    def load(cls, path: str | Path) -> CameraModel:
        """Read a calibration from TOML (a ``[camera]`` table, or the fields at top level)."""
        data = load_toml(path)
        table = data.get("camera", data)
        if not isinstance(table, Mapping):
            raise ConfigError(f"{path}: [camera] must be a table")
        return cls.from_dict(table, source=str(path))

    def to_dict(self) -> dict[str, Any]:
        """The calibration as plain values (what `save` writes under ``[camera]``)."""
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "forward": list(self.forward),
            "mount_height_m": self.mount_height_m,
        }

    def save(self, path: str | Path) -> None:
        """Write the calibration as TOML under a ``[camera]`` table."""
        dump_toml({"camera": self.to_dict()}, path)

    # -- validation ---------------------------------------------------------------
    def validate(self) -> None:
        """Raise `ConfigError` naming the first field that is out of range."""
        src = self.source
        if self.width <= 0 or self.height <= 0:
            raise ConfigError(
                f"{src}: camera width/height must be positive, got {self.width}x{self.height}"
            )
        for name in ("fx", "fy"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ConfigError(f"{src}: camera.{name} must be a positive focal length, got {v}")
        if not (math.isfinite(self.cx) and 0.0 <= self.cx < self.width):
            raise ConfigError(
                f"{src}: camera.cx = {self.cx} is outside the image width [0, {self.width})"
            )
        if not (math.isfinite(self.cy) and 0.0 <= self.cy < self.height):
            raise ConfigError(
                f"{src}: camera.cy = {self.cy} is outside the image height [0, {self.height})"
            )
        t = np.asarray(self.forward, dtype=float)
        if not np.all(np.isfinite(t)) or abs(float(np.linalg.norm(t)) - 1.0) > 1e-6:
            raise ConfigError(
                f"{src}: camera.forward must be a unit vector, got {list(self.forward)} "
                f"(norm {float(np.linalg.norm(t)):.6g})"
            )
        if t[2] <= 0.0:
            raise ConfigError(
                f"{src}: camera.forward must point ahead of the camera (z > 0), "
                f"got {list(self.forward)}"
            )
        if not (math.isfinite(self.mount_height_m) and self.mount_height_m > 0.0):
            raise ConfigError(
                f"{src}: camera.mount_height_m must be positive, got {self.mount_height_m}"
            )

    # -- geometry -----------------------------------------------------------------
    @property
    def K(self) -> NDArray[np.float64]:
        """The 3x3 intrinsic matrix."""
        return np.array(
            [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]], dtype=np.float64
        )

    @property
    def K_inv(self) -> NDArray[np.float64]:
        """Inverse of `K` (closed form)."""
        return np.array(
            [
                [1.0 / self.fx, 0.0, -self.cx / self.fx],
                [0.0, 1.0 / self.fy, -self.cy / self.fy],
                [0.0, 0.0, 1.0],
            ],
            dtype=np.float64,
        )

    @property
    def f(self) -> float:
        """Vertical focal length in pixels, the ``f`` of ``y_c = y - f tan(phi)``."""
        return self.fy

    @property
    def t(self) -> NDArray[np.float64]:
        """The calibrated forward direction as an array."""
        return np.asarray(self.forward, dtype=np.float64)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels, OpenCV's order."""
        return (self.width, self.height)

    def project(self, points_cam: ArrayLike) -> NDArray[np.float64]:
        """Project (N, 3) camera-frame points to (N, 2) pixels; points behind give NaN."""
        p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        z = p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.fx * p[:, 0] / z + self.cx
            v = self.fy * p[:, 1] / z + self.cy
        out = np.stack([u, v], axis=1)
        out[z <= 0.0] = np.nan
        return out

    def rays(self, pixels: ArrayLike) -> NDArray[np.float64]:
        """(N, 2) pixels to (N, 3) camera-frame rays with z = 1."""
        px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        x = (px[:, 0] - self.cx) / self.fx
        y = (px[:, 1] - self.cy) / self.fy
        return np.stack([x, y, np.ones_like(x)], axis=1)

    def scaled(self, width: int, height: int) -> CameraModel:
        """The same camera for an image resized to ``width x height``."""
        sx = width / self.width
        sy = height / self.height
        return CameraModel(
            width=int(width),
            height=int(height),
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
            forward=self.forward,
            mount_height_m=self.mount_height_m,
            source=self.source,
        )
