"""The paper's pitch estimator: robust Sampson cost, Levenberg–Marquardt, warm start.

Minimises (paper eq. 3)::

    C(θ) = Σ_i ρ( g_i(θ)² / σ² ),   ρ(z) = log(1 + z)

where g_i is the signed Sampson distance (pixels) of correspondence i under
``F(θ) = -K^{-T} [t]_x R(θ) K^{-1}`` and σ the Cauchy scale in pixels (the
paper's ρ(z) = log(1+z) on the Sampson error in px² is σ = 1 px). θ is the
pitch φ alone (the paper's model, the default) or (φ, yaw) or (φ, yaw, roll).

Levenberg–Marquardt on a robustified Gauss–Newton model (gradient
``Σ w_i g_i J_i``, Hessian ``Σ w_i (1 - 2 w_i g_i²) J_iᵀ J_i`` with
``w_i = 1/(σ² + g_i²)``, falling back to the IRLS Hessian ``Σ w_i J_iᵀ J_i``
where outliers make the exact one indefinite), damped by λ, steps limited to a
trust region. The start is the previous frame's estimate (warm start), 0 for
the first frame. An optional polish with Tukey's biweight (our extension,
default on) removes the residual pull of gross outliers. The standard
deviation comes from the curvature with a sandwich correction for the robust
weights and a robust (MAD) estimate of the inlier noise. See ``docs/pitch.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview.camera import CameraModel
from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError
from roadpreview.pitch.base import (
    PitchEstimate,
    poor_fit_reason,
    too_few,
    validate_correspondences,
)
from roadpreview.pitch.geometry import (
    PitchOnlySampson,
    normalise,
    sampson_distance_and_jacobian,
)

Array = NDArray[np.float64]

_DOF = {"pitch": 1, "pitch_yaw": 2, "pitch_yaw_roll": 3}


@dataclass(frozen=True)
class RobustPitchConfig:
    """Settings of `RobustPitchEstimator` (units in the field metadata)."""

    cauchy_scale_px: float = param(
        1.0,
        unit="px",
        gt=0.0,
        help="σ of ρ(g²/σ²) = log(1 + g²/σ²); the paper's log(1+z) on px² is σ = 1 px",
    )
    loss: str = param(
        "cauchy",
        choices=("cauchy", "linear"),
        help="'linear' is plain least squares, kept only as a comparison",
    )
    dof: str = param(
        "pitch",
        choices=tuple(_DOF),
        help="rotation model: the paper's pitch only, or with yaw (and roll) for curves",
    )
    min_correspondences: int = param(
        12,
        ge=3,
        help="fewer valid pairs than this is a failed fit, not a guess",
    )
    max_iterations: int = param(50, ge=1, help="LM iterations before giving up")
    step_tolerance_rad: float = param(
        1e-6,
        unit="rad",
        gt=0.0,
        help="converged when the step is smaller (5.7e-5 deg, 200x below the 0.01 deg goal)",
    )
    max_step_rad: float = param(
        0.05,
        unit="rad",
        gt=0.0,
        help="trust region of one LM step (2.9 deg); the cost is periodic in the angles",
    )
    max_abs_angle_rad: float = param(
        0.35,
        unit="rad",
        gt=0.0,
        le=1.5,
        help="a rotation beyond 20 deg between frames is not a car's pitch: failed fit",
    )
    inlier_threshold_px: float = param(
        2.0,
        unit="px",
        gt=0.0,
        help="|Sampson distance| below this counts as an inlier",
    )
    min_inlier_ratio: float = param(
        0.25,
        ge=0.0,
        le=1.0,
        help="below this the fit is reported as poor (falsy)",
    )
    min_information: float = param(
        1e4,
        unit="1/rad²",
        ge=0.0,
        help="mean-normalised curvature below this means the pitch is unobservable",
    )
    initial_damping: float = param(1e-3, gt=0.0, help="LM λ at the first iteration")
    vote: bool = param(
        True,
        help=(
            "extension: restart a far start from a one-point vote (the paper's LM alone "
            "crawls on the flat Cauchy cost far from the minimum)"
        ),
    )
    vote_step_rad: float = param(
        5e-4,
        unit="rad",
        gt=0.0,
        help=(
            "a first Newton step longer than this (0.03 deg) means the warm start is far: "
            "restart from a one-point vote, which lands within about 0.01 deg"
        ),
    )
    polish_tukey_c: float = param(
        3.5,
        ge=0.0,
        help=(
            "extension: after the Cauchy fit, reweighted steps with Tukey's biweight at "
            "c = this x the MAD noise, which rejects gross outliers entirely (Cauchy's "
            "influence only decays as 1/g); 0 = the paper's pure Cauchy fit"
        ),
    )
    polish_iterations: int = param(
        3,
        ge=1,
        help="Tukey IRLS steps; from the Cauchy optimum two or three suffice",
    )

    def validate(self, where: str = "") -> None:
        if self.dof not in _DOF:
            raise ConfigError(f"{where}.dof = {self.dof!r}: must be one of {list(_DOF)}")


class _Model(Protocol):
    def __call__(self, theta: Array) -> tuple[Array, Array]: ...
    def distance(self, theta: Array) -> Array: ...


class _PitchModel:
    """The paper's one-parameter model on the fast trigonometric-polynomial path."""

    def __init__(self, n_ref: Array, n_cur: Array, t: Array, fx: float, fy: float) -> None:
        self._m = PitchOnlySampson(n_ref, n_cur, t, fx, fy)

    def __call__(self, theta: Array) -> tuple[Array, Array]:
        g, dg = self._m(float(theta[0]))
        return g, dg[:, None]

    def distance(self, theta: Array) -> Array:
        return self._m.distance(float(theta[0]))


