"""Synthetic compensated trajectories for the detector tests (helpers, also as fixtures)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pytest

from roadpreview.anomaly import TrajectorySample
from roadpreview.types import FusionMode


def trajectory(
    t: np.ndarray,
    y: np.ndarray,
    *,
    left: np.ndarray | None = None,
    right: np.ndarray | None = None,
    distance_m: float | np.ndarray = 20.0,
    speed_mps: float | None = 15.0,
    lead_accel: np.ndarray | None = None,
    modes: Sequence[FusionMode] | None = None,
    valid: np.ndarray | None = None,
) -> list[TrajectorySample]:
    """TrajectorySamples from arrays (halves default to the whole-lead trajectory)."""
    n = len(t)
    left = y if left is None else left
    right = y if right is None else right
    d = np.broadcast_to(np.asarray(distance_m, dtype=float), (n,))
    return [
        TrajectorySample(
            t=float(t[k]),
            y_c=float(y[k]),
            y_c_left=float(left[k]),
            y_c_right=float(right[k]),
            lead_distance_m=float(d[k]),
            lead_distance_std_m=0.5,
            mode=FusionMode.FUSED if modes is None else modes[k],
            lead_accel_mps2=None if lead_accel is None else float(lead_accel[k]),
            ego_speed_mps=speed_mps,
            valid=True if valid is None else bool(valid[k]),
        )
        for k in range(n)
    ]


def raised_cosine_bump(t: np.ndarray, start: float, duration: float, height: float) -> np.ndarray:
    """0 outside [start, start + duration], a raised-cosine hump of ``height`` inside."""
    phase = (t - start) / duration
    inside = (phase >= 0) & (phase <= 1)
    return np.where(inside, height * 0.5 * (1 - np.cos(2 * np.pi * phase)), 0.0)


@pytest.fixture
def make_trajectory() -> Callable[..., list[TrajectorySample]]:
    """`trajectory` (fixtures: test modules cannot import conftest with importlib mode)."""
    return trajectory


@pytest.fixture
def bump() -> Callable[[np.ndarray, float, float, float], np.ndarray]:
    """`raised_cosine_bump`."""
    return raised_cosine_bump
