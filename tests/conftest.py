"""Shared fixtures: paths to the real recordings in ../shared (skip when absent)."""

from __future__ import annotations

import fcntl
import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import pytest

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording
    from roadpreview.sim.scenario import ScenarioConfig

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


def recording_cache_root() -> Path:
    """Where simulated recordings persist between runs and are shared by the xdist workers:
    ``$ROADPREVIEW_TEST_CACHE`` or ``.pytest_cache/roadpreview-recordings``."""
    env = os.environ.get("ROADPREVIEW_TEST_CACHE")
    return Path(env) if env else ROOT / ".pytest_cache" / "roadpreview-recordings"


def cached_recording(cfg: ScenarioConfig, dest: Path) -> Path:
    """``cfg``'s recording copied into ``dest``: rendered once per scenario, simulator
    source (`roadpreview.eval.runner.scenario_digest`) and numpy / scipy / OpenCV version
    into the shared cache, under a file
    lock so that two workers wanting the same drive render it once. The copy keeps a test
    that damages its files away from the cache and from the other tests."""
    import cv2
    import numpy as np
    import scipy

    from roadpreview.digests import digest
    from roadpreview.eval.runner import scenario_digest
    from roadpreview.sim.recording import write_recording

    root = recording_cache_root()
    root.mkdir(parents=True, exist_ok=True)
    # the libraries that compute and encode it too (`make test-latest` shares the cache)
    key = digest([scenario_digest(cfg), np.__version__, scipy.__version__, cv2.__version__])
    done = root / key / ".complete"
    with (root / f"{key}.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not done.exists():
            shutil.rmtree(root / key, ignore_errors=True)  # a render that was cut short
            write_recording(cfg, root / key)
            done.touch()
    shutil.copytree(root / key, dest, ignore=shutil.ignore_patterns(".complete"))
    return dest


@pytest.fixture(scope="session")
def make_recording(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Recording]:
    """Factory for simulated recordings, cached by their scenario and the simulator's code.

    ``make_recording("demo", seed=0, duration_s=6.0, width=640, height=360, masks=False,
    video=True)`` returns an opened `roadpreview.sim.recording.Recording`, a copy of its
    own for this session (`cached_recording`): rendered once for all runs and workers
    until the simulator's source changes. Keep drives short all the same: a first render
    costs about 15-30 ms per frame at 640x360-1280x720.
    """
    from dataclasses import replace

    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import Recording

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
            cache[key] = Recording.open(cached_recording(cfg, folder))
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


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Modules marked ``slow`` run first (stable otherwise): with ``--dist loadscope`` each
    module goes to one xdist worker whole (its module fixtures built once), and the
    longest ones started first keep both cores busy to the end instead of leaving one
    long module alone at the tail."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
