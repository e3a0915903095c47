"""Epipolar geometry of a forward-moving, rotating camera (vectorised).

The paper's model (eq. 2): ``F(φ) = -K^{-T} [t]_x R(φ) K^{-1}``, with t the
calibrated forward direction and R(φ) the pitch rotation of ``docs/method.md``.
The rotation may be extended with yaw and roll for curves:
``R = R_z(roll) R_y(yaw) R_x(φ)``.

Everything here works on normalised coordinates ``n = K^{-1} p`` and uses the
fact that ``K^{-T}`` only rescales the first two components of a line, so the
Sampson error comes out in pixels without forming F explicitly.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def skew(v: ArrayLike) -> Array:
    """The cross-product matrix ``[v]_x`` with ``[v]_x w = v x w``."""
    x, y, z = np.asarray(v, dtype=np.float64).ravel()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rot_pitch(phi: float) -> Array:
    """R(φ): un-pitched camera frame -> camera pitched nose up by φ."""
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def _d_rot_pitch(phi: float) -> Array:
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[0.0, 0.0, 0.0], [0.0, -s, c], [0.0, -c, -s]])


def rot_yaw(psi: float) -> Array:
    """Camera turning left by ψ (rotation about the camera's vertical axis)."""
    c, s = np.cos(psi), np.sin(psi)
    # turning left moves image content to the right: R @ (0,0,1) = (sin ψ, 0, cos ψ)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _d_rot_yaw(psi: float) -> Array:
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[-s, 0.0, c], [0.0, 0.0, 0.0], [-c, 0.0, -s]])


def rot_roll(rho: float) -> Array:
    """Camera rolling left side up by ρ (rotation about the optical axis)."""
    c, s = np.cos(rho), np.sin(rho)
    # left side up: a point to the right of centre moves up in the image (y decreases)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def _d_rot_roll(rho: float) -> Array:
    c, s = np.cos(rho), np.sin(rho)
    return np.array([[-s, c, 0.0], [-c, -s, 0.0], [0.0, 0.0, 0.0]])


def rotation(params: ArrayLike) -> Array:
    """R from ``(φ,)``, ``(φ, ψ)`` or ``(φ, ψ, ρ)``: ``R_z(ρ) R_y(ψ) R_x(φ)``."""
    p = np.asarray(params, dtype=np.float64).ravel()
    R = rot_pitch(p[0])
    if p.size > 1:
        R = rot_yaw(p[1]) @ R
    if p.size > 2:
        R = rot_roll(p[2]) @ R
    return R


def rotation_and_jacobian(params: ArrayLike) -> tuple[Array, list[Array]]:
    """R and its partial derivatives with respect to each parameter."""
    p = np.asarray(params, dtype=np.float64).ravel()
    Rx, dRx = rot_pitch(p[0]), _d_rot_pitch(p[0])
    Ry = np.eye(3) if p.size < 2 else rot_yaw(p[1])
    Rz = np.eye(3) if p.size < 3 else rot_roll(p[2])
    R = Rz @ Ry @ Rx
    d = [Rz @ Ry @ dRx]
    if p.size > 1:
        d.append(Rz @ _d_rot_yaw(p[1]) @ Rx)
    if p.size > 2:
        d.append(_d_rot_roll(p[2]) @ Ry @ Rx)
    return R, d


def essential(params: ArrayLike, t: ArrayLike) -> Array:
    """``E = -[t]_x R``: the essential matrix of forward motion along t with rotation R."""
    return -skew(t) @ rotation(params)


def fundamental(params: ArrayLike, K: ArrayLike, t: ArrayLike) -> Array:
    """``F = -K^{-T} [t]_x R K^{-1}`` (paper eq. 2), for ``x_cur^T F x_ref = 0``."""
    Ki = np.linalg.inv(np.asarray(K, dtype=np.float64))
    return Ki.T @ essential(params, t) @ Ki


