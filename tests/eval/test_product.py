"""The product-level figures of E6 that are plain functions of a trace."""

from __future__ import annotations

import numpy as np

from roadpreview.eval.product import mode_changes, mode_changes_after_startup
from roadpreview.types import FusionMode

F, V, IMU, D = (
    int(FusionMode.FUSED),
    int(FusionMode.VISUAL_ONLY),
    int(FusionMode.IMU_ONLY),
    int(FusionMode.DEGRADED),
)


def test_start_up_changes_are_counted_apart() -> None:
    modes = np.array([D, V, V, F, F, IMU, IMU, F, F])
    assert mode_changes(modes) == 4
    assert mode_changes_after_startup(modes) == 2  # F -> I -> F


def test_a_drive_never_fused_has_no_changes_after_start_up() -> None:
    modes = np.array([D, V, D, V])
    assert mode_changes(modes) == 3
    assert mode_changes_after_startup(modes) == 0
    assert mode_changes_after_startup(np.array([], dtype=int)) == 0
