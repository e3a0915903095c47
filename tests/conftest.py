"""Shared fixtures: paths to the real recordings in ../shared (skip when absent)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import pytest

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

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


@pytest.fixture(scope="session")
def make_recording(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Recording]:
    """Factory for simulated recordings, cached per session by their parameters.

    ``make_recording("demo", seed=0, duration_s=6.0, width=640, height=360, masks=False,
    video=True)`` returns an opened `roadpreview.sim.recording.Recording`. Keep
    drives short: rendering costs about 15-30 ms per frame at 640x360-1280x720.
    """
    from dataclasses import replace

    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import Recording, write_recording

    root = tmp_path_factory.mktemp("recordings")
    cache: dict[tuple[object, ...], Recording] = {}

    def make(
        preset: str = "demo",
        *,
        seed: int = 0,
        duration_s: float | None = None,
        width: int | None = 640,
        height: int | None = 360,
        masks: bool = False,
        video: bool = True,
        **scenario_overrides: object,
    ) -> Recording:
        key = (
            preset,
            seed,
            duration_s,
            width,
            height,
            masks,
            video,
            tuple(sorted(scenario_overrides.items())),
        )
        if key not in cache:
            cfg = drive_config(preset, seed, duration_s=duration_s, width=width, height=height)
            # the overrides are DriveConfig fields of any type: checked by replace at run time
            overrides = cast("dict[str, Any]", scenario_overrides)
            cfg = replace(cfg, output=replace(cfg.output, masks=masks, video=video), **overrides)
            folder = root / f"rec{len(cache):03d}_{preset}_{seed}"
            write_recording(cfg, folder)
            cache[key] = Recording.open(folder)
        return cache[key]

    return make


@pytest.fixture(scope="session")
def first_frames() -> Callable[[Path, Path, int], Path]:
    """``first_frames(video, out, n)``: a video of the first ``n`` frames of ``video``
    (MJPG in ``out``, an .avi), e.g. a camera that goes silent after them."""
    import cv2

    def write(video: Path, out: Path, n: int) -> Path:
        src = cv2.VideoCapture(str(video))
        size = (int(src.get(cv2.CAP_PROP_FRAME_WIDTH)), int(src.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        writer = cv2.VideoWriter(str(out), cv2.VideoWriter.fourcc(*"MJPG"), 30.0, size)
        try:
            for _ in range(n):
                ok, frame = src.read()
                assert ok, f"{video}: fewer than {n} frames"
                writer.write(frame)
        finally:
            writer.release()
            src.release()
        return out

    return write


@pytest.fixture(scope="session")
def _log_levels_at_start() -> dict[str, int]:
    import logging

    from roadpreview.cli.main import PROGRESS_LOGGER

    # the root (``main`` sets it), the progress logger, and the package's (the benchmarks
    # turn it down to errors while they measure)
    return {n: logging.getLogger(n).level for n in ("", PROGRESS_LOGGER, "roadpreview")}


@pytest.fixture(autouse=True)
def _restore_log_levels(_log_levels_at_start: dict[str, int]) -> Iterator[None]:
    """`roadpreview.cli.main.main` sets the root and progress loggers' levels (``-q``:
    errors only) as a command line should; a test (or a module fixture) that calls it
    must not silence the warnings later tests look for: every test starts and ends with
    the session's levels."""
    import logging

    def reset() -> None:
        for name, level in _log_levels_at_start.items():
            logging.getLogger(name).setLevel(level)

    reset()
    yield
    reset()