def normalise(pixels: Array, K: ArrayLike) -> Array:
    """(N, 2) pixels -> (N, 3) normalised homogeneous coordinates ``K^{-1} p``."""
    Km = np.asarray(K, dtype=np.float64)
    n = np.empty((pixels.shape[0], 3))
    # general K (skew allowed): solve the upper-triangular system in closed form
    fx, s, cx = Km[0, 0], Km[0, 1], Km[0, 2]
    fy, cy = Km[1, 1], Km[1, 2]
    n[:, 1] = (pixels[:, 1] - cy) / fy
    n[:, 0] = (pixels[:, 0] - cx - s * n[:, 1]) / fx
    n[:, 2] = 1.0
    return n


def sampson_terms(
    E: Array, n_ref: Array, n_cur: Array, fx: float, fy: float
) -> tuple[Array, Array, Array, Array]:
    """Pieces of the Sampson error for ``F = K^{-T} E K^{-1}``.

    Returns ``r = n_cur^T E n_ref`` (the algebraic residual) and the pixel-scaled
    line components ``(E n_ref)_{1,2} / (fx, fy)`` and ``(E^T n_cur)_{1,2} / (fx, fy)``
    stacked as a (N, 2) pair each, plus the denominator ``D`` (their squared sum).
    Only valid when K has no skew (the usual case; `normalise` handles skew for
    the coordinates themselves).
    """
    l_cur = n_ref @ E.T  # E n_ref, (N, 3): epipolar lines in the current image
    l_ref = n_cur @ E  # E^T n_cur: lines in the reference image
    r = np.einsum("ij,ij->i", n_cur, l_cur)
    a = l_cur[:, :2] / (fx, fy)
    b = l_ref[:, :2] / (fx, fy)
    D = np.einsum("ij,ij->i", a, a) + np.einsum("ij,ij->i", b, b)
    return r, a, b, D


def sampson_distance(
    params: ArrayLike, x_ref: Array, x_cur: Array, K: ArrayLike, t: ArrayLike
) -> Array:
    """Signed Sampson distance (pixels) of each correspondence; its square is the
    Sampson error of paper eq. 3."""
    Km = np.asarray(K, dtype=np.float64)
    E = essential(params, t)
    r, _, _, D = sampson_terms(E, normalise(x_ref, Km), normalise(x_cur, Km), Km[0, 0], Km[1, 1])
    return r / np.sqrt(D)


def sampson_error(
    params: ArrayLike, x_ref: Array, x_cur: Array, K: ArrayLike, t: ArrayLike
) -> Array:
    """Sampson error ``e_i(φ)`` in pixels² (paper eq. 3)."""
    return sampson_distance(params, x_ref, x_cur, K, t) ** 2


def sampson_distance_and_jacobian(
    params: ArrayLike, n_ref: Array, n_cur: Array, t: Array, fx: float, fy: float
) -> tuple[Array, Array]:
    """Signed Sampson distance g (N,) and its analytic Jacobian dg/dparams (N, k).

    ``g = r / sqrt(D)``, so ``g' = r'/sqrt(D) - r D' / (2 D^{3/2})`` with
    ``r' = n_cur^T E' n_ref``, ``D' = 2 (a·a' + b·b')`` and ``E' = -[t]_x R'``.
    """
    R, dR = rotation_and_jacobian(params)
    T = -skew(t)
    E = T @ R
    r, a, b, D = sampson_terms(E, n_ref, n_cur, fx, fy)
    sqrt_D = np.sqrt(D)
    g = r / sqrt_D
    J = np.empty((g.size, len(dR)))
    for k, dRk in enumerate(dR):  # k <= 3 parameters, not a loop over points
        dE = T @ dRk
        dl_cur = n_ref @ dE.T
        dl_ref = n_cur @ dE
        dr = np.einsum("ij,ij->i", n_cur, dl_cur)
        da = dl_cur[:, :2] / (fx, fy)
        db = dl_ref[:, :2] / (fx, fy)
        dD = 2.0 * (np.einsum("ij,ij->i", a, da) + np.einsum("ij,ij->i", b, db))
        J[:, k] = dr / sqrt_D - 0.5 * r * dD / (D * sqrt_D)
    return g, J


