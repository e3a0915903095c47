"""Value types shared by the simulator's parts (motion, renderer, IMU, recording).

All quantities are SI and follow the conventions of ``docs/method.md``:
world X forward along the road, Y left, Z up; pitch positive nose up, roll
positive left side up, yaw positive turning left.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CameraPose:
    """Pose of the camera's optical centre in the world frame at one instant."""

    x_m: float
    y_m: float
    z_m: float
    pitch_rad: float
    roll_rad: float = 0.0
    yaw_rad: float = 0.0


@dataclass(frozen=True)
class VehicleShape:
    """Outer dimensions of a vehicle body (a box), relative to its centre of gravity."""

    length_m: float = 4.5
    width_m: float = 1.8
    height_m: float = 1.5
    #: height of the body's underside above the road at rest
    ground_clearance_m: float = 0.25
    #: distance from the CG forward to the front face of the body
    cg_to_front_m: float = 2.2
    #: height of the CG above the road at rest
    cg_height_m: float = 0.55

    @property
    def cg_to_rear_m(self) -> float:
        return self.length_m - self.cg_to_front_m


@dataclass(frozen=True)
class VehiclePose:
    """A vehicle body in the world at one instant (pose of its centre of gravity)."""

    vehicle_id: int
    x_m: float
    y_m: float
    z_m: float
    pitch_rad: float
    roll_rad: float
    yaw_rad: float
    shape: VehicleShape
    #: appearance seed, so that one vehicle keeps its colour and texture
    appearance: int = 0
    is_lead: bool = False


@dataclass(frozen=True)
class Conditions:
    """Visibility at one instant.

    ``fog_density_per_m``: extinction coefficient of Koschmieder's law,
    contrast falls as exp(-k d) with distance d (0 = clear).
    ``light``: scene illumination, a fraction of daylight (1 = day, about 0.05 = dusk with
    auto exposure, about 0.001 = street-lit night, where background texture is gone).
    ``tunnel``: inside a tunnel (dark walls and ceiling, artificial light).
    """

    fog_density_per_m: float = 0.0
    light: float = 1.0
    tunnel: bool = False
