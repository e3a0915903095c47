"""The comparison back ends: `visual-only` (the paper), `imu-only` (the paper's drifting
IMU) and `none` (no compensation), behind the same streaming interface."""

from __future__ import annotations

import math

from roadpreview.errors import InputDataError
from roadpreview.fusion.base import FusedPitch, VisualPitch
from roadpreview.fusion.config import ImuOnlyConfig, VisualOnlyConfig
from roadpreview.fusion.gyro import GyroHistory, RejectCounter
from roadpreview.types import FusionMode


class _Clock:
    """Non-decreasing query times (the frame clock of every back end)."""

    def __init__(self) -> None:
        self.last = -math.inf

    def check(self, t: float) -> None:
        if not math.isfinite(t):
            raise InputDataError(f"estimate(t): t = {t!r} is not a finite time")
        if t < self.last:
            raise InputDataError(
                f"estimate(t): t = {t:.6f} s is before the previous query ({self.last:.6f} s)"
            )
        self.last = t


class _InputsIgnored:
    """The inputs a comparison back end does not use: accepted and ignored.

    `VisualOnlyPitch` overrides the visual calls; the gyro's pitch rate goes into the
    back end's ``gyro`` history when it has one (`ImuOnlyPitch`); `ZeroPitchFusion` uses
    nothing. Roll and yaw rates are not used by any of them.
    """

    #: where pushed pitch rates go (None: the gyro is ignored)
    gyro: GyroHistory | None = None

    def push_gyro(
        self,
        t: float,
        pitch_rate: float,
        *,
        roll_rate: float | None = None,
        yaw_rate: float | None = None,
    ) -> bool:
        """The pitch rate into ``gyro`` (False: rejected there, logged); without a gyro
        history accepted and ignored (True)."""
        gyro = self.gyro
        return True if gyro is None else gyro.push(t, pitch_rate)

    def push_visual(self, meas: VisualPitch) -> None:
        """Ignored."""

    def push_vision_failure(self, t: float, reason: str) -> None:
        """Ignored."""


class VisualOnlyPitch(_InputsIgnored):
    """The paper's compensation: the visual pitch alone, chained over key frames.

    phi(t) = phi(t_ref) + dphi for the frame's measurement; a key frame the
    chain does not know is anchored at the last output. Without a good
    measurement the last value is held and the mode becomes DEGRADED after
    ``loss_frames`` frames (there is nothing to bridge with). Gyro samples are
    accepted and ignored.
    """

    name = "visual-only"

    def __init__(self, config: VisualOnlyConfig | None = None) -> None:
        self.config = config or VisualOnlyConfig()
        self.events = RejectCounter("fusion[visual-only]")
        self.reset()

    def reset(self) -> None:
        self._chain: dict[float, tuple[float, float]] = {}  # frame -> (phi, var)
        self._pending: dict[float, VisualPitch] = {}
        self._clock = _Clock()
        self._phi = 0.0
        self._var = 0.0
        self._bad = 0
        self._started = False

    def push_visual(self, meas: VisualPitch) -> None:
        v = self.config.vision
        good = (
            meas.quality_ok
            and math.isfinite(meas.t_ref)
            and math.isfinite(meas.t)
            and meas.t_ref < meas.t
            and math.isfinite(meas.dphi)
            and abs(meas.dphi) <= v.max_abs_dphi_rad
            and math.isfinite(meas.std)
            and meas.inlier_ratio >= v.min_inlier_ratio
        )
        if good:
            self._pending[meas.t] = meas
        elif meas.quality_ok:
            self.events("visual-bad", "unusable visual measurement at t=%r ignored", meas.t)

    def push_vision_failure(self, t: float, reason: str) -> None:
        self._pending.pop(t, None)

    def estimate(self, t: float) -> FusedPitch:
        self._clock.check(t)
        if not self._started:
            self._started = True
            self._chain[t] = (0.0, 0.0)
        m = self._pending.pop(t, None)
        for k in [k for k in self._pending if k < t]:
            del self._pending[k]
        if m is not None:
            ref = self._chain.get(m.t_ref)
            if ref is None:
                ref = (self._phi, self._var)
                self._chain[m.t_ref] = ref
            self._phi = ref[0] + m.dphi
            self._var = ref[1] + self.config.vision.variance(m.std)
            self._chain[t] = (self._phi, self._var)
            self._bad = 0
        elif t not in self._chain:
            self._bad += 1
            self._chain[t] = (self._phi, self._var)
        if len(self._chain) > 512:
            for k in sorted(self._chain)[:256]:
                del self._chain[k]
        ok = self._bad < self.config.loss_frames
        return FusedPitch(
            t=t,
            phi=self._phi,
            std=math.sqrt(self._var) if ok else math.inf,
            mode=FusionMode.VISUAL_ONLY if ok else FusionMode.DEGRADED,
        )


