"""`kalman`: gyro-driven Kalman filter with stochastic clones for relative visual pitch.

`GyroPitchKalmanFilter` is the `PitchBackEnd` (a `RewindableBackEnd`: its state is
copied for the frames beyond the gyro); `kalman_fusion` puts it into the
`StreamingPitchFusion` that the registry name ``kalman`` builds.

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
a Kalman update with a per-call R (the estimator's std, inflated for few
inliers, plus the time-offset term), after a Mahalanobis gate on the
innovation.

Clones: each frame the state passes is cloned into the slot of the oldest
clone, except the slot of the current key frame, which stays pinned as long as
measurements refer to it. A measurement whose key frame has no clone (older
than every slot) is turned into an increment against the last frame measured
against the same key.

**filterpy, and where it is bypassed.** The state lives in filterpy's
``KalmanFilter``: ``kf.P`` and ``kf.x`` are numpy views of one flat buffer
``[P | x]`` (n rows of n + 1, an ``array('d')``), updated in place, so a reader
or a test sees and may write the filter as usual. Its generic ``predict`` and
``update`` are not called per frame, because the whole per-frame budget of the
issue's benchmark (100k IMU samples/s at 100 Hz IMU and 30 Hz camera: 33 µs
per frame for everything, gyro buffering, alignment and modes included) is
less than filterpy's ``update`` alone (25-30 µs in CPython: argument checks,
copies of x and P, a deepcopy of z, seven dense 6x6 products for a scalar
measurement). Both are written out for the structure of the problem, without
allocating arrays. Measured when the back end was split out of the fusion (10k
frames of prediction, clone and one update, best of 3): 6.8 µs per frame here,
29.7 µs through ``KalmanFilter.predict`` and ``update``; the whole ``kalman``
fusion on the 20 s bench drive ran at 166k IMU samples/s, and at 29k calling
filterpy (below the 100k target), with outputs equal to 5e-16.
``test_frame_sequence_equals_filterpy`` runs both on a random sequence of frames
and keeps x and P within 1e-12 (relative) of filterpy's after every call:

* prediction, ``F = I - ΔM e0 e1ᵀ``: only row and column 0 and the (phi, b)
  block change, a dozen scalars (``test_prediction_equals_filterpy_predict_at_imu_rate``);
  single entries are read and written through a memoryview of the
  ``array('d')``, at a third of the cost of numpy's item access. Per frame the
  prediction and the clone of the new frame are one pass (`step`: the new
  row 0 is written to the clone's row and column as it is computed), which is
  filterpy's ``predict`` with ``F`` and ``Q`` premultiplied by the clone's copy
  matrix;
* update, scalar z and ``h = e0 - e_j``, in Joseph form as the issue asks:
  ``u = P hᵀ``, ``S = h u + R``, ``K = u S⁻¹`` as filterpy forms them, and
  ``(I - K h) P (I - K h)ᵀ + K R Kᵀ`` expanded for the rank-one h as
  ``P + K wᵀ + w Kᵀ`` with ``w = (S/2) K - u``. This is the same polynomial
  in K as Joseph's (hence its insensitivity to an error in K, unlike
  ``P - K S Kᵀ``) and symmetric by construction. ``B = [[w, y], [K, 0]]`` and
  the product of ``[K; w]`` (as columns) with it gives ``[K wᵀ | K y]`` and
  ``[w Kᵀ | 0]``, their sum the change of ``[P | x]`` (exactly symmetric),
  one add updates P and x together: eight small numpy calls, no allocation.
  (The outer product is an element-wise product of two gathers from B, one
  ``take``: numpy's broadcasting machinery costs three plain calls here.)
  ``test_lean_update_equals_filterpy_update`` checks it against
  ``KalmanFilter.update`` on random states (x, P and K to 1e-12 relative).

Other filterpy attributes written by its ``update`` (``K``, ``y``, ``S``,
``x_post``, ...) are not maintained; ``kf.x`` and ``kf.P`` are the state. A
caller that assigns new arrays to them is noticed at the next step and copied
into new storage.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable
from typing import NamedTuple, Protocol, cast, overload

import numpy as np
from filterpy.kalman import KalmanFilter
from numpy.typing import NDArray

from roadpreview.fusion.base import BackEndEstimate, VisualPitch
from roadpreview.fusion.config import KalmanConfig
from roadpreview.fusion.gyro import RejectCounter
from roadpreview.fusion.streaming import StreamingPitchFusion

Array = NDArray[np.float64]


class _Doubles(Protocol):
    """A memoryview of float64 as it behaves (typeshed types memoryview items as int):
    single entries (a 0-d view by ``()``) are floats, slices are views."""

    @overload
    def __getitem__(self, key: int | tuple[()]) -> float: ...
    @overload
    def __getitem__(self, key: slice) -> _Doubles: ...
    @overload
    def __setitem__(self, key: int | tuple[()], value: float) -> None: ...
    @overload
    def __setitem__(self, key: slice, value: _Doubles) -> None: ...


def _doubles(view: memoryview[int] | memoryview[float]) -> _Doubles:
    """``view`` (format ``d``) typed as what it holds."""
    return cast(_Doubles, view)


class _FilterState(Protocol):
    """What this back end uses of filterpy's (untyped) ``KalmanFilter``."""

    dim_x: int
    x: Array
    P: Array
    inv: Callable[[Array], Array]


