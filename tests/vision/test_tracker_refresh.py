"""The tracked box takes in matching detections, but not a transient change of size.

A lead pitching over a bump makes the motion finder's box swell by 25-40 % for about a
second; blended in, the width cue read that as the gap closing by 4-5 m, and the lead's
"braking" suppressed the anomaly's own alert (the demo's bump at 18 m).
"""

from __future__ import annotations

import pytest

from roadpreview.camera import CameraModel
from roadpreview.vision.base import Detection
from roadpreview.vision.tracker import LeadTrackerConfig, LeadVehicleTracker

CAM = CameraModel(width=1280, height=720, fx=1000.0, fy=1000.0, cx=640.0, cy=360.0)
BOX = (600.0, 350.0, 680.0, 414.0)  # 80 px wide: 1.8 m at 22.5 m


def _tracker() -> LeadVehicleTracker:
    tr = LeadVehicleTracker(CAM, LeadTrackerConfig())
    tr._active = True
    tr._box = BOX
    return tr


def _scaled(
    box: tuple[float, float, float, float], k: float
) -> tuple[float, float, float, float]:
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    hw, hh = k * (box[2] - box[0]) / 2, k * (box[3] - box[1]) / 2
    return (cx - hw, cy - hh, cx + hw, cy + hh)


def test_a_detection_of_the_same_size_is_blended_in() -> None:
    tr = _tracker()
    moved = (604.0, 352.0, 684.0, 416.0)  # 4 px right, 2 down, same size
    tr._refresh(Detection(moved, 0.9, "vehicle"), 10.0)
    a = tr.config.box_refresh
    expected = tuple((1 - a) * o + a * n for o, n in zip(BOX, moved, strict=True))
    assert tr._box == pytest.approx(expected, abs=1e-9)


def test_a_swollen_detection_is_ignored_until_the_disagreement_persists() -> None:
    tr = _tracker()
    cfg = tr.config
    big = _scaled(BOX, 1.3)  # 30 % wider: beyond the 15 % gate
    t0 = 100.0
    for k in range(5):  # finder runs 0.3 s apart, 1.2 s < refresh_size_persist_s
        tr._refresh(Detection(big, 0.9, "vehicle"), t0 + 0.3 * k)
        assert tr._box == BOX, f"blended at +{0.3 * k:.1f} s"
    tr._refresh(Detection(big, 0.9, "vehicle"), t0 + cfg.refresh_size_persist_s)
    width = tr._box[2] - tr._box[0]
    assert width == pytest.approx(80.0 * (1 + cfg.box_refresh * 0.3), rel=1e-9)


def test_an_agreeing_detection_ends_a_disagreement() -> None:
    tr = _tracker()
    tr._refresh(Detection(_scaled(BOX, 1.3), 0.9, "vehicle"), 0.0)
    tr._refresh(Detection(BOX, 0.9, "vehicle"), 0.5)  # agrees: the run of disagreement ends
    tr._refresh(Detection(_scaled(BOX, 1.3), 0.9, "vehicle"), 1.6)  # a new, short one
    assert tr._box == BOX
