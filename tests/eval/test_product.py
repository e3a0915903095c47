"""The product-level figures of E6 that are plain functions of a trace."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from roadpreview.anomaly import DETECTORS, AnomalyConfig
from roadpreview.eval.detectors import THRESHOLD_FIELDS, at_threshold
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


def test_an_operating_point_sets_only_the_detectors_threshold() -> None:
    """`at_threshold` turns the field `THRESHOLD_FIELDS` names, for every registered
    detector, and leaves the rest of the configuration as it was."""
    assert set(THRESHOLD_FIELDS) == set(DETECTORS)
    base = AnomalyConfig()
    for detector, (_, _, table_name) in DETECTORS.items():
        cfg = at_threshold(base, detector, 7.25)
        table = getattr(cfg, table_name)
        assert getattr(table, THRESHOLD_FIELDS[detector]) == 7.25
        assert replace(table, **{THRESHOLD_FIELDS[detector]: 0.0}) == replace(
            getattr(base, table_name), **{THRESHOLD_FIELDS[detector]: 0.0}
        )
        assert replace(cfg, **{table_name: getattr(base, table_name)}) == base
