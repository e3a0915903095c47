"""`GyroWithEstimates`: the gyro alone, integrated with the bias and the camera-IMU time
offset that the product's fusion estimates (the ``imu-estimated`` back end).

The paper's IMU baseline (`roadpreview.fusion.baselines.ImuOnlyPitch`) integrates the raw
rate with bias 0 and offset 0: it ramps with the bias. This back end runs the ``kalman``
fusion on the same inputs only for its estimates, and outputs

    phi(t) = sum over frames of  ∫ (ω - b̂) dt  over [t_prev + τ̂, t + τ̂],

b̂ and τ̂ the fusion's at each frame: what the gyro is worth at short time scales once its
bias and offset are known. It never sees vision in its output, so it still drifts with the
bias's error; the evaluation's error budget and Table I report it beside the fusion.
"""

from __future__ import annotations

import math

from roadpreview.fusion.base import FusedPitch, VisualPitch
from roadpreview.fusion.config import KalmanConfig
from roadpreview.fusion.kalman import kalman_fusion
from roadpreview.types import FusionMode


class GyroWithEstimates:
    """The ``imu-estimated`` back end (module docstring); a `PitchFusion`."""

    name = "imu-estimated"

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.config = config or KalmanConfig()
        self.fusion = kalman_fusion(self.config)
        self.events = self.fusion.events
        self.reset()

    def reset(self) -> None:
        self.fusion.reset()
        self._t = math.nan  # the last frame (camera clock)
        self._phi = 0.0
        self._var = 0.0

    def push_gyro(
        self,
        t: float,
        pitch_rate: float,
        *,
        roll_rate: float | None = None,
        yaw_rate: float | None = None,
    ) -> bool:
        return self.fusion.push_gyro(t, pitch_rate, roll_rate, yaw_rate)

    def push_visual(self, meas: VisualPitch) -> None:
        self.fusion.push_visual(meas)

    def push_vision_failure(self, t: float, reason: str) -> None:
        self.fusion.push_vision_failure(t, reason)

    def estimate(self, t: float) -> FusedPitch:
        """The gyro's integral since the first frame, with the fusion's bias and offset at
        this frame (IMU_ONLY while the IMU is alive, else DEGRADED: nothing added)."""
        est = self.fusion.estimate(t)
        b = est.bias if math.isfinite(est.bias) else 0.0
        tau = est.time_offset if math.isfinite(est.time_offset) else 0.0
        t0 = self._t
        self._t = t
        gyro = self.fusion.gyro
        alive = gyro.newest is not None and gyro.newest - tau >= t - self.config.gyro.timeout_s
        if math.isfinite(t0) and t > t0 and alive:
            mo = gyro.motion(t0 + tau, t + tau)
            self._phi += mo.dG - b * mo.dM
            self._var += mo.dV + (mo.dM * est.bias_std) ** 2
        return FusedPitch(
            t=t,
            phi=self._phi,
            std=math.sqrt(self._var),
            mode=FusionMode.IMU_ONLY if alive else FusionMode.DEGRADED,
            bias=b,
            time_offset=tau,
            bias_std=est.bias_std,
        )
