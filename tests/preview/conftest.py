"""Synthetic lead trajectories for the preview's tests: a road under the lead's wheels through
the nominal car's two-axle response, seen at a distance by a camera."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from roadpreview.anomaly.base import TrajectorySample
from roadpreview.anomaly.response import NominalVehicle

FloatArray = NDArray[np.float64]
Profile = Callable[[FloatArray], FloatArray]


def synth_samples(
    left: Profile,
    right: Profile,
    *,
    speed_mps: float = 50 / 3.6,
    distance_m: float = 15.0,
    focal_px: float = 1000.0,
    noise_px: float = 0.15,
    duration_s: float = 8.0,
    fps: float = 30.0,
    seed: int = 0,
) -> list[TrajectorySample]:
    """Frames of a lead at constant distance and speed whose left / right front wheels run
    over ``left(s)`` / ``right(s)`` (s: the front wheel's path from t = 0), through the
    nominal car (the halves move as the tracks: the roll convention of the detector)."""
    veh = NominalVehicle()
    t = np.arange(0.0, duration_s, 0.001)
    tau = veh.wheelbase_m / speed_mps
    faces = []
    for prof in (left, right):
        _, q, _ = signal.lsim(veh.quarter_car, prof(speed_mps * t), t)
        rear = np.interp(t - tau, t, q, left=0.0)
        faces.append((1.0 + veh.rho) * rear - veh.rho * q)
    tf = np.arange(0.0, duration_s, 1.0 / fps)
    zl, zr = (np.interp(tf, t, z) for z in faces)
    rng = np.random.default_rng(seed)
    k = focal_px / distance_m
    y = -k * 0.5 * (zl + zr) + noise_px * rng.standard_normal(tf.size)
    yl = -k * zl + noise_px * rng.standard_normal(tf.size)
    yr = -k * zr + noise_px * rng.standard_normal(tf.size)
    return [
        TrajectorySample(
            t=float(tf[i]),
            y_c=float(y[i]),
            y_c_left=float(yl[i]),
            y_c_right=float(yr[i]),
            lead_distance_m=distance_m,
            ego_speed_mps=speed_mps,
            focal_px=focal_px,
        )
        for i in range(tf.size)
    ]


def box_bump(start_m: float, height_m: float = 0.06, length_m: float = 0.5) -> Profile:
    """A bump of ``height_m`` over ``length_m`` from ``start_m`` along the wheel's path."""

    def profile(s: FloatArray) -> FloatArray:
        return np.where((s >= start_m) & (s <= start_m + length_m), height_m, 0.0)

    return profile


def flat(s: FloatArray) -> FloatArray:
    return np.zeros_like(s)


def lead_spot_ahead_m(distance_m: float, speed_mps: float, age_s: float) -> float:
    """Where the road the lead's front wheel was on ``age_s`` ago is, ahead of the ego's
    front axle (the nominal geometry, camera 0.2 m behind the front axle)."""
    veh = NominalVehicle()
    return distance_m + veh.rear_overhang_m + veh.wheelbase_m - 0.2 - speed_mps * age_s
