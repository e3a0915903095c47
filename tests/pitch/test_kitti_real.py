"""Pitch on real KITTI frames (../shared/data/kitti-lead-car; skipped when absent).

Correspondences: goodFeaturesToTrack + pyramidal LK with a forward-backward
check between consecutive frames, with the lead car's region masked out. The
car drives straight at low speed, closes in on the lead and stops: the camera
barely pitches between frames.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.pitch.essential import EssentialMatrixPitchEstimator
from roadpreview.pitch.robust_lm import RobustPitchEstimator

# KITTI 2011_09_26 left colour camera, rectified (../shared/data/README.md)
KITTI = CameraModel(width=1242, height=375, fx=721.5377, fy=721.5377, cx=609.5593, cy=172.8540)
# the lead car's region over the whole clip (it grows as the ego closes in), hand-measured
LEAD_REGION = (slice(180, 375), slice(520, 800))


def _gray(path: Path) -> np.ndarray:
    image = cv2.imread(str(path))
    assert image is not None, path
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def _pairs(kitti_dir: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    files = sorted((kitti_dir / "frames").glob("*.png"))
    assert len(files) == 78
    frames = [_gray(f) for f in files]
    mask = np.full(frames[0].shape, 255, np.uint8)
    mask[LEAD_REGION] = 0
    win, levels = (21, 21), 3
    out = []
    for prev, cur in itertools.pairwise(frames):
        p0 = cv2.goodFeaturesToTrack(prev, 1500, 0.01, 7, mask=mask)
        # nextPts: without OPTFLOW_USE_INITIAL_FLOW only its buffer is used (the stubs take
        # no None)
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(
            prev, cur, p0, p0.copy(), winSize=win, maxLevel=levels
        )
        pb, st2, _ = cv2.calcOpticalFlowPyrLK(
            cur, prev, p1, p1.copy(), winSize=win, maxLevel=levels
        )
        fb = np.linalg.norm((pb - p0).reshape(-1, 2), axis=1)
        ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (fb < 0.5)
        out.append((p0.reshape(-1, 2)[ok], p1.reshape(-1, 2)[ok]))
    return out


@pytest.mark.shared
def test_kitti_frame_to_frame_pitch_is_small_and_agrees_with_essential(kitti_dir: Path) -> None:
    robust = RobustPitchEstimator(KITTI)
    essential = EssentialMatrixPitchEstimator(KITTI)
    compared = 0
    for a, b in _pairs(kitti_dir):
        r = robust.estimate(a, b)
        assert r, r.reason
        assert abs(r.phi_deg) < 0.3
        # the 5-point baseline needs translation; compare where the ego still moves
        if float(np.median(np.linalg.norm(b - a, axis=1))) > 1.0:
            e = essential.estimate(a, b)
            assert e, e.reason
            assert abs(math.degrees(r.phi - e.phi)) < 0.1
            compared += 1
    assert compared >= 40  # the ego moves for about the first 50 frames
