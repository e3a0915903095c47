"""Shared fixtures: paths to the real recordings in ../shared (skip when absent)."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
FILES = Path(__file__).resolve().parent / "files"


def _shared(*parts: str) -> Path:
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is absent (real recordings live in ../shared)")
    return path


@pytest.fixture(scope="session")
def kitti_dir() -> Path:
    """The 78 real KITTI frames with a lead car (../shared/data/kitti-lead-car)."""
    return _shared("data", "kitti-lead-car")


@pytest.fixture(scope="session")
def comma_dir() -> Path:
    """The real comma2k19 RAV4 minute (../shared/data/comma2k19-rav4-segment)."""
    return _shared("data", "comma2k19-rav4-segment")


@pytest.fixture(scope="session")
def yolox_model() -> Path:
    """The real YOLOX-nano COCO detector (../shared/models/yolox_nano.onnx)."""
    return _shared("models", "yolox_nano.onnx")
