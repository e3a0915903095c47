"""``build_dataset`` renders its drives as tasks on the batch's Dask engine: each drive
the same as rendered in this process, and a second call reuses them."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TypedDict

import cv2
import numpy as np
import pytest

from roadpreview.sim.dataset import build_dataset, drive_config
from roadpreview.sim.recording import Recording, write_recording

pytestmark = pytest.mark.slow


class _Small(TypedDict):
    duration_s: float
    width: int
    height: int


SMALL = _Small(duration_s=1.5, width=320, height=180)


def _frames(video: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(video))
    out = []
    ok, frame = cap.read()
    while ok:
        out.append(frame)
        ok, frame = cap.read()
    cap.release()
    return out


def test_drives_rendered_on_the_engine_equal_those_rendered_here(tmp_path: Path) -> None:
    out = tmp_path / "ds"

    def build() -> None:
        build_dataset(out, preset_name="controlled", n_drives=2, seed=5, jobs=2, **SMALL)

    build()
    index = json.loads((out / "dataset.json").read_text())
    assert index["n_drives"] == 2
    here = tmp_path / "here"
    write_recording(drive_config("controlled", 6, **SMALL), here)
    a, b = Recording.open(out / "drive_00006"), Recording.open(here)
    # the same bits, not merely close: the same code on the same machine and libraries, in
    # a 1-thread worker and in this process (the simulator pins BLAS to one thread)
    assert a.truth.keys() == b.truth.keys()
    for key in a.truth:
        np.testing.assert_array_equal(a.truth[key], b.truth[key], err_msg=key)
    for name in ("imu.csv", "frames.csv"):
        assert (a.folder / name).read_bytes() == (b.folder / name).read_bytes(), name
    frames_a, frames_b = _frames(a.folder / "video.mp4"), _frames(b.folder / "video.mp4")
    assert len(frames_a) == len(frames_b) == 45
    assert all(np.array_equal(x, y) for x, y in zip(frames_a, frames_b, strict=True))
    stamp = (out / "drive_00005" / "truth.json").stat().st_mtime_ns
    build()
    assert (out / "drive_00005" / "truth.json").stat().st_mtime_ns == stamp  # reused
