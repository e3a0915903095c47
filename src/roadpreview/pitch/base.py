"""The pitch-estimator interface and its result type.

A pitch estimator takes N background correspondences between a reference
(key) frame and the current frame, in pixels, and returns the camera's
rotation between the two frames: the pitch φ (positive = nose up, see
``docs/method.md``), optionally yaw and roll. A fit that fails for a normal
reason (too few points, degenerate geometry, no convergence, poor fit) is a
*falsy* `PitchEstimate` carrying the reason; it is not an exception.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview.errors import InputDataError


class PitchInDegrees:
    """``phi_deg`` and ``std_deg`` of a result with a pitch ``phi`` and its ``std`` (rad).

    Shared by `PitchEstimate` and `roadpreview.fusion.FusedPitch`; slot-free, so a
    slotted dataclass that inherits it stays without a ``__dict__``.
    """

    __slots__ = ()

    phi: float
    std: float

    @property
    def phi_deg(self) -> float:
        """The pitch in degrees (for display and reports)."""
        return math.degrees(self.phi)

    @property
    def std_deg(self) -> float:
        return math.degrees(self.std)


@dataclass(frozen=True)
class PitchEstimate(PitchInDegrees):
    """Result of one pitch fit.

    ``phi`` is the pitch of the current frame relative to the reference frame
    in radians (nose up positive); NaN when the fit failed. ``std`` is its
    standard deviation (rad) from the curvature of the cost. A result is truthy
    only when the fit succeeded; ``reason`` says why it did not.
    """

    phi: float
    std: float
    inlier_ratio: float
    iterations: int
    converged: bool
    n_points: int
    reason: str = ""
    yaw: float = 0.0
    roll: float = 0.0
    cost: float = math.nan
    #: rows dropped before the fit because a coordinate was NaN or infinite
    n_invalid: int = 0

    def __bool__(self) -> bool:
        return self.converged and not self.reason and math.isfinite(self.phi)

    @classmethod
    def failed(
        cls, reason: str, *, n_points: int = 0, iterations: int = 0, n_invalid: int = 0
    ) -> PitchEstimate:
        """A falsy result that says why the fit failed."""
        return cls(
            phi=math.nan,
            std=math.inf,
            inlier_ratio=0.0,
            iterations=iterations,
            converged=False,
            n_points=n_points,
            reason=reason,
            n_invalid=n_invalid,
        )


@runtime_checkable
class PitchEstimator(Protocol):
    """Estimates the camera pitch between a reference frame and the current one."""

    #: registry name ("robust", "essential", "none")
    name: str

    def estimate(self, x_ref: ArrayLike, x_cur: ArrayLike) -> PitchEstimate:
        """Fit the rotation from (N, 2) pixel correspondences ``x_ref`` -> ``x_cur``."""
        ...

    def reset(self) -> None:
        """Forget the warm start (new sequence or new reference frame)."""
        ...


def validate_correspondences(
    x_ref: ArrayLike, x_cur: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """Check shapes; drop rows with a non-finite coordinate.

    Returns the two (M, 2) float64 arrays of valid rows and the number of rows
    dropped. Raises `InputDataError` (a `ValueError`) naming the array when a
    shape is wrong.
    """
    a = np.asarray(x_ref, dtype=np.float64)
    b = np.asarray(x_cur, dtype=np.float64)
    for name, arr in (("x_ref", a), ("x_cur", b)):
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise InputDataError(
                f"{name}: correspondences must be an (N, 2) array of pixel coordinates, "
                f"got shape {arr.shape}"
            )
    if a.shape != b.shape:
        raise InputDataError(
            f"x_ref and x_cur must have the same shape, got {a.shape} and {b.shape}"
        )
    if np.isfinite(a).all() and np.isfinite(b).all():  # the usual case: nothing to drop
        return a, b, 0
    finite = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    n_invalid = int(a.shape[0] - np.count_nonzero(finite))
    if n_invalid:
        a = a[finite]
        b = b[finite]
    return a, b, n_invalid


def too_few(n: int, minimum: int, n_invalid: int) -> PitchEstimate | None:
    """The falsy result for fewer than ``minimum`` valid pairs, else None."""
    if n >= minimum:
        return None
    return PitchEstimate.failed(
        f"too few correspondences: {n} valid < {minimum}", n_points=n, n_invalid=n_invalid
    )


def poor_fit_reason(inlier_ratio: float, minimum: float) -> str:
    """The reason of a fit whose inlier ratio is below ``minimum`` ("" when it is not)."""
    if inlier_ratio >= minimum:
        return ""
    return f"poor fit: inlier ratio {inlier_ratio:.2f} < {minimum:.2f}"