class _RotationModel:
    """Pitch with yaw (and roll): the general analytic Jacobian."""

    def __init__(self, n_ref: Array, n_cur: Array, t: Array, fx: float, fy: float) -> None:
        self._args = (n_ref, n_cur, t, fx, fy)

    def __call__(self, theta: Array) -> tuple[Array, Array]:
        return sampson_distance_and_jacobian(theta, *self._args)

    def distance(self, theta: Array) -> Array:
        return sampson_distance_and_jacobian(theta, *self._args)[0]


def _median_abs(x: Array) -> float:
    """median(|x|) through one partition (np.median's overhead is large at N ~ 1000)."""
    a = np.abs(x)
    k = a.size // 2
    if a.size % 2:
        return float(np.partition(a, k)[k])
    part = np.partition(a, (k - 1, k))
    return 0.5 * float(part[k - 1] + part[k])


def _limit(delta: Array, max_step: float) -> tuple[Array, float]:
    """Clip a step to the trust region; also return its largest component."""
    if delta.size == 1:
        d = min(max(float(delta[0]), -max_step), max_step)
        return np.array([d]), abs(d)
    delta = np.clip(delta, -max_step, max_step)
    return delta, float(np.max(np.abs(delta)))


def _solve(A: Array, b: Array) -> Array:
    """``A^{-1} b`` for the tiny (k <= 3) normal equations; scalar fast path for k = 1."""
    if A.shape == (1, 1):
        if A[0, 0] == 0.0 or not math.isfinite(float(A[0, 0])):
            raise np.linalg.LinAlgError("singular 1x1 system")
        return b / float(A[0, 0])
    return np.asarray(np.linalg.solve(A, b), dtype=np.float64)


def _positive_definite(H: Array) -> bool:
    if H.shape == (1, 1):
        return bool(H[0, 0] > 0.0)
    try:
        np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        return False
    return True


