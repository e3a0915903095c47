"""`kalman`: gyro-driven Kalman filter with stochastic clones for relative visual pitch.

State (filterpy ``KalmanFilter``, dimension 2 + n_clones)::

    x = [phi, b, phi(t_c1), ..., phi(t_cn)]

phi is the camera pitch relative to the first frame, b the gyro pitch-rate
bias, phi(t_ci) clones of phi taken when the state passed recent frame times
(stochastic cloning). Prediction over [t1, t2] from the gyro's running
integral (`GyroHistory`)::

    phi <- phi + ΔG - ΔM b          (every IMU sample in the interval, composed exactly)
    b   <- b + w_b,  Var(w_b) = q_b (t2 - t1)
    Var(phi noise) = ΔV             (white rate noise, bridged gaps, extrapolation)

A visual measurement dphi = phi(t) - phi(t_ref) is taken at its frame t,
where the current phi is phi(t); phi(t_ref) is the clone of its key frame,
so ``H = [1, 0, ..., -1 (slot of t_ref), ...]``. Because the key frame's
pitch is a state with its own uncertainty and correlation, a new key frame
(re-anchoring) changes nothing: no step, no double counting. Each update is
filterpy's Joseph-form ``update(z, R, H)`` with a per-call R (the estimator's
std, inflated for few inliers, plus the time-offset term), after a Mahalanobis
gate on the innovation.

Clones: each frame the state passes is cloned into the slot of the oldest
clone, except the slot of the current key frame, which stays pinned as long as
measurements refer to it. A measurement whose key frame has no clone (older
than every slot) is turned into an increment against the last frame measured
against the same key.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from filterpy.kalman import KalmanFilter
from numpy.typing import NDArray

from roadpreview.fusion.base import VisualPitch
from roadpreview.fusion.config import KalmanConfig
from roadpreview.fusion.core import StreamingFusion
from roadpreview.fusion.gyro import Motion

Array = NDArray[np.float64]


def _inv_1x1(s: Array) -> Array:
    """Inverse of the 1x1 innovation covariance (filterpy's ``inv`` hook)."""
    return 1.0 / s


class GyroPitchKalmanFilter(StreamingFusion):
    """Pitch and gyro bias from gyro prediction and relative visual pitch (filterpy)."""

    name = "kalman"
    can_rewind = True

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.kcfg = config or KalmanConfig()
        self.max_rejections = self.kcfg.max_consecutive_rejections
        n = 2 + self.kcfg.n_clones
        self.kf = KalmanFilter(dim_x=n, dim_z=1)
        self.kf.inv = _inv_1x1
        self._R = np.zeros((1, 1))
        # measurement rows: phi minus the clone in slot i
        self._H = []
        for i in range(self.kcfg.n_clones):
            h = np.zeros((1, n))
            h[0, 0] = 1.0
            h[0, 2 + i] = -1.0
            self._H.append(h)
        self._gate2 = self.kcfg.gate_sigma**2
        super().__init__(self.kcfg)

    # -- hooks ------------------------------------------------------------------------------
    def _bk_reset(self) -> None:
        self.kf.x = np.zeros((self.kf.dim_x, 1))
        self.kf.P = np.zeros((self.kf.dim_x, self.kf.dim_x))
        self._slots: list[float] = [-math.inf] * self.kcfg.n_clones
        self._pinned = math.nan
        self._shift = 0.0  # movement of the pinned key's clone (level change)
        # per key frame: (last frame measured against it, its dphi, its variance)
        self._last_by_key: dict[float, tuple[float, float, float]] = {}

    def _bk_init(self, t0: float) -> None:
        self._bk_reset()
        g = self.config.gyro
        self.kf.x[1, 0] = g.initial_bias_rad_s
        self.kf.P[1, 1] = g.bias_prior_std_rad_s**2

    def _bk_propagate(self, t: float, motion: Motion) -> None:
        """x <- F x + B u, P <- F P F' + Q with F = I - ΔM e0 e1', u = ΔG and Q the white
        rate noise ΔV plus the bias walk q_b [[ΔM³/3, -ΔM²/2], [-ΔM²/2, Δt]] (filterpy's
        predict, written out for the structure of F: 3 µs instead of 8)."""
        dm = motion.dM
        x, P = self.kf.x, self.kf.P
        x[0, 0] += motion.dG - dm * x[1, 0]
        if dm != 0.0:
            P[0, :] -= dm * P[1, :]
            P[:, 0] -= dm * P[:, 1]
        # Q: white rate noise, and the bias walk during the interval as it reaches phi
        qb = self._q_bias
        P[0, 0] += motion.dV + qb * dm * dm * dm / 3.0
        P[0, 1] -= qb * dm * dm / 2.0
        P[1, 0] = P[0, 1]
        P[1, 1] += qb * (t - self._t)

    def _bk_frame(self, t: float) -> None:
        slots = self._slots
        victim = -1
        oldest = math.inf
        for i, ts in enumerate(slots):
            if ts != self._pinned and ts < oldest:
                oldest, victim = ts, i
        slots[victim] = t
        j = 2 + victim
        x, P = self.kf.x, self.kf.P
        x[j, 0] = x[0, 0]
        P[j, :] = P[0, :]
        P[:, j] = P[:, 0]
        P[j, j] = P[0, 0]

    def _bk_note(self, meas: VisualPitch) -> None:
        if meas.t_ref in self._slots:
            self._pinned = meas.t_ref

    def _bk_visual(self, meas: VisualPitch, var: float) -> bool:
        z, R = meas.dphi, var
        try:
            slot = self._slots.index(meas.t_ref)
        except ValueError:
            prev = self._last_by_key.get(meas.t_ref)
            if prev is None or prev[0] not in self._slots:
                self.events(
                    "no-key",
                    "key frame t_ref=%.6f of the measurement at t=%.6f has no clone and no"
                    " earlier measurement: skipped",
                    meas.t_ref,
                    meas.t,
                )
                return True  # not an outlier: nothing to test it against
            self.events(
                "key-increment", "key frame t_ref=%.6f has no clone: increments used", meas.t_ref
            )
            slot = self._slots.index(prev[0])
            z, R = meas.dphi - prev[1], var + prev[2]
            self._pinned = prev[0]
        self._remember(meas, var)
        j = 2 + slot
        x, P = self.kf.x, self.kf.P
        y = z - (x[0, 0] - x[j, 0])
        s = max(P[0, 0] + P[j, j] - 2.0 * P[0, j] + R, R)
        if y * y > self._gate2 * s:
            self.events(
                "gated",
                "visual measurement at t=%.6f gated (%.1f sigma)",
                meas.t,
                abs(y) / math.sqrt(s),
            )
            return False
        self._R[0, 0] = R
        self.kf.update(z, R=self._R, H=self._H[slot])  # a float z: filterpy's copy of it is free
        P = self.kf.P
        P += P.T  # keep P exactly symmetric: rounding in the products accumulates
        P *= 0.5
        if self._pinned in self._slots:  # how far the key frame's estimate moved
            self._shift += float(self.kf.K[2 + self._slots.index(self._pinned), 0]) * y
        return True

    def _remember(self, meas: VisualPitch, var: float) -> None:
        d = self._last_by_key
        d[meas.t_ref] = (meas.t, meas.dphi, var)
        if len(d) > 8:
            del d[min(d)]

    def _bk_output(self) -> tuple[float, float]:
        return float(self.kf.x[0, 0]), float(self.kf.P[0, 0])

    def _bk_bias(self) -> tuple[float, float]:
        return float(self.kf.x[1, 0]), float(self.kf.P[1, 1])

    def _bk_take_level_shift(self) -> float:
        shift, self._shift = self._shift, 0.0
        return shift

    def _bk_snapshot(self) -> Any:
        return (
            self.kf.x.copy(),
            self.kf.P.copy(),
            list(self._slots),
            self._pinned,
            dict(self._last_by_key),
            self._shift,
        )

    def _bk_restore(self, snap: Any) -> None:
        x, P, slots, pinned, last, shift = snap
        self.kf.x = x
        self.kf.P = P
        self._slots = slots
        self._pinned = pinned
        self._last_by_key = last
        self._shift = shift