class ImuOnlyPitch(_InputsIgnored):
    """The integrated gyro: phi(t) = ∫ (ω - b) dt from the first frame, b fixed (default 0).

    The paper's IMU comparison, which drifts with the uncorrected bias. Gyro
    input gets the same validation, ordering and gap bridging as the fusion;
    the time offset is the configured one (not estimated). Visual input is
    ignored. Mode IMU_ONLY while the IMU is alive, else DEGRADED.
    """

    name = "imu-only"
    gyro: GyroHistory  #: always one here

    def __init__(self, config: ImuOnlyConfig | None = None) -> None:
        self.config = config or ImuOnlyConfig()
        self.events = RejectCounter("fusion[imu-only]")
        self.gyro = GyroHistory(self.config.gyro, self.events)
        self.reset()

    def reset(self) -> None:
        self.gyro.reset()
        self._clock = _Clock()
        self._t_c = math.nan  # committed time (camera clock)
        self._phi_c = 0.0
        self._var_c = 0.0
        self._dm_c = 0.0  # measured time since the start (for the bias uncertainty)

    def estimate(self, t: float) -> FusedPitch:
        self._clock.check(t)
        cfg = self.config
        tau = cfg.time_offset_s
        if math.isnan(self._t_c):
            self._t_c = t
        newest = self.gyro.newest
        alive = newest is not None and newest - tau >= t - cfg.gyro.timeout_s
        horizon = t if newest is None else min(t, newest - tau)
        if horizon > self._t_c:
            mo = self.gyro.motion(self._t_c + tau, horizon + tau)
            self._phi_c += mo.dG - cfg.bias_rad_s * mo.dM
            self._var_c += mo.dV
            self._dm_c += mo.dM
            self._t_c = horizon
            self.gyro.floor = max(self.gyro.floor, horizon + tau)
            self.gyro.trim(self.gyro.floor - cfg.gyro.history_s)
        phi, var, dm = self._phi_c, self._var_c, self._dm_c
        if t > self._t_c:
            mo = self.gyro.motion(self._t_c + tau, t + tau)
            phi += mo.dG - cfg.bias_rad_s * mo.dM
            var += mo.dV
            dm += mo.dM
        var += (dm * cfg.gyro.bias_prior_std_rad_s) ** 2
        return FusedPitch(
            t=t,
            phi=phi,
            std=math.sqrt(var),
            mode=FusionMode.IMU_ONLY if alive else FusionMode.DEGRADED,
            bias=cfg.bias_rad_s,
            time_offset=tau,
            bias_std=cfg.gyro.bias_prior_std_rad_s,
        )


class ZeroPitchFusion(_InputsIgnored):
    """The paper's other baseline: pitch 0 (y_c = y), std infinite, mode DEGRADED."""

    name = "none"

    def __init__(self, config: object | None = None) -> None:
        self.reset()

    def reset(self) -> None:
        self._clock = _Clock()

    def estimate(self, t: float) -> FusedPitch:
        self._clock.check(t)
        return FusedPitch(t=t, phi=0.0, std=math.inf, mode=FusionMode.DEGRADED)
