"""The whole calibration from a drive's tracks and IMU samples (pure: arrays in, results
out). The order matters: the direction of travel first (it fixes the translation of the
rotation fits), then the camera's rotations, the time offset (in any IMU orientation),
and with the IMU's samples aligned, its axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roadpreview.calib.drive import DriveTracks, ImuData
from roadpreview.calib.forward import (
    ForwardEstimate,
    body_axes_in_camera,
    focus_of_expansion,
    forward_direction,
)
from roadpreview.calib.motion import relative_motion, rotation_given_direction
from roadpreview.calib.rotation import AxisResult, RotationResult, rate_axis, rotation_from_rates
from roadpreview.calib.timing import (
    TimeOffsetResult,
    estimate_time_offset,
    gyro_integral,
    mean_rates,
)
from roadpreview.camera import CameraModel

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class CalibrationSettings:
    """Thresholds of the calibration (SI units)."""

    min_parallax_px: float = 2.0  #: a key pair with less did not move enough for t
    min_key_age_s: float = 0.1  #: a shorter key pair's direction is too noisy
    max_turn_rad: float = math.radians(0.5)  #: a key pair that yawed more is not straight
    min_offset_s: float = -0.3  #: time offset search range
    max_offset_s: float = 0.3
    min_excitation_rad_s: float = math.radians(0.3)  #: on two axes, for the full rotation
    max_rotation_std_deg: float = 3.0


@dataclass(frozen=True)
class Calibration:
    """Everything ``roadpreview calibrate`` estimates (each part falsy when not found)."""

    camera: CameraModel  #: the input camera, with the estimated forward direction if found
    forward: ForwardEstimate
    forward_seconds: float  #: driving time of the key pairs the direction used
    foe_px: tuple[float, float]  #: (u, v) of the focus of expansion; v is the horizon row
    rotations: int  #: frame-to-frame rotations the camera gave
    time_offset: TimeOffsetResult
    pitch_axis: AxisResult  #: the gyro axis and sign of the camera's pitch rate
    rotation: RotationResult  #: IMU (chip) -> camera
    body_from_imu: F64  #: (3, 3) the mount rotation (NaN when the rotation is unknown)
    imu_samples: int
    imu_seconds: float


def calibrate(
    tracks: DriveTracks,
    imu: ImuData | None,
    camera: CameraModel,
    settings: CalibrationSettings | None = None,
) -> Calibration:
    """Estimate what the drive allows (module docstring); ``imu`` None: the camera only."""
    s = settings or CalibrationSettings()
    K = camera.K
    # 1. the direction of travel from each key frame's longest pair, straight driving only
    dirs: list[F64] = []
    seconds = 0.0
    for p in tracks.key_pairs:  # one essential matrix per key frame
        m = relative_motion(p.x_a, p.x_b, K)
        if (
            m
            and p.tb - p.ta >= s.min_key_age_s
            and m.parallax_px >= s.min_parallax_px
            and abs(m.rotvec[1]) <= s.max_turn_rad
        ):
            dirs.append(m.direction)
            seconds += p.tb - p.ta
    forward = forward_direction(np.asarray(dirs).reshape(-1, 3))
    t = forward.t if forward else camera.t
    cam = camera
    if forward:
        cam = CameraModel(
            **{**camera.to_dict(), "forward": tuple(float(x) for x in forward.t)},
            source=camera.source,
        )
    foe = focus_of_expansion(t, K)
    # 2. the camera's rotation between consecutive frames, translation along t
    ta, tb, rv = [], [], []
    for p in tracks.consecutive:  # one small least-squares fit per frame
        r = rotation_given_direction(p.x_a, p.x_b, K, t)
        if r:
            ta.append(p.ta)
            tb.append(p.tb)
            rv.append(r.rotvec)
    a, b = np.asarray(ta), np.asarray(tb)
    rot = np.asarray(rv).reshape(-1, 3)
    nan3 = np.full((3, 3), np.nan)
    empty = np.empty(0)
    if imu is None or len(imu) < 2:
        why = "no IMU samples in the drive"
        offset = TimeOffsetResult(math.nan, math.nan, math.nan, 0, 0.0, empty, empty, why)
        axis = AxisResult(0, 1, math.nan, np.full(3, np.nan), np.full(3, np.nan), 0, why)
        rotation = RotationResult(nan3, math.nan, np.full(3, np.nan), math.nan, 0, why)
        return Calibration(
            cam, forward, seconds, foe, rot.shape[0], offset, axis, rotation, nan3, 0, 0.0
        )
    # 3. the time offset; 4. the axes, with the gyro shifted by it
    offset = estimate_time_offset(
        a, b, rot, imu.t, imu.gyro, min_offset_s=s.min_offset_s, max_offset_s=s.max_offset_s
    )
    tau = offset.offset_s if offset else 0.0
    tg, G = gyro_integral(imu.t, imu.gyro)
    inside = (a + tau >= tg[0]) & (b + tau <= tg[-1])
    v = rot[inside] / (b - a)[inside, None]
    g = mean_rates(tg, G, a[inside] + tau, b[inside] + tau)
    axis = rate_axis(v[:, 0], g)  # the camera's pitch rate (nose up) is about its +x
    rotation = rotation_from_rates(
        v, g, min_excitation_rad_s=s.min_excitation_rad_s, max_std_deg=s.max_rotation_std_deg
    )
    body_from_imu = body_axes_in_camera(t).T @ rotation.R if rotation else nan3
    return Calibration(
        camera=cam,
        forward=forward,
        forward_seconds=seconds,
        foe_px=foe,
        rotations=int(rot.shape[0]),
        time_offset=offset,
        pitch_axis=axis,
        rotation=rotation,
        body_from_imu=body_from_imu,
        imu_samples=len(imu),
        imu_seconds=float(imu.t[-1] - imu.t[0]),
    )
