"""`factor-graph`: a gtsam fixed-lag smoother over pitch and gyro bias at frame times.

`GyroPitchFixedLagSmoother` is the `PitchBackEnd`; `factor_graph_fusion` puts it into
the `StreamingPitchFusion` that the registry name ``factor-graph`` builds.

Variables (1-vectors; gtsam's scalar ``double`` values are slow to insert from
Python): ``x_k`` the pitch at frame k (relative to the first frame) and
``b_j`` the gyro pitch-rate bias, a new one every ``bias_node_every_s``.
Factors:

* gyro between-factor on (x_{k-1}, x_k, b_j): the integrated rate over the
  interval, ``x_k - x_{k-1} - (ΔG - ΔM b_j)``, sigma sqrt(ΔV) (the same running
  integral as the Kalman filter, `GyroHistory`). By default gtsam's C++ linear
  factor (`LinearContainerFactor` of a `JacobianFactor`: exact, the model is
  linear); ``gyro_factor = "custom"`` makes it a `gtsam.CustomFactor` with the
  same error, which the smoother calls back into Python for at every update;
* bias random walk ``BetweenFactorVector(b_{j-1}, b_j, 0)``, sigma sqrt(q_b Δt);
* visual factor ``BetweenFactorVector(x_key, x_k, dphi)`` with a robust noise
  model (Huber by default: Gaussian for inliers, linear beyond ``robust_k``
  sigmas) of the measurement's own sigma;
* priors x_0 = 0 and b_0 = initial bias at the start.

The smoother keeps ``lag_s`` (2 s) of states. The key frame of the current
visual measurements is re-stamped at every use so that it stays in the window
however long the front end keeps it. ``IncrementalFixedLagSmoother`` (iSAM2)
is the default; upstream reports crashes and a factor list that grows without
bound with it (its unused factor slots are reused here), so the smoother can
also be re-created from its own marginals every ``rebuild_every_s`` (a bounded
rebuild), and `BatchFixedLagSmoother` (LM over the window) is available as
``smoother = "batch"``.

The output at a frame is the filtered estimate of its state (the newest in the
window). Frames beyond the commit horizon (gyro not yet arrived) are
extrapolated from the newest committed state (`StreamingPitchFusion._tentative`).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Mapping
from typing import SupportsFloat, SupportsIndex, SupportsInt, cast

import gtsam
import numpy as np
from numpy.typing import NDArray

from roadpreview.fusion.base import BackEndEstimate, VisualPitch
from roadpreview.fusion.config import FactorGraphConfig
from roadpreview.fusion.gyro import Motion, RejectCounter
from roadpreview.fusion.streaming import StreamingPitchFusion

_MIN_SIGMA = 1e-9  # rad: floor of every noise sigma (an interval of zero length)

Array = NDArray[np.float64]
#: the error function of a `gtsam.CustomFactor` (gtsam's stubs give its signature)
_ErrorFunction = Callable[[gtsam.CustomFactor, gtsam.Values, gtsam.JacobianVector | None], Array]
_Smoother = gtsam.IncrementalFixedLagSmoother | gtsam.BatchFixedLagSmoother
#: key -> stamp as the smoothers' `update` is typed (its Mapping's key type is invariant)
_Stamps = Mapping[SupportsInt | SupportsIndex, SupportsFloat | SupportsIndex]


def X(k: int) -> int:
    return int(gtsam.symbol("x", k))


def B(k: int) -> int:
    return int(gtsam.symbol("b", k))


_MINUS_ONE = np.array([[-1.0]])
_ONE = np.array([[1.0]])


def _gyro_error(k0: int, k1: int, kb: int, d_g: float, d_m: float) -> _ErrorFunction:
    """Error of the gyro between-factor: x_k - x_{k-1} - (ΔG - ΔM b); its Jacobians are
    constant (the model is linear)."""
    h_b = np.array([[d_m]])

    def error(this: gtsam.CustomFactor, v: gtsam.Values, H: gtsam.JacobianVector | None) -> Array:
        e: Array = v.atVector(k1) - v.atVector(k0) - d_g + d_m * v.atVector(kb)
        if H is not None:
            H[0] = _MINUS_ONE
            H[1] = _ONE
            H[2] = h_b
        return e

    return error


def _joint_prior_error(keys: list[int], mean: Array) -> _ErrorFunction:
    """Error of a joint Gaussian prior on several 1-vector variables (bounded rebuild)."""
    n = mean.size
    jac = [np.eye(n)[:, i : i + 1] for i in range(n)]

    def error(this: gtsam.CustomFactor, v: gtsam.Values, H: gtsam.JacobianVector | None) -> Array:
        x = np.array([v.atVector(k)[0] for k in keys])
        if H is not None:
            for i in range(n):
                H[i] = jac[i]
        return x - mean

    return error


def factor_graph_fusion(config: FactorGraphConfig | None = None) -> StreamingPitchFusion:
    """The ``factor-graph`` fusion: `GyroPitchFixedLagSmoother` in a `StreamingPitchFusion`."""
    config = config or FactorGraphConfig()
    return StreamingPitchFusion(GyroPitchFixedLagSmoother(config), config)


class GyroPitchFixedLagSmoother:
    """Pitch and gyro bias by a gtsam fixed-lag smoother over frame-time states; a
    `PitchBackEnd` (it cannot copy its state: frames beyond the gyro are extrapolated)."""

    name = "factor-graph"
    #: the robust loss bounds an outlier's pull but rejects nothing: the fusion tests every
    #: measurement against the gyro
    gate_with_gyro = True
    max_rejections = 5

    def __init__(self, config: FactorGraphConfig | None = None) -> None:
        self.config = config or FactorGraphConfig()
        self.events = RejectCounter(f"fusion[{self.name}]")
        self._q_bias = self.config.gyro.bias_random_walk**2
        self._reset()

    # -- smoother ---------------------------------------------------------------------------
    def _new_smoother(self) -> _Smoother:
        if self.config.smoother == "batch":
            return gtsam.BatchFixedLagSmoother(self.config.lag_s)
        params = gtsam.ISAM2Params()
        # relinearise whatever moves by more than a small fraction of a visual sigma, so that
        # the robust weights are re-evaluated at the solution (iteratively reweighted)
        params.setRelinearizeThreshold(self.config.relinearize_threshold_rad)
        params.relinearizeSkip = self.config.relinearize_skip
        params.findUnusedFactorSlots = True  # reuse the slots of removed factors (no growth)
        return gtsam.IncrementalFixedLagSmoother(self.config.lag_s, params)

    def _noise(self, sigma: float) -> gtsam.noiseModel.Isotropic:
        return gtsam.noiseModel.Isotropic.Sigma(1, max(sigma, _MIN_SIGMA))

    def _robust(self, sigma: float) -> gtsam.noiseModel.Base:
        base = self._noise(sigma)
        loss = self.config.robust_loss
        if loss == "none":
            return base
        k = self.config.robust_k
        m = (
            gtsam.noiseModel.mEstimator.Huber.Create(k)
            if loss == "huber"
            else gtsam.noiseModel.mEstimator.Cauchy.Create(k)
        )
        return gtsam.noiseModel.Robust.Create(m, base)

    # -- PitchBackEnd -----------------------------------------------------------------------
    def _reset(self) -> None:
        self.smoother: _Smoother = self._new_smoother()
        self._k = -1  # newest pitch state
        self._j = 0  # current bias state
        self._bias_t = -math.inf  # when it was added
        self._key_of: dict[float, int] = {}  # frame time -> state index
        self._graph = gtsam.NonlinearFactorGraph()
        self._values = gtsam.Values()
        self._stamps: dict[int, float] = {}
        self._unit = gtsam.noiseModel.Unit.Create(1)
        self._phi = 0.0
        self._var = 0.0
        self._b = 0.0
        self._bvar = 0.0
        self._bvar_node = -1  # the bias state whose variance _bvar is
        self._frame_cache: dict[int, tuple[int, float, float]] = {}  # k -> (update, phi, var)
        self._pinned = math.nan
        # key -> stamp as the smoother holds them, oldest first; X key -> frame time
        self._times: OrderedDict[int, float] = OrderedDict()
        self._newest_stamp = -math.inf
        self._frame_of: dict[int, float] = {}
        self._shift = 0.0
        self._last_by_key: dict[float, tuple[float, float, float]] = {}
        self._last_rebuild = -math.inf
        self.n_updates = 0

    def start(self, t0: float) -> None:
        """phi = 0 at the first frame ``t0`` (a tight prior), the configured bias prior."""
        self._reset()  # (a new smoother)
        g = self.config.gyro
        self._last_rebuild = t0
        self._k = 0
        self._key_of[t0] = 0
        b0 = np.array([g.initial_bias_rad_s])
        self._j = 0
        self._bias_t = t0
        self._values.insert(X(0), np.zeros(1))
        self._values.insert(B(0), b0)
        self._graph.add(gtsam.PriorFactorVector(X(0), np.zeros(1), self._noise(1e-6)))
        self._graph.add(gtsam.PriorFactorVector(B(0), b0, self._noise(g.bias_prior_std_rad_s)))
        self._stamps[X(0)] = t0
        self._frame_of[X(0)] = t0
        self._stamps[B(0)] = t0
        self._b = g.initial_bias_rad_s
        self._bvar = g.bias_prior_std_rad_s**2

    def step(self, t: float, dG: float, dV: float, dM: float) -> None:
        """A new pitch state at frame ``t``, tied to the previous one by the gyro factor (and
        a new bias state every `FactorGraphConfig.bias_node_every_s`); solved at
        `end_frame`."""
        k0 = self._k
        k = k0 + 1
        self._k = k
        self._key_of[t] = k
        mo = Motion(dG, dV, dM)
        x0, x1, b0 = X(k0), X(k), B(self._j)
        pred = self._phi + mo.dG - self._b * mo.dM
        self._values.insert(x1, np.array([pred]))
        self._graph.add(self._gyro_factor(x0, x1, b0, mo, pred))
        self._stamps[x1] = t
        self._frame_of[x1] = t
        self._stamps[b0] = t  # in use: keep it in the window
        if t - self._bias_t >= self.config.bias_node_every_s - 1e-9:
            self._j += 1
            b1 = B(self._j)
            self._values.insert(b1, np.array([self._b]))
            sigma = math.sqrt(self._q_bias * (t - self._bias_t))
            self._graph.add(gtsam.BetweenFactorVector(b0, b1, np.zeros(1), self._noise(sigma)))
            self._stamps[b1] = t
            self._bias_t = t
        self._phi = pred  # until the smoother says otherwise

    def _gyro_factor(
        self, x0: int, x1: int, b0: int, mo: Motion, pred: float
    ) -> gtsam.NonlinearFactor:
        """x1 - x0 - (ΔG - ΔM b0), sigma sqrt(ΔV): a `gtsam.CustomFactor`, or (default) the
        same linear factor held in C++ (`LinearContainerFactor` of a `JacobianFactor` at the
        current estimate), which the smoother evaluates without calling back into Python."""
        sigma = max(math.sqrt(mo.dV), _MIN_SIGMA)
        if self.config.gyro_factor == "custom":
            return gtsam.CustomFactor(
                self._noise(sigma), [x0, x1, b0], _gyro_error(x0, x1, b0, mo.dG, mo.dM)
            )
        lin = gtsam.Values()
        lin.insert(x0, np.array([self._phi]))
        lin.insert(x1, np.array([pred]))
        lin.insert(b0, np.array([self._b]))
        # whitened: (A δ - r) / sigma with the residual r = 0 at the linearisation point
        jf = gtsam.JacobianFactor(
            x0,
            np.array([[-1.0 / sigma]]),
            x1,
            np.array([[1.0 / sigma]]),
            b0,
            np.array([[mo.dM / sigma]]),
            np.zeros(1),
            self._unit,
        )
        return gtsam.LinearContainerFactor(jf, lin)

    def pin_key(self, t_ref: float) -> None:
        if t_ref in self._key_of:
            self._pinned = t_ref

    def update(self, meas: VisualPitch, var: float) -> bool:
        """A robust between-factor from the key frame's state to the current one (never
        rejected here: ``gate_with_gyro``)."""
        k = self._key_of[meas.t]
        z, R = meas.dphi, var
        kref = self._key_of.get(meas.t_ref)
        if kref is None:
            prev = self._last_by_key.get(meas.t_ref)
            if prev is None or prev[0] not in self._key_of:
                self.events(
                    "no-key",
                    "key frame t_ref=%.6f of t=%.6f is not in the window: skipped",
                    meas.t_ref,
                    meas.t,
                )
                return True
            kref = self._key_of[prev[0]]
            z, R = meas.dphi - prev[1], var + prev[2]
            self.events(
                "key-increment", "key frame t_ref=%.6f left the window: increments used", meas.t_ref
            )
        self._last_by_key[meas.t_ref] = (meas.t, meas.dphi, var)
        if len(self._last_by_key) > 8:
            del self._last_by_key[min(self._last_by_key)]
        self._graph.add(
            gtsam.BetweenFactorVector(X(kref), X(k), np.array([z]), self._robust(math.sqrt(R)))
        )
        self._stamps[X(kref)] = meas.t  # keep the key frame in the window
        return True

    def end_frame(self, t: float) -> None:
        """Give the frame's new factors to the smoother and read the new estimate."""
        if self._graph.size() == 0:
            return
        kp = self._key_of.get(self._pinned)
        before = (
            float(self.smoother.calculateEstimateVector(X(kp))[0])
            if kp is not None and X(kp) in self._times
            else None
        )
        self.smoother.update(self._graph, self._values, cast(_Stamps, self._stamps))
        self.n_updates += 1
        self._restamp(self._stamps)
        self._frame_cache.clear()
        self._graph = gtsam.NonlinearFactorGraph()
        self._values = gtsam.Values()
        self._stamps = {}
        self._forget_old()
        k = self._k
        est = self.smoother.calculateEstimateVector
        self._phi = float(est(X(k))[0])
        self._b = float(est(B(self._j))[0])
        self._var, self._bvar = self._marginal_variances(k)
        if before is not None and kp is not None and kp in self._key_of.values():
            self._shift += float(est(X(kp))[0]) - before  # how far the key frame moved
        every = self.config.rebuild_every_s
        if every > 0 and t - self._last_rebuild >= every:
            self._rebuild(t)

    def _restamp(self, stamps: dict[int, float]) -> None:
        """Record the stamps the smoother now holds, oldest first."""
        times = self._times
        for key, ts in stamps.items():
            times[key] = ts
            times.move_to_end(key)
            self._newest_stamp = max(self._newest_stamp, ts)

    def _forget_old(self) -> None:
        """Drop what the smoother has marginalised: keys stamped more than ``lag_s`` before
        the newest stamp (the fixed-lag smoothers' rule)."""
        times = self._times
        cutoff = self._newest_stamp - self.config.lag_s
        while times:
            key, ts = next(iter(times.items()))
            if ts >= cutoff:
                break
            del times[key]
            tf = self._frame_of.pop(key, None)
            if tf is not None:
                del self._key_of[tf]

    def _marginal_variances(self, k: int) -> tuple[float, float]:
        """Marginal variances of the newest pitch (every frame) and of the bias (when a bias
        state is added, every `FactorGraphConfig.bias_node_every_s`: it changes slowly)."""
        new_bias = self._j != self._bvar_node
        if isinstance(self.smoother, gtsam.IncrementalFixedLagSmoother):
            var = float(self.smoother.marginalCovariance(X(k))[0, 0])
            if new_bias:
                self._bvar = float(self.smoother.marginalCovariance(B(self._j))[0, 0])
        else:
            marg = gtsam.Marginals(self.smoother.getFactors(), self.smoother.calculateEstimate())
            var = float(marg.marginalCovariance(X(k))[0, 0])
            if new_bias:
                self._bvar = float(marg.marginalCovariance(B(self._j))[0, 0])
        self._bvar_node = self._j
        return var, self._bvar

    def _rebuild(self, t: float) -> None:
        """Bounded rebuild: a new smoother holding the newest state, its bias and the key
        frame, with their joint marginal as the prior (their correlation is kept)."""
        k = self._k
        keys = [X(k), B(self._j)]
        kp = self._key_of.get(self._pinned)
        if kp is not None and kp != k:
            keys.append(X(kp))
        kv = gtsam.KeyVector(keys)
        if isinstance(self.smoother, gtsam.IncrementalFixedLagSmoother):
            jm = self.smoother.getISAM2().jointMarginalCovariance(kv)
        else:
            marg = gtsam.Marginals(self.smoother.getFactors(), self.smoother.calculateEstimate())
            jm = marg.jointMarginalCovariance(kv)
        cov = np.array(jm.fullMatrix())
        cov = 0.5 * (cov + cov.T)
        mean = np.array([float(self.smoother.calculateEstimateVector(key)[0]) for key in keys])
        self.smoother = self._new_smoother()
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        for key, m in zip(keys, mean, strict=True):
            values.insert(key, np.array([m]))
        graph.add(
            gtsam.CustomFactor(
                gtsam.noiseModel.Gaussian.Covariance(cov), keys, _joint_prior_error(keys, mean)
            )
        )
        stamps = dict.fromkeys(keys, t)
        self.smoother.update(graph, values, cast(_Stamps, stamps))
        self._times = OrderedDict()
        self._restamp(stamps)
        self._key_of = {tf: kk for tf, kk in self._key_of.items() if X(kk) in keys}
        self._frame_of = {X(kk): tf for tf, kk in self._key_of.items()}
        self._last_rebuild = t

    def estimate(self) -> BackEndEstimate:
        return self._phi, self._var, self._b, self._bvar

    def frame_estimate(self, t: float) -> tuple[float, float] | None:
        k = self._key_of.get(t)
        if k is None or X(k) not in self._times:
            return None
        cached = self._frame_cache.get(k)
        if cached is None or cached[0] != self.n_updates:
            phi = float(self.smoother.calculateEstimateVector(X(k))[0])
            var = self._marginal_x(k)
            cached = (self.n_updates, phi, var)
            self._frame_cache[k] = cached
        return cached[1], cached[2]

    def _marginal_x(self, k: int) -> float:
        if isinstance(self.smoother, gtsam.IncrementalFixedLagSmoother):
            return float(self.smoother.marginalCovariance(X(k))[0, 0])
        marg = gtsam.Marginals(self.smoother.getFactors(), self.smoother.calculateEstimate())
        return float(marg.marginalCovariance(X(k))[0, 0])

    def take_level_shift(self) -> float:
        shift, self._shift = self._shift, 0.0
        return shift