class RobustPitchEstimator:
    """Pitch (optionally yaw, roll) from background correspondences, the paper's method.

    Parameters
    ----------
    camera
        Calibrated camera: K and the forward direction t.
    config
        `RobustPitchConfig`; defaults are the paper's choices plus the Tukey polish.

    The estimator keeps the last successful estimate as the warm start of the
    next call; `reset` forgets it (call it when the reference frame changes to
    one whose relative pitch is unrelated).
    """

    name = "robust"

    def __init__(self, camera: CameraModel, config: RobustPitchConfig | None = None) -> None:
        self.camera = camera
        self.config = config or RobustPitchConfig()
        check_ranges(self.config, "pitch")
        self.config.validate("pitch")
        self._k = _DOF[self.config.dof]
        self._theta_prev = np.zeros(self._k)

    def reset(self) -> None:
        """Forget the warm start; the next fit starts from zero rotation."""
        self._theta_prev = np.zeros(self._k)

    # -- pieces of the fit ----------------------------------------------------------
    def _cost(self, g: Array) -> float:
        if self.config.loss == "cauchy":
            return float(np.sum(np.log1p(g * g / self.config.cauchy_scale_px**2)))
        return float(0.5 * np.dot(g, g))

    def _normal_equations(self, g: Array, J: Array) -> tuple[Array, Array]:
        """Hessian model and half-gradient of the cost at the current parameters."""
        if self.config.loss != "cauchy":
            return J.T @ J, J.T @ g
        w = 1.0 / (self.config.cauchy_scale_px**2 + g * g)
        grad = J.T @ (w * g)
        H_exact = J.T @ (J * (w * (1.0 - 2.0 * w * g * g))[:, None])
        if _positive_definite(H_exact):
            return H_exact, grad
        return J.T @ (J * w[:, None]), grad

    def _start_is_poor(self, g: Array, J: Array) -> bool:
        """Is the start too far for LM on the Cauchy cost to be quick?

        Far from the minimum the Cauchy cost with σ = 1 px is nearly flat and
        its curvature misleading, so LM crawls or overshoots. The start is poor
        when fewer than a quarter of the points lie within 3 σ, or when the first
        Newton step would be longer than ``vote_step_rad``.
        """
        near = np.abs(g) < 3.0 * self.config.cauchy_scale_px
        if np.count_nonzero(near) < 0.25 * g.size:
            return True
        H, grad = self._normal_equations(g, J)
        return not (H[0, 0] > 0.0 and abs(grad[0] / H[0, 0]) < self.config.vote_step_rad)

    def _vote(
        self, model: _Model, theta: Array, g: Array, J: Array, cost: float
    ) -> tuple[Array, Array, Array]:
        """A one-point vote for the start: each correspondence alone, linearised at
        ``theta``, fixes φ_i = φ - g_i / g'_i; the |g'|-weighted median of these is a
        robust start (a Hough vote in one dimension, one evaluation of the model)."""
        slope = J[:, 0]
        usable = np.abs(slope) > 1e-6 * float(np.max(np.abs(slope)))
        if np.count_nonzero(usable) < 3:  # no point sees the pitch: leave it to the checks
            return theta, g, J
        candidates = theta[0] - g[usable] / slope[usable]
        weights = np.abs(slope[usable])
        order = np.argsort(candidates)
        cum = np.cumsum(weights[order])
        median = float(candidates[order][np.searchsorted(cum, 0.5 * cum[-1])])
        step = float(
            np.clip(median - theta[0], -self.config.max_step_rad, self.config.max_step_rad)
        )
        new_theta = theta + step
        g_new, J_new = model(new_theta)
        if self._cost(g_new) < cost:
            return new_theta, g_new, J_new
        return theta, g, J

    def _tukey_weights(self, g: Array, c: float) -> Array:
        u = g / c
        return np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)

    def _tukey_polish(
        self, model: _Model, theta: Array, g: Array, J: Array
    ) -> tuple[Array, Array, Array, float, int]:
        """IRLS with Tukey's biweight, started at the Cauchy optimum (a redescending
        M-estimator needs a good start, which the Cauchy fit provides)."""
        cfg = self.config
        c = max(1.4826 * _median_abs(g), 0.05) * cfg.polish_tukey_c
        steps = 0
        while steps < cfg.polish_iterations:  # iterations, not points
            steps += 1
            w = self._tukey_weights(g, c)
            Jw = J * w[:, None]
            try:
                delta = -_solve(J.T @ Jw, Jw.T @ g)
            except np.linalg.LinAlgError:
                break
            delta, step = _limit(delta, cfg.max_step_rad)
            theta = theta + delta
            g, J = model(theta)
            if step < 10.0 * cfg.step_tolerance_rad:
                break
        return theta, g, J, c, steps

    # -- the fit ----------------------------------------------------------------------
    def estimate(
        self, x_ref: ArrayLike, x_cur: ArrayLike, initial: ArrayLike | None = None
    ) -> PitchEstimate:
        """Fit the rotation from (N, 2) pixel pairs ``x_ref`` (reference) -> ``x_cur``.

        ``initial`` overrides the warm start (a pitch, or one value per parameter).
        Rows with a NaN/inf coordinate are dropped (counted in ``n_invalid``);
        wrong shapes raise `InputDataError`.
        """
        cfg = self.config
        a, b, n_invalid = validate_correspondences(x_ref, x_cur)
        n = a.shape[0]
        if (failed := too_few(n, cfg.min_correspondences, n_invalid)) is not None:
            return failed
        cam = self.camera
        K = cam.K
        model_cls = _PitchModel if self._k == 1 else _RotationModel
        model: _Model = model_cls(normalise(a, K), normalise(b, K), cam.t, cam.fx, cam.fy)
        if initial is None:
            theta = self._theta_prev.copy()
        else:
            theta = np.zeros(self._k)
            init = np.asarray(initial, dtype=np.float64).ravel()
            theta[: min(self._k, init.size)] = init[: self._k]

        g, J = model(theta)
        if not math.isfinite(float(np.dot(g, g)) + float(J.sum())):
            return PitchEstimate.failed(
                "degenerate geometry: a correspondence lies on the epipole (zero epipolar line)",
                n_points=n,
                n_invalid=n_invalid,
            )
        it = 0
        if self._k == 1 and cfg.vote and cfg.loss == "cauchy" and self._start_is_poor(g, J):
            theta, g, J = self._vote(model, theta, g, J, self._cost(g))
            it = 1
        cost = self._cost(g)
        lam = cfg.initial_damping
        converged = False
        while it < cfg.max_iterations:  # iterations, not points
            it += 1
            H, grad = self._normal_equations(g, J)
            diag = np.diag(np.maximum(np.diag(H), 1e-12)) if self._k > 1 else np.maximum(H, 1e-12)
            accepted = False
            small_step = False
            while lam < 1e10:
                try:
                    delta = -_solve(H + lam * diag, grad)
                except np.linalg.LinAlgError:
                    lam *= 10.0
                    continue
                delta, step = _limit(delta, cfg.max_step_rad)
                small_step = step < cfg.step_tolerance_rad
                theta_new = theta + delta
                g_new, J_new = model(theta_new)
                cost_new = self._cost(g_new)
                if cost_new < cost or (small_step and cost_new <= cost):
                    theta, cost, g, J = theta_new, cost_new, g_new, J_new
                    lam = max(lam * 0.1, 1e-12)
                    accepted = True
                    break
                if small_step:
                    break
                lam *= 10.0
            if small_step or not accepted:
                # no step lowers the cost any more: a minimum
                converged = True
                break
        if not converged:
            return PitchEstimate.failed(
                f"no convergence in {cfg.max_iterations} iterations",
                n_points=n,
                iterations=it,
                n_invalid=n_invalid,
            )

        if cfg.loss == "cauchy" and cfg.polish_tukey_c > 0.0:
            theta, g, J, c, polish_iters = self._tukey_polish(model, theta, g, J)
            it += polish_iters
            w = self._tukey_weights(g, c)
        elif cfg.loss == "cauchy":
            w = 1.0 / (cfg.cauchy_scale_px**2 + g * g)
        else:
            w = np.ones_like(g)

        if float(np.max(np.abs(theta))) > cfg.max_abs_angle_rad:
            return PitchEstimate.failed(
                f"implausible rotation {np.degrees(theta).round(2).tolist()} deg "
                f"(limit {math.degrees(cfg.max_abs_angle_rad):.0f} deg)",
                n_points=n,
                iterations=it,
                n_invalid=n_invalid,
            )

        # curvature, observability and a robust sandwich covariance
        Jw = J * w[:, None]
        H = J.T @ Jw
        inliers = np.abs(g) < cfg.inlier_threshold_px
        n_in = int(np.count_nonzero(inliers))
        inlier_ratio = n_in / n
        info = float(H[0, 0]) / max(float(w.mean()), 1e-12) / n
        if not math.isfinite(info) or info < cfg.min_information:
            return PitchEstimate.failed(
                f"degenerate geometry: pitch unobservable (information per point {info:.3g} "
                f"< {cfg.min_information:.3g} 1/rad²)",
                n_points=n,
                iterations=it,
                n_invalid=n_invalid,
            )
        g_in = g[inliers] if n_in >= 3 else g
        noise = max(1.4826 * _median_abs(g_in), 1e-3)
        try:
            H_inv = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return PitchEstimate.failed(
                "degenerate geometry: singular curvature",
                n_points=n,
                iterations=it,
                n_invalid=n_invalid,
            )
        meat = (J.T @ (J * (w * w)[:, None])) * noise**2
        cov = H_inv @ meat @ H_inv
        std = math.sqrt(max(float(cov[0, 0]), 0.0))
        reason = poor_fit_reason(inlier_ratio, cfg.min_inlier_ratio)
        result = PitchEstimate(
            phi=float(theta[0]),
            std=std,
            inlier_ratio=inlier_ratio,
            iterations=it,
            converged=True,
            n_points=n,
            reason=reason,
            yaw=float(theta[1]) if self._k > 1 else 0.0,
            roll=float(theta[2]) if self._k > 2 else 0.0,
            cost=cost,
            n_invalid=n_invalid,
        )
        if result:
            self._theta_prev = theta.copy()
        return result
