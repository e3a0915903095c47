"""Vertical vehicle dynamics: a linear 4-corner car (3-DOF body, or 7-DOF with wheels) on a road.

The body (sprung mass) heaves, pitches and rolls on four spring-damper corners;
in the 7-DOF model each corner has an unsprung mass on a tyre spring. The road
enters under each wheel after a tyre-enveloping filter (rigid-disc envelope of
the wheel radius, then a moving average over the contact patch). Longitudinal
acceleration pitches the body through the moment m a_x h_cg (braking dives the
nose). The linear system is discretised exactly (matrix exponential, inputs
piecewise linear in time) and run loop-free in modal coordinates. Equations,
parameters and tests: ``docs/simulator-physics.md``; sign conventions:
``docs/method.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import linalg
from scipy.ndimage import uniform_filter1d
from scipy.signal import lfilter

from roadpreview.configtools import check_ranges, param
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.sim.frames import body_to_world
from roadpreview.sim.road import Road
from roadpreview.sim.types import VehiclePose, VehicleShape

FloatArray = NDArray[np.float64]

MODELS = ("7dof", "3dof")
#: corner order used by every (n, 4) array: front-left, front-right, rear-left, rear-right
CORNERS = ("FL", "FR", "RL", "RR")

#: spacing of the spatial grid on which the tyre-enveloping filter runs, m
_ENVELOPE_GRID_M = 0.01
#: modal propagation is used when the eigenvector matrix is better conditioned than this
_MODAL_MAX_COND = 1e8


@dataclass(frozen=True)
class SuspensionRates:
    """Per-corner spring rates (N/m) and damper rates (N s/m) of the front and rear axles."""

    front_spring_npm: float
    rear_spring_npm: float
    front_damper_nspm: float
    rear_damper_nspm: float

    def corners(self) -> tuple[FloatArray, FloatArray]:
        """Spring and damper rates per corner in ``CORNERS`` order."""
        k = np.array([self.front_spring_npm] * 2 + [self.rear_spring_npm] * 2)
        c = np.array([self.front_damper_nspm] * 2 + [self.rear_damper_nspm] * 2)
        return k, c


@dataclass(frozen=True)
class VehicleParams:
    """Mass, geometry, suspension and tyre of one vehicle (SI units; defaults: a mid-size car).

    The suspension is given either by ride frequency and damping ratio per axle
    (``suspension_from = "frequency"``, the default) or by spring and damper rates
    per corner (``suspension_from = "rates"``); see ``rates()``.
    """

    model: str = param(
        "7dof",
        choices=MODELS,
        help="7dof: body + 4 wheel masses on tyre springs; 3dof: rigid tyres",
    )
    sprung_mass_kg: float = param(
        1400.0, unit="kg", gt=0, le=60_000, help="body mass (a mid-size car, driver and fuel)"
    )
    pitch_inertia_kgm2: float = param(
        2300.0,
        unit="kg m^2",
        gt=0,
        le=1e6,
        help="body pitch inertia about the CG (dynamic index ~0.9)",
    )
    roll_inertia_kgm2: float = param(
        500.0, unit="kg m^2", gt=0, le=1e6, help="body roll inertia about the CG"
    )
    cg_to_front_axle_m: float = param(1.2, unit="m", gt=0, le=5, help="a: CG to front axle")
    cg_to_rear_axle_m: float = param(1.5, unit="m", gt=0, le=8, help="b: CG to rear axle")
    track_m: float = param(1.55, unit="m", gt=0, le=3, help="lateral wheel spacing, both axles")
    suspension_from: str = param(
        "frequency",
        choices=("frequency", "rates"),
        help="derive rates from ride frequencies, or give them",
    )
    front_ride_freq_hz: float = param(
        1.2, unit="Hz", ge=0.5, le=3.0, help="front body (ride) natural frequency; cars 1.0-1.6"
    )
    rear_ride_freq_hz: float = param(
        1.35,
        unit="Hz",
        ge=0.5,
        le=3.0,
        help="rear ride frequency, a bit above the front (flat ride)",
    )
    front_damping_ratio: float = param(0.3, ge=0, le=1.5, help="front ride damping ratio; 0.2-0.4")
    rear_damping_ratio: float = param(0.3, ge=0, le=1.5, help="rear ride damping ratio")
    front_spring_npm: float | None = param(
        None, unit="N/m", gt=0, le=1e7, help="front corner spring rate (rates mode)"
    )
    rear_spring_npm: float | None = param(
        None, unit="N/m", gt=0, le=1e7, help="rear corner spring rate (rates mode)"
    )
    front_damper_nspm: float | None = param(
        None, unit="N s/m", ge=0, le=1e6, help="front corner damper rate (rates mode)"
    )
    rear_damper_nspm: float | None = param(
        None, unit="N s/m", ge=0, le=1e6, help="rear corner damper rate (rates mode)"
    )
    front_unsprung_kg: float = param(
        40.0, unit="kg", gt=0, le=2000, help="wheel, brake, upright per front corner (7dof)"
    )
    rear_unsprung_kg: float = param(
        35.0, unit="kg", gt=0, le=2000, help="unsprung mass per rear corner (7dof)"
    )
    tyre_stiffness_npm: float = param(
        250e3, unit="N/m", gt=0, le=1e8, help="vertical tyre rate (7dof); a car tyre 200-300 kN/m"
    )
    wheel_radius_m: float = param(
        0.31,
        unit="m",
        ge=0,
        le=1.0,
        help="rigid-disc envelope of the road (wheel bridging); 0 = off",
    )
    contact_length_m: float = param(
        0.15, unit="m", ge=0, le=0.5, help="moving average over the contact patch; 0 = off"
    )
    # param() returns dataclasses.field(default_factory=...), which RUF009 cannot see
    shape: VehicleShape = param(  # noqa: RUF009
        default_factory=VehicleShape, help="outer body box; its cg_height_m is the dive lever"
    )

    def validate(self, where: str) -> None:
        """Cross-field checks: axles inside the body, rates given in the chosen mode, tyres."""
        prefix = f"{where}." if where else ""
        s = self.shape
        if self.cg_to_front_axle_m >= s.cg_to_front_m:
            raise ConfigError(
                f"{prefix}cg_to_front_axle_m = {self.cg_to_front_axle_m} m: must be"
                f" < shape.cg_to_front_m = {s.cg_to_front_m} m"
            )
        if self.cg_to_rear_axle_m >= s.cg_to_rear_m:
            raise ConfigError(
                f"{prefix}cg_to_rear_axle_m = {self.cg_to_rear_axle_m} m: must be"
                f" < shape length - cg_to_front = {s.cg_to_rear_m} m"
            )
        if self.track_m >= s.width_m:
            raise ConfigError(
                f"{prefix}track_m = {self.track_m} m: must be < shape.width_m = {s.width_m} m"
            )
        if not 0 < s.cg_height_m < s.height_m:
            raise ConfigError(
                f"{prefix}shape.cg_height_m = {s.cg_height_m} m: must be in (0, shape.height_m)"
            )
        rate_names = (
            "front_spring_npm",
            "rear_spring_npm",
            "front_damper_nspm",
            "rear_damper_nspm",
        )
        for name in rate_names:
            value = getattr(self, name)
            if self.suspension_from == "rates" and value is None:
                raise ConfigError(f"{prefix}{name}: missing (suspension_from = 'rates')")
            if self.suspension_from == "frequency" and value is not None:
                raise ConfigError(
                    f"{prefix}{name}: given, but suspension_from = 'frequency'"
                    " derives it (set suspension_from = 'rates')"
                )
        if self.model == "7dof" and self.suspension_from == "frequency":
            for axle, freq in (
                ("front", self.front_ride_freq_hz),
                ("rear", self.rear_ride_freq_hz),
            ):
                ride = self._corner_mass(axle) * (2 * math.pi * freq) ** 2
                if ride >= 0.5 * self.tyre_stiffness_npm:
                    raise ConfigError(
                        f"{prefix}tyre_stiffness_npm = {self.tyre_stiffness_npm}"
                        f" N/m: too soft for a {freq} Hz {axle} ride"
                    )

    @property
    def wheelbase_m(self) -> float:
        return self.cg_to_front_axle_m + self.cg_to_rear_axle_m

    def _corner_mass(self, axle: str) -> float:
        """Static share of the sprung mass on one corner of ``axle``."""
        a, b, wb = self.cg_to_front_axle_m, self.cg_to_rear_axle_m, self.wheelbase_m
        return 0.5 * self.sprung_mass_kg * (b if axle == "front" else a) / wb

    def rates(self) -> SuspensionRates:
        """Spring and damper rate per corner.

        In frequency mode, with m_c the corner's static share of the sprung mass
        (m b / 2L front, m a / 2L rear) and w = 2 pi f: the ride rate is
        k_ride = m_c w^2; the suspension spring is k_ride itself (3dof) or the
        spring that in series with the tyre gives k_ride, k = k_ride k_t / (k_t - k_ride)
        (7dof); the damper is c = 2 zeta m_c w.
        """
        if self.suspension_from == "rates":
            values = (
                self.front_spring_npm,
                self.rear_spring_npm,
                self.front_damper_nspm,
                self.rear_damper_nspm,
            )
            if any(v is None for v in values):
                raise ConfigError("suspension rates missing (suspension_from = 'rates')")
            kf, kr, cf, cr = (float(v) for v in values)  # type: ignore[arg-type]
            return SuspensionRates(kf, kr, cf, cr)
        out = []
        for axle, freq, zeta in (
            ("front", self.front_ride_freq_hz, self.front_damping_ratio),
            ("rear", self.rear_ride_freq_hz, self.rear_damping_ratio),
        ):
            m_c = self._corner_mass(axle)
            w = 2 * math.pi * freq
            k_ride = m_c * w * w
            k = k_ride
            if self.model == "7dof":
                kt = self.tyre_stiffness_npm
                k = k_ride * kt / (kt - k_ride)
            out.append((k, 2 * zeta * m_c * w))
        return SuspensionRates(out[0][0], out[1][0], out[0][1], out[1][1])


# -- the linear model ------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ModelResponse:
    """States of the model on a time grid: generalised coordinates, velocities, accelerations.

    Columns of ``q``: body heave z (m), pitch theta (rad, nose up), roll rho (rad, left
    up), then (7dof) the four wheel-centre displacements (m, ``CORNERS`` order); all
    world-absolute deviations from the configuration at rest on a level road.
    """

    t: FloatArray
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray


@dataclass(frozen=True)
class _Discrete:
    phi: FloatArray
    g0: FloatArray
    g1: FloatArray
    eigvals_d: NDArray[np.complex128] | None
    modes: NDArray[np.complex128] | None
    modes_inv: NDArray[np.complex128] | None


class VehicleModel:
    """The linear equations ``M q'' + C q' + K q = Kw w + Cw w' + Qa a_x`` of one vehicle.

    ``w`` (4 columns, ``CORNERS`` order) is the (enveloped) road height under each wheel,
    ``a_x`` the longitudinal acceleration; body corner i at (x_i, y_i) from the CG moves by
    z + x_i theta + y_i rho.
    """

    def __init__(self, params: VehicleParams) -> None:
        check_ranges(params, "vehicle")
        params.validate("vehicle")
        self.params = params
        p = params
        a, b, half = p.cg_to_front_axle_m, p.cg_to_rear_axle_m, 0.5 * p.track_m
        self.corner_x: FloatArray = np.array([a, a, -b, -b])
        self.corner_y: FloatArray = np.array([half, -half, half, -half])
        self.rates = p.rates()
        k, c = self.rates.corners()
        # corner displacement = T @ (z, theta, rho)
        t_mat = np.column_stack([np.ones(4), self.corner_x, self.corner_y])
        m_body = np.diag([p.sprung_mass_kg, p.pitch_inertia_kgm2, p.roll_inertia_kgm2])
        qa_body = np.array([0.0, p.sprung_mass_kg * p.shape.cg_height_m, 0.0])
        if p.model == "3dof":
            self.m = m_body
            self.k = t_mat.T @ np.diag(k) @ t_mat
            self.c = t_mat.T @ np.diag(c) @ t_mat
            self.kw = t_mat.T @ np.diag(k)
            self.cw = t_mat.T @ np.diag(c)
            self.qa = qa_body
        else:
            mu = np.array([p.front_unsprung_kg] * 2 + [p.rear_unsprung_kg] * 2)
            kt = np.full(4, p.tyre_stiffness_npm)
            self.m = linalg.block_diag(m_body, np.diag(mu))
            self.k = np.block(
                [
                    [t_mat.T @ np.diag(k) @ t_mat, -t_mat.T @ np.diag(k)],
                    [-np.diag(k) @ t_mat, np.diag(k + kt)],
                ]
            )
            self.c = np.block(
                [
                    [t_mat.T @ np.diag(c) @ t_mat, -t_mat.T @ np.diag(c)],
                    [-np.diag(c) @ t_mat, np.diag(c)],
                ]
            )
            self.kw = np.vstack([np.zeros((3, 4)), np.diag(kt)])
            self.cw = np.zeros((7, 4))
            self.qa = np.concatenate([qa_body, np.zeros(4)])
        self.ndof = self.m.shape[0]
        self._m_inv = np.linalg.inv(self.m)
        nd = self.ndof
        self.a_mat = np.block(
            [[np.zeros((nd, nd)), np.eye(nd)], [-self._m_inv @ self.k, -self._m_inv @ self.c]]
        )
        # inputs u = (w_1..w_4, a_x); B0 acts on u, B1 on du/dt
        self.b0 = np.vstack([np.zeros((nd, 5)), self._m_inv @ np.column_stack([self.kw, self.qa])])
        self.b1 = np.vstack(
            [np.zeros((nd, 5)), self._m_inv @ np.column_stack([self.cw, np.zeros(nd)])]
        )
        self._static_gain = np.linalg.solve(self.k, np.column_stack([self.kw, self.qa]))
        self._discrete: dict[float, _Discrete] = {}

    # -- analysis --------------------------------------------------------------------
    def static_state(self, w: ArrayLike, a_x: ArrayLike = 0.0) -> FloatArray:
        """Static equilibrium q for road heights ``w`` (..., 4) and acceleration ``a_x`` (...)."""
        w_arr = np.asarray(w, dtype=float)
        a_arr = np.broadcast_to(np.asarray(a_x, dtype=float), w_arr.shape[:-1])
        u = np.concatenate([w_arr, a_arr[..., None]], axis=-1)
        return np.asarray(u @ self._static_gain.T)

    def modes(self) -> tuple[FloatArray, FloatArray]:
        """Undamped-equivalent natural frequencies (Hz) and damping ratios of the modes,
        one entry per complex-conjugate pair, sorted by frequency."""
        lam = np.linalg.eigvals(self.a_mat)
        lam = lam[lam.imag >= 0]
        wn = np.abs(lam)
        order = np.argsort(wn)
        return wn[order] / (2 * np.pi), -lam.real[order] / wn[order]

    def energy(self, q: ArrayLike, qd: ArrayLike, w: ArrayLike | None = None) -> FloatArray:
        """Mechanical energy (J) above the static state for road heights ``w`` (default 0):
        kinetic 1/2 q'^T M q' plus spring energy 1/2 dq^T K dq, per row."""
        q_arr = np.atleast_2d(np.asarray(q, dtype=float))
        qd_arr = np.atleast_2d(np.asarray(qd, dtype=float))
        dq = q_arr if w is None else q_arr - self.static_state(np.asarray(w, dtype=float))
        kinetic = 0.5 * np.einsum("ni,ij,nj->n", qd_arr, self.m, qd_arr)
        potential = 0.5 * np.einsum("ni,ij,nj->n", dq, self.k, dq)
        return np.asarray(kinetic + potential)

    # -- time response ---------------------------------------------------------------
    def _discretise(self, dt: float) -> _Discrete:
        cached = self._discrete.get(dt)
        if cached is not None:
            return cached
        ns = self.a_mat.shape[0]
        # Van Loan: expm([[A, I, 0], [0, 0, I], [0, 0, 0]] dt) holds Phi, Gamma0, Gamma2
        big = np.zeros((3 * ns, 3 * ns))
        big[:ns, :ns] = self.a_mat
        big[:ns, ns : 2 * ns] = np.eye(ns)
        big[ns : 2 * ns, 2 * ns :] = np.eye(ns)
        e = linalg.expm(big * dt)
        phi = e[:ns, :ns]
        gamma0 = e[:ns, ns : 2 * ns]
        gamma2 = e[:ns, 2 * ns :]
        g0 = gamma0 @ self.b0
        g1 = (gamma2 @ self.b0 + gamma0 @ self.b1) / dt
        lam, vec = np.linalg.eig(self.a_mat)
        eigvals_d = modes = modes_inv = None
        if np.linalg.cond(vec) < _MODAL_MAX_COND:
            eigvals_d, modes, modes_inv = np.exp(lam * dt), vec, np.linalg.inv(vec)
        out = _Discrete(phi, g0, g1, eigvals_d, modes, modes_inv)
        self._discrete[dt] = out
        return out

    def respond(
        self,
        t: ArrayLike,
        w: ArrayLike,
        a_x: ArrayLike | None = None,
        *,
        q0: ArrayLike | None = None,
        qd0: ArrayLike | None = None,
        method: str = "auto",
    ) -> ModelResponse:
        """Response to road heights ``w`` (n, 4) and acceleration ``a_x`` (n,) on the uniform
        time grid ``t`` (n,); inputs are taken as linear between samples (exact discretisation).

        Starts from ``q0``, ``qd0`` (default: static equilibrium for the first inputs, at rest).
        ``method``: ``"modal"`` (loop-free, one first-order recursion per mode with
        ``scipy.signal.lfilter``), ``"loop"`` (state-space recursion step by step) or
        ``"auto"`` (modal unless the modes are nearly defective).
        """
        t_arr = np.asarray(t, dtype=float)
        w_arr = np.asarray(w, dtype=float)
        n = t_arr.size
        if t_arr.ndim != 1 or n < 2:
            raise InputDataError(f"t: must be a 1-D time grid of >= 2 samples, got {t_arr.shape}")
        if w_arr.shape != (n, 4):
            raise InputDataError(f"w: must have shape ({n}, 4), got {w_arr.shape}")
        steps = np.diff(t_arr)
        dt = float(steps.mean())
        if dt <= 0 or np.abs(steps - dt).max() > 1e-9 * max(1.0, abs(float(t_arr[-1]))):
            raise InputDataError("t: must be uniformly spaced and increasing")
        a_arr = np.zeros(n) if a_x is None else np.asarray(a_x, dtype=float)
        if a_arr.shape != (n,):
            raise InputDataError(f"a_x: must have shape ({n},), got {a_arr.shape}")
        if method not in ("auto", "modal", "loop"):
            raise InputDataError(f"method = {method!r}: must be auto, modal or loop")
        u = np.column_stack([w_arr, a_arr])
        nd = self.ndof
        if q0 is None:
            q_start = self.static_state(w_arr[0], a_arr[0])
        else:
            q_start = np.asarray(q0, dtype=float).reshape(nd)
        qd_start = np.zeros(nd) if qd0 is None else np.asarray(qd0, dtype=float).reshape(nd)
        x0 = np.concatenate([q_start, qd_start])
        disc = self._discretise(round(dt, 15))
        du = np.diff(u, axis=0)
        use_modal = method == "modal" or (method == "auto" and disc.modes is not None)
        if use_modal:
            if disc.modes is None or disc.modes_inv is None or disc.eigvals_d is None:
                raise InputDataError("method = 'modal': the modes are nearly defective; use loop")
            # forcing per step, projected on the modes: V^-1 (G0 u_k + G1 (u_k+1 - u_k))
            gamma = np.zeros((n, x0.size), dtype=complex)
            gamma[:-1] = u[:-1] @ (disc.modes_inv @ disc.g0).T + du @ (disc.modes_inv @ disc.g1).T
            xi0 = disc.modes_inv @ x0
            xi = np.empty(gamma.shape, dtype=complex)
            for i, lam_d in enumerate(disc.eigvals_d):
                xi[:, i] = lfilter([0.0, 1.0], [1.0, -lam_d], gamma[:, i], zi=[xi0[i]])[0]
            x = (xi @ disc.modes.T).real
        else:
            g = u[:-1] @ disc.g0.T + du @ disc.g1.T  # (n-1, ns) forcing per step
            x = np.empty((n, x0.size))
            x[0] = x0
            phi = disc.phi
            for i in range(n - 1):
                x[i + 1] = phi @ x[i] + g[i]
        q, qd = x[:, :nd], x[:, nd:]
        wd = np.gradient(w_arr, t_arr, axis=0)
        forces = (
            -q @ self.k.T
            - qd @ self.c.T
            + w_arr @ self.kw.T
            + wd @ self.cw.T
            + a_arr[:, None] * self.qa[None, :]
        )
        qdd = forces @ self._m_inv.T
        return ModelResponse(t=t_arr, q=q, qd=qd, qdd=qdd)


# -- road input under the wheels ---------------------------------------------------------


def _disc_envelope(h: FloatArray, radius_m: float, ds: float) -> FloatArray:
    """Lowest path of the centre of a rigid disc of ``radius_m`` rolling on profile ``h``
    (sampled every ``ds``), relative to its contact point: max_s h(x+s) - (R - sqrt(R^2-s^2))."""
    half = int(radius_m / ds)
    if half < 1:
        return h
    padded = np.pad(h, half, mode="edge")
    out = h.copy()
    n = h.size
    for j in range(-half, half + 1):
        if j == 0:
            continue
        s = j * ds
        drop = radius_m - math.sqrt(max(0.0, radius_m * radius_m - s * s))
        np.maximum(out, padded[half + j : half + j + n] - drop, out=out)
    return out


def wheel_road_inputs(
    params: VehicleParams, road: Road, x: ArrayLike, lateral_m: float
) -> FloatArray:
    """Road height (m) under each wheel, (n, 4) in ``CORNERS`` order, for CG positions ``x``
    (n,) on the lateral line ``lateral_m``, after the tyre-enveloping filter."""
    x_arr = np.asarray(x, dtype=float)
    a, b, half = params.cg_to_front_axle_m, params.cg_to_rear_axle_m, 0.5 * params.track_m
    offsets = np.array([a, a, -b, -b])
    lines = np.array([lateral_m + half, lateral_m - half, lateral_m + half, lateral_m - half])
    xw = x_arr[:, None] + offsets[None, :]
    radius, patch = params.wheel_radius_m, params.contact_length_m
    if radius <= 0 and patch <= 0:
        return road.height(xw, lines[None, :])
    ds = _ENVELOPE_GRID_M if patch <= 0 else min(_ENVELOPE_GRID_M, patch / 8)
    pad = radius + patch + 4 * ds
    xs = np.arange(float(xw.min()) - pad, float(xw.max()) + pad + ds, ds)
    out = np.empty(xw.shape)
    for side, y in ((0, lateral_m + half), (1, lateral_m - half)):
        h = road.height(xs, y)
        h = _disc_envelope(h, radius, ds)
        if patch > 0:
            size = 2 * round(0.5 * patch / ds) + 1  # odd: centred on the wheel
            h = uniform_filter1d(h, size=size, mode="nearest")
        for corner in (side, side + 2):
            out[:, corner] = np.interp(xw[:, corner], xs, h)
    return out


# -- the motion of one vehicle ------------------------------------------------------------


_SERIES = (
    "t",
    "x",
    "y",
    "z",
    "v",
    "a",
    "pitch",
    "roll",
    "yaw",
    "pitch_rate",
    "roll_rate",
    "yaw_rate",
    "heave",
    "accel_world",
    "wheel_road",
)


@dataclass(frozen=True, eq=False)
class BodyMotion:
    """The body's motion on a time grid (SI; world frame and signs of ``docs/method.md``).

    ``x, y, z``: CG position; ``v, a``: longitudinal speed and acceleration; ``pitch``
    (nose up), ``roll`` (left up), ``yaw``: world-absolute (road grade and crossfall
    included), with their rates; ``heave``: CG height above its static equilibrium on the
    smooth road (hills + crossfall); ``accel_world`` (n, 3): CG acceleration in the world
    frame without gravity; ``wheel_road`` (n, 4): enveloped road height under each wheel.
    """

    t: FloatArray
    x: FloatArray
    y: FloatArray
    z: FloatArray
    v: FloatArray
    a: FloatArray
    pitch: FloatArray
    roll: FloatArray
    yaw: FloatArray
    pitch_rate: FloatArray
    roll_rate: FloatArray
    yaw_rate: FloatArray
    heave: FloatArray
    accel_world: FloatArray
    wheel_road: FloatArray
    params: VehicleParams
    vehicle_id: int = 0
    is_lead: bool = False
    appearance: int = 0

    @property
    def shape(self) -> VehicleShape:
        return self.params.shape

    def __len__(self) -> int:
        return int(self.t.size)

    def sample(self, times: ArrayLike) -> BodyMotion:
        """The motion linearly interpolated onto ``times`` (within the simulated span)."""
        tq = np.atleast_1d(np.asarray(times, dtype=float))
        t0, t1 = float(self.t[0]), float(self.t[-1])
        tol = 1e-9 * max(1.0, abs(t1))
        if tq.size and (tq.min() < t0 - tol or tq.max() > t1 + tol):
            raise InputDataError(
                f"times: must lie within the simulated [{t0}, {t1}] s, got [{tq.min()}, {tq.max()}]"
            )
        tc = np.clip(tq, t0, t1)
        pos = np.interp(tc, self.t, np.arange(self.t.size, dtype=float))
        i0 = np.minimum(pos.astype(np.intp), self.t.size - 2)
        frac = pos - i0
        values: dict[str, FloatArray] = {}
        for name in _SERIES:
            arr = getattr(self, name)
            f = frac.reshape((-1,) + (1,) * (arr.ndim - 1))
            values[name] = arr[i0] * (1 - f) + arr[i0 + 1] * f
        values["t"] = tq
        return BodyMotion(
            **values,
            params=self.params,
            vehicle_id=self.vehicle_id,
            is_lead=self.is_lead,
            appearance=self.appearance,
        )

    def pose_at(self, t: float) -> VehiclePose:
        """The CG pose at time ``t`` (interpolated)."""
        s = self.sample([t])
        return VehiclePose(
            vehicle_id=self.vehicle_id,
            x_m=float(s.x[0]),
            y_m=float(s.y[0]),
            z_m=float(s.z[0]),
            pitch_rad=float(s.pitch[0]),
            roll_rad=float(s.roll[0]),
            yaw_rad=float(s.yaw[0]),
            shape=self.shape,
            appearance=self.appearance,
            is_lead=self.is_lead,
        )

    def points_world(self, times: ArrayLike, offsets_body: ArrayLike) -> FloatArray:
        """World positions (n, k, 3) at ``times`` (n,) of body-fixed points ``offsets_body``
        (k, 3), given from the CG in the body frame (x forward, y left, z up)."""
        off = np.asarray(offsets_body, dtype=float).reshape(-1, 3)
        s = self.sample(times)
        rot = body_to_world(s.pitch, s.roll, s.yaw)
        centre = np.column_stack([s.x, s.y, s.z])
        return np.asarray(centre[:, None, :] + np.einsum("nij,kj->nki", rot, off))

    def point_world(self, t: float, offsets_body: ArrayLike) -> FloatArray:
        """World positions (k, 3) at time ``t`` of body-fixed points (k, 3) from the CG."""
        out: FloatArray = self.points_world([t], offsets_body)[0]
        return out


def simulate_vehicle(
    params: VehicleParams,
    road: Road,
    t: ArrayLike,
    x: ArrayLike,
    v: ArrayLike,
    a: ArrayLike,
    lateral_m: float,
    *,
    vehicle_id: int = 0,
    is_lead: bool = False,
    appearance: int = 0,
    method: str = "auto",
) -> BodyMotion:
    """Vertical motion of a vehicle whose CG follows X = ``x`` (n,) with speed ``v`` and
    acceleration ``a`` along the lateral line Y = ``lateral_m``, on the uniform grid ``t``.

    The vehicle starts in static equilibrium for the road under it and the initial
    acceleration.
    """
    model = VehicleModel(params)
    t_arr = np.asarray(t, dtype=float)
    x_arr = np.asarray(x, dtype=float)
    v_arr = np.asarray(v, dtype=float)
    a_arr = np.asarray(a, dtype=float)
    n = t_arr.size
    for name, arr in (("x", x_arr), ("v", v_arr), ("a", a_arr)):
        if arr.shape != (n,):
            raise InputDataError(f"{name}: must have shape ({n},) like t, got {arr.shape}")
    w = wheel_road_inputs(params, road, x_arr, lateral_m)
    resp = model.respond(t_arr, w, a_arr, method=method)
    q, qd, qdd = resp.q, resp.qd, resp.qdd
    # static equilibrium on the smooth road (no roughness or anomalies), for the heave
    hills_front = road.hills(x_arr + params.cg_to_front_axle_m)
    hills_rear = road.hills(x_arr - params.cg_to_rear_axle_m)
    w_slow = (
        np.column_stack([hills_front, hills_front, hills_rear, hills_rear])
        + road.crossfall(lateral_m + model.corner_y)[None, :]
    )
    z_static = model.static_state(w_slow)[:, 0]
    cg_h = params.shape.cg_height_m
    zeros = np.zeros(n)
    accel = np.column_stack([a_arr, zeros, qdd[:, 0]])
    return BodyMotion(
        t=t_arr,
        x=x_arr,
        y=np.full(n, float(lateral_m)),
        z=cg_h + q[:, 0],
        v=v_arr,
        a=a_arr,
        pitch=q[:, 1].copy(),
        roll=q[:, 2].copy(),
        yaw=zeros.copy(),
        pitch_rate=qd[:, 1].copy(),
        roll_rate=qd[:, 2].copy(),
        yaw_rate=zeros.copy(),
        heave=q[:, 0] - z_static,
        accel_world=accel,
        wheel_road=w,
        params=params,
        vehicle_id=vehicle_id,
        is_lead=is_lead,
        appearance=appearance,
    )


__all__ = [
    "CORNERS",
    "BodyMotion",
    "ModelResponse",
    "SuspensionRates",
    "VehicleModel",
    "VehicleParams",
    "simulate_vehicle",
    "wheel_road_inputs",
]