#: the work buffers of `GyroPitchKalmanFilter._update` (`_make_buffers`)
_UpdateBuffers = tuple[
    Array, Array, Array, Array, Array, _Doubles, _Doubles, Array,
    NDArray[np.intp], Array, Array, Array, Array, Array, Array, Array,
]  # fmt: skip


def _inv_1x1(s: Array) -> Array:
    """Inverse of the 1x1 innovation covariance (filterpy's ``inv`` hook)."""
    return 1.0 / s


def kalman_fusion(config: KalmanConfig | None = None) -> StreamingPitchFusion:
    """The ``kalman`` fusion: `GyroPitchKalmanFilter` in a `StreamingPitchFusion`."""
    config = config or KalmanConfig()
    return StreamingPitchFusion(GyroPitchKalmanFilter(config), config)


class _Snapshot(NamedTuple):
    """A copy of the filter's state (`GyroPitchKalmanFilter.snapshot`)."""

    st: array[float]
    slots: list[float]
    pinned: float
    last_by_key: dict[float, tuple[float, float, float]]
    shift: float
    t: float


class GyroPitchKalmanFilter:
    """Pitch and gyro bias from gyro prediction and relative visual pitch (filterpy's
    ``KalmanFilter`` holds the state); a `RewindableBackEnd`."""

    name = "kalman"
    gate_with_gyro = False  # the Mahalanobis gate of `update` tests every measurement

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.config = config or KalmanConfig()
        self.events = RejectCounter(f"fusion[{self.name}]")
        self.max_rejections = self.config.max_consecutive_rejections
        self._q_bias = self.config.gyro.bias_random_walk**2
        n = 2 + self.config.n_clones
        self._n = n
        self.kf: _FilterState = KalmanFilter(dim_x=n, dim_z=1)
        self.kf.inv = _inv_1x1  # for a caller of kf.update: the 1x1 S needs no matrix inverse
        self._make_buffers()
        self._gate2 = self.config.gate_sigma**2
        self._reset()

    def _make_buffers(self) -> None:
        """Work buffers of the update and their views, made once (no allocation per frame)."""
        n = self._n
        # (i, flat index of P[i, 0], of P[1, i]) for the rows below the bias: `step`
        self._below = [(i, i * (n + 1), n + 1 + i) for i in range(2, n)]
        self._s0 = np.empty(())  # a scalar operand (a Python float costs a conversion per call)
        self._u = np.empty(n + 1)  # [P hᵀ, x0 - xj]
        self._un = self._u[:n]
        # B = [[w, y], [K, 0]]: the update's vectors. With A = [K; w] as columns, one product
        # gives MM[0] = [K wᵀ | K y] and MM[1] = [w Kᵀ | 0]; their sum [K wᵀ + w Kᵀ | K y]
        # (exactly symmetric on the left: K_i w_j + w_i K_j) is the whole change of [P | x].
        # The product's operands, A[a, i] repeated along j and B[a, j] along i, are gathered
        # from B by one `take` (indices made here) into same-shape contiguous arrays, so
        # that the product is a plain element-wise one: a broadcast product (A[:, :, None] *
        # B[:, None, :]) goes through numpy's buffered iterator, as costly as three calls
        m = n + 1
        B = np.zeros((2, m))
        self._Bf, self._w, self._K = B.reshape(-1), B[0, :n], B[1, :n]
        i, j = np.indices((n, m))
        # flat indices into B: [K_i; w_i] (rows 1 and 0 of B, by i) and [B[0, j]; B[1, j]]
        self._gather = np.stack((m + i, i, j, m + j)).reshape(-1)
        self._AB = np.empty((2, 2, n, m))  # the two gathered operands
        self._ABf, self._Ag, self._Bg = self._AB.reshape(-1), self._AB[0], self._AB[1]
        self._MM = np.empty((2, n, m))
        self._MM0, self._MM1 = self._MM[0], self._MM[1]
        self._dXP = np.empty((n, n + 1))  # the change of [P | x]
        # single entries through memoryviews (as `_sv`), flat for the change
        self._s0v = _doubles(self._s0.data)
        self._Bv = _doubles(self._Bf.data)
        self._dv = _doubles(self._dXP.data.cast("B").cast("d"))
        # all of them for `_update`, read in one attribute load
        self._ubuf: _UpdateBuffers = (
            self._u,
            self._un,
            self._K,
            self._w,
            self._s0,
            self._s0v,
            self._Bv,
            self._Bf,
            self._gather,
            self._ABf,
            self._Ag,
            self._Bg,
            self._MM,
            self._MM0,
            self._MM1,
            self._dXP,
        )

    _VIEWS = (
        "_s0",
        "_u",
        "_un",
        "_Bf",
        "_w",
        "_K",
        "_gather",
        "_AB",
        "_ABf",
        "_Ag",
        "_Bg",
        "_MM",
        "_MM0",
        "_MM1",
        "_dXP",
        "_s0v",
        "_Bv",
        "_dv",
        "_ubuf",
        "_xp",
        "_Pa",
        "_xa",
        "_rows",
        "_sv",
    )

    def __getstate__(self) -> dict[str, object]:
        """Copies and pickles keep the storage, not the views into it (a copied numpy view
        would no longer share memory with the copied storage); `__setstate__` remakes them."""
        state = self.__dict__.copy()
        for name in self._VIEWS:
            state.pop(name, None)
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._make_buffers()
        self._install(self._st)

    def _install(self, st: array[float]) -> None:
        """Make ``st`` (flat, [P | x] row by row: n rows of n + 1) the storage of filterpy's P
        and x: kf.P and kf.x are numpy views of it, so the state is where filterpy keeps it,
        while Python reads and writes single entries through a memoryview of the array
        (``_sv``) at a third of the cost of numpy's item access (there are some forty per
        frame; the array's own item assignment parses its argument, the memoryview's
        converts the float directly, half the cost)."""
        n = self._n
        xp = np.frombuffer(st, dtype=np.float64).reshape(n, n + 1)
        kf = self.kf
        kf.P, kf.x = xp[:, :n], xp[:, n:]
        self._st, self._xp, self._Pa, self._xa = st, xp, kf.P, kf.x
        self._sv = _doubles(memoryview(st))
        self._rows = [xp[i] for i in range(n)]  # [P[i, :], x[i]]

    def _bind(self) -> None:
        """kf.P or kf.x was replaced by a caller (only this class does it otherwise): copy
        them into new storage. The calls that begin a step (`step`, the outputs, the
        snapshot) check for it."""
        n = self._n
        xp = np.empty((n, n + 1))
        xp[:, :n] = self.kf.P
        xp[:, n] = np.reshape(self.kf.x, n)
        self._install(array("d", xp.tobytes()))

    # -- PitchBackEnd -----------------------------------------------------------------------
    def _reset(self) -> None:
        n = self._n
        self._install(array("d", bytes(8 * n * (n + 1))))
        self._t = -math.inf  # time of the state (the last frame stepped to)
        self._slots: list[float] = [-math.inf] * self.config.n_clones
        # the slots, oldest clone first, and the list of slots that order is for (`_clone_slot`)
        self._age: list[int] = list(range(self.config.n_clones))
        self._age_of: list[float] | None = self._slots
        self._pinned = math.nan
        self._shift = 0.0  # movement of the pinned key's clone (level change)
        # per key frame: (last frame measured against it, its dphi, its variance)
        self._last_by_key: dict[float, tuple[float, float, float]] = {}

    def start(self, t0: float) -> None:
        """phi = 0 at the first frame ``t0`` (cloned), the configured bias prior."""
        self._reset()
        g = self.config.gyro
        self.kf.x[1, 0] = g.initial_bias_rad_s
        self.kf.P[1, 1] = g.bias_prior_std_rad_s**2
        self._t = t0
        self._clone(t0)

    def step(self, t: float, dG: float, dV: float, dM: float) -> None:
        """Predict to frame ``t`` and clone phi there, in one pass: x <- F x + B u,
        P <- F P F' + Q with F = I - ΔM e0 e1', u = ΔG and Q the white rate noise ΔV plus
        the bias walk q_b [[ΔM³/3, -ΔM²/2], [-ΔM²/2, Δt]] (filterpy's predict written out
        for the structure of F: row and column 0 and the (phi, b) block; P is exactly
        symmetric, so column 0 is row 0); the predicted row 0 goes to the new clone's row
        and column 0 to its column as they are computed."""
        kf = self.kf
        if kf.P is not self._Pa or kf.x is not self._xa:
            self._bind()
        j = 2 + self._clone_slot(t)
        st, n = self._sv, self._n
        m = n + 1  # P[i, j] = st[i m + j], x[i] = st[i m + n]
        st[n] = st[n] + (dG - dM * st[m + n])  # phi += ΔG - ΔM b
        qb = self._q_bias
        if dM != 0.0:
            p10 = st[1]  # (P[1, 0], P being symmetric)
            p01 = p10 - dM * st[m + 1]
            p00 = ((st[0] - dM * p10) - dM * p01) + (dV + qb * dM * dM * dM / 3.0)
            p01 = p01 - qb * dM * dM / 2.0
            for i, im, i1 in self._below:  # P[0, i] -= ΔM P[1, i]; P[i, 0] and P[i, j] the same
                v = st[i] - dM * st[i1]
                st[i] = v
                st[im] = v
                st[im + j] = v
        else:
            p00 = st[0] + (dV + qb * dM * dM * dM / 3.0)
            p01 = st[1] - qb * dM * dM / 2.0
            for _, im, _ in self._below:  # P[i, j] = P[i, 0]
                st[im + j] = st[im]
        st[0] = p00
        st[j] = p00
        st[1] = p01
        st[m] = p01
        st[m + j] = p01
        st[j * m : j * m + m] = st[0:m]  # row j = row 0 (so P[j, j] = P[0, j] = P[0, 0]), x_j = x_0
        st[m + 1] = st[m + 1] + qb * (t - self._t)
        self._t = t

    def _clone_slot(self, t: float) -> int:
        """The slot of the clone of frame ``t``: the oldest, except the pinned key frame's.

        ``_age`` lists the slots oldest first, as ``sorted(range(k), key=slots)`` would (ties,
        the initial -inf, by index): frames come in time order, so the slot written last is
        the newest, and the victim is the first entry, or the second when the first is the
        pinned key's (the usual case), without a `min` and a `sort` per frame. It is sorted
        again when ``_slots`` has been replaced (a snapshot put back, a test) or ``t`` is not
        newer than every clone."""
        slots, age = self._slots, self._age
        if self._age_of is not slots or not t > slots[age[-1]]:
            age[:] = sorted(range(len(slots)), key=slots.__getitem__)
            # (``t`` not the newest: after it is written the list is out of order, redo it)
            self._age_of = slots if t > slots[age[-1]] else None
        # (slot times are distinct but for the initial -inf, and the pinned key is finite)
        victim = age.pop(1 if slots[age[0]] == self._pinned else 0)
        age.append(victim)
        slots[victim] = t
        return victim

    def _clone(self, t: float) -> None:
        """Clone the current phi (frame ``t``) into a slot."""
        j = 2 + self._clone_slot(t)
        st, n = self._sv, self._n
        m = n + 1
        st[j * m : j * m + m] = st[0:m]  # P[j, :] = P[0, :] and x[j] = x[0]
        for i in range(0, n * m, m):  # P[:, j] = P[:, 0], so P[j, j] = P[0, 0]
            st[i + j] = st[i]

    def pin_key(self, t_ref: float) -> None:
        if t_ref != self._pinned and t_ref in self._slots:  # (a pinned key keeps its slot)
            self._pinned = t_ref

    def update(self, meas: VisualPitch, var: float) -> bool:
        """Gate, then the Joseph-form update against the key frame's clone (`_update`)."""
        t_ref, dphi = meas.t_ref, meas.dphi
        z, R = dphi, var
        slots = self._slots
        try:
            slot = slots.index(t_ref)
        except ValueError:
            prev = self._last_by_key.get(t_ref)
            if prev is None or prev[0] not in slots:
                self.events(
                    "no-key",
                    "key frame t_ref=%.6f of the measurement at t=%.6f has no clone and no"
                    " earlier measurement: skipped",
                    t_ref,
                    meas.t,
                )
                return True  # not an outlier: nothing to test it against
            self.events(
                "key-increment", "key frame t_ref=%.6f has no clone: increments used", t_ref
            )
            slot = slots.index(prev[0])
            z, R = dphi - prev[1], var + prev[2]
            self._pinned = prev[0]
        last = self._last_by_key
        last[t_ref] = (meas.t, dphi, var)
        if len(last) > 8:
            del last[min(last)]
        j = 2 + slot
        st, n = self._sv, self._n
        jm = j * (n + 1)
        y = z - (st[n] - st[jm + n])
        p00, p0j, pjj = st[0], st[j], st[jm + j]
        s = p00 + pjj - 2.0 * p0j + R
        if s < R:  # max(s, R)
            s = R
        if y * y > self._gate2 * s:
            self.events(
                "gated",
                "visual measurement at t=%.6f gated (%.1f sigma)",
                meas.t,
                abs(y) / math.sqrt(s),
            )
            return False
        # (the update's S as `_update` forms it, P[j, 0] being P[0, j])
        self._update(j, y, R, (p00 - p0j) - (p0j - pjj) + R)
        pinned = self._pinned  # how far the key frame's estimate moved: its row's K y
        if pinned == slots[slot]:  # (the key measured against, as a rule)
            self._shift += self._dv[jm + n]
        elif pinned in slots:
            self._shift += self._dv[(2 + slots.index(pinned)) * (n + 1) + n]
        return True

    def _update(self, j: int, y: float, R: float, S: float | None = None) -> Array:
        """Joseph-form update with the scalar innovation ``y`` of ``h = e0 - e_j`` and
        variance ``R`` (filterpy's ``update`` for this h, module docstring):
        ``P += K wᵀ + w Kᵀ`` with ``w = (S/2) K - u``, ``x += K y``, ``u = P hᵀ``,
        ``K = u / S``, ``S = h u + R`` (computed here unless the caller has it). Returns the
        change of [P | x] (its last column is K y)."""
        u, un, K, w, s0, s0v, Bv, Bf, gather, ABf, Ag, Bg, MM, MM0, MM1, dxp = self._ubuf
        n, rows, xp = self._n, self._rows, self._xp
        np.subtract(rows[0], rows[j], u)  # P hᵀ (P symmetric), then x0 - xj
        if S is None:
            st, jm = self._sv, j * (n + 1)
            S = (st[0] - st[jm]) - (st[j] - st[jm + j]) + R  # h P hᵀ + R = u[0] - u[j] + R
        s0v[()] = 1.0 / S
        np.multiply(un, s0, K)  # K = P hᵀ S⁻¹
        s0v[()] = 0.5 * S
        np.multiply(K, s0, w)
        np.subtract(w, un, w)  # w = (S/2) K - P hᵀ
        Bv[n] = y
        Bf.take(gather, None, ABf, "clip")  # ("clip": no index check, they are in range)
        np.multiply(Ag, Bg, MM)  # [K wᵀ | K y] and [w Kᵀ | 0]
        np.add(MM0, MM1, dxp)  # [K wᵀ + w Kᵀ | K y]
        np.add(xp, dxp, xp)  # P += K wᵀ + w Kᵀ, x += K y
        return dxp

    def end_frame(self, t: float) -> None:
        """Nothing to do: every measurement is fused as it comes."""

    def estimate(self) -> BackEndEstimate:
        kf = self.kf
        if kf.P is not self._Pa or kf.x is not self._xa:
            self._bind()
        st, n = self._sv, self._n
        m = n + 1
        return st[n], st[0], st[m + n], st[m + 1]

    def frame_estimate(self, t: float) -> tuple[float, float] | None:
        """None: the fusion rewinds this back end (`snapshot`) instead of extrapolating
        from earlier frames, so it never needs them."""
        return None

    def take_level_shift(self) -> float:
        shift, self._shift = self._shift, 0.0
        return shift

    def snapshot(self) -> object:
        kf = self.kf
        if kf.P is not self._Pa or kf.x is not self._xa:
            self._bind()
        return _Snapshot(
            array("d", self._st),
            list(self._slots),
            self._pinned,
            dict(self._last_by_key),
            self._shift,
            self._t,
        )

    def restore(self, snapshot: object) -> None:
        if not isinstance(snapshot, _Snapshot):
            raise TypeError(f"not a snapshot of {type(self).__name__}: {type(snapshot)}")
        self._st[:] = snapshot.st  # in place: the views stay valid (bound by the snapshot)
        self._slots = snapshot.slots
        self._pinned = snapshot.pinned
        self._last_by_key = snapshot.last_by_key
        self._shift = snapshot.shift
        self._t = snapshot.t