def sampson_error_derivative(
    params: ArrayLike, x_ref: Array, x_cur: Array, K: ArrayLike, t: ArrayLike
) -> tuple[Array, Array]:
    """Sampson error e (N,) in px² and de/dparams (N, k), from pixel inputs."""
    Km = np.asarray(K, dtype=np.float64)
    g, J = sampson_distance_and_jacobian(
        params, normalise(x_ref, Km), normalise(x_cur, Km), np.asarray(t, float), Km[0, 0], Km[1, 1]
    )
    return g**2, 2.0 * g[:, None] * J


class PitchOnlySampson:
    """Sampson distance of the pitch-only model as a cheap function of φ.

    With ``R(φ) = A + cos φ B + sin φ C`` every per-point quantity of the
    Sampson distance is a trigonometric polynomial in φ, so after one O(N)
    precomputation each evaluation is two small matrix-vector products::

        r(φ) = P @ [1, c, s]
        D(φ) = Q @ [1, 2c, 2s, c², 2cs, s²]

    (``r`` the algebraic residual, ``D`` the Sampson denominator). This is the
    per-frame hot path of `RobustPitchEstimator` in its default (pitch-only) mode.
    """

    _A = np.diag([1.0, 0.0, 0.0])
    _B = np.diag([0.0, 1.0, 1.0])
    _C = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

    def __init__(self, n_ref: Array, n_cur: Array, t: Array, fx: float, fy: float) -> None:
        T = -skew(t)
        # Work on (3, N) arrays ("structure of arrays"): numpy reduces fast over a
        # leading axis and slowly over a short trailing one.
        ref_T = np.ascontiguousarray(n_ref.T)
        cur_T = np.ascontiguousarray(n_cur.T)
        mats = (self._A, self._B, self._C)
        # lines in the current image: E n_ref = T(A + cB + sC) n_ref -> u (3 terms, 3, N)
        u = (np.concatenate([T @ M for M in mats], axis=0) @ ref_T).reshape(3, 3, -1)
        # lines in the reference image: E^T n_cur = (A + cB + sC)^T (T^T n_cur)
        v = (np.concatenate([M.T @ T.T for M in mats], axis=0) @ cur_T).reshape(3, 3, -1)
        self.P: Array = (u * cur_T[None]).sum(axis=1)  # (3, N): r = [1, c, s] @ P
        scale = np.array([1.0 / fx, 1.0 / fy])[None, :, None]
        ab = np.concatenate([u[:, :2] * scale, v[:, :2] * scale], axis=1)  # (3, 4, N)
        # the six distinct entries of the Gram matrix of the three line terms: (6, N)
        q = np.einsum("ikn,jkn->ijn", ab, ab)
        self.Q: Array = np.stack([q[0, 0], q[0, 1], q[0, 2], q[1, 1], q[1, 2], q[2, 2]])
        # rows: value and derivative with respect to φ; filled in by _bases
        self._mp = np.zeros((2, 3))
        self._mq = np.zeros((2, 6))
        self._mp[0, 0] = self._mq[0, 0] = 1.0

    def _bases(self, phi: float) -> tuple[Array, Array]:
        c, s = math.cos(phi), math.sin(phi)
        mp, mq = self._mp, self._mq
        mp[0, 1], mp[0, 2], mp[1, 1], mp[1, 2] = c, s, -s, c
        mq[0, 1:] = (2.0 * c, 2.0 * s, c * c, 2.0 * c * s, s * s)
        mq[1, 1:] = (-2.0 * s, 2.0 * c, -2.0 * c * s, 2.0 * (c * c - s * s), 2.0 * s * c)
        return mp, mq

    def __call__(self, phi: float) -> tuple[Array, Array]:
        """Signed Sampson distance g (N,) and dg/dφ (N,) at φ."""
        mp, mq = self._bases(phi)
        r, dr = mp @ self.P
        D, dD = mq @ self.Q
        inv_sqrt_D = 1.0 / np.sqrt(D)
        g = r * inv_sqrt_D
        dg = (dr - 0.5 * g * dD * inv_sqrt_D) * inv_sqrt_D
        return g, dg

    def distance(self, phi: float) -> Array:
        """Only g (for trial steps)."""
        mp, mq = self._bases(phi)
        p0: Array = mp[0]  # (an integer index is untyped in numpy's stubs)
        q0: Array = mq[0]
        return (p0 @ self.P) / np.sqrt(q0 @ self.Q)
