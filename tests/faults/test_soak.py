"""``roadpreview bench soak`` in miniature: a 3 s drive instead of 30 min. The report's
structure and its physical sanity (RSS sampled, costs positive, a part of a frame never
costing more than the frame), never timing thresholds (docs/robustness.md)."""

from __future__ import annotations

import csv
import itertools
import json
import shutil
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from roadpreview.bench import BENCHMARKS, LONG
from roadpreview.bench.soak import (
    CHECKPOINTS,
    SoakOptions,
    container_sizes,
    grown_containers,
    parse_resolution,
    run,
    soak,
    window_median,
)
from roadpreview.errors import ConfigError

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

#: one clock tick's worth of slack between two timings of the same call, ms
TICK_MS = 0.05


@pytest.fixture(scope="module")
def drive(make_recording: Callable[..., Recording]) -> Recording:
    # the same drive as tests/sources and tests/cli use: rendered once per session
    return make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180)


def _frame_times(folder: Path) -> list[float]:
    with (folder / "frames.csv").open() as fh:
        return [float(row["t_s"]) for row in csv.DictReader(fh)]


def test_soak_report_is_complete_and_physically_sane(drive: Recording) -> None:
    times = _frame_times(drive.folder)
    report = soak(drive.folder, options=SoakOptions(minutes=3 / 60, rss_every_s=0.5), window_s=1)

    # every frame replayed; the drive's span is the frames' span (frames.csv, 1 µs rounding)
    assert report.frames == len(times)
    assert report.drive_s == pytest.approx(times[-1] - times[0], abs=1e-5)
    assert report.source_errors
    assert not any(report.source_errors.values())

    # the four checkpoints, in order, the last one at the last frame
    assert [r["fraction"] for r in report.checkpoints] == list(CHECKPOINTS)
    at = [r["drive_s"] for r in report.checkpoints]
    assert all(a < b for a, b in itertools.pairwise(at))
    assert at[-1] == pytest.approx(report.drive_s, abs=1e-9)

    # RSS sampled every 0.5 s of drive: a Python with numpy and OpenCV holds > 50 MB
    series = np.array(report.rss_series)
    assert len(series) >= report.drive_s / 0.5
    assert np.all(np.diff(series[:, 0]) >= 0)
    assert np.all((series[:, 1] > 50) & (series[:, 1] < 8000))
    assert all(50 < r["rss_mb"] < 8000 for r in report.checkpoints)
    assert all(r["gc_objects"] > 1000 for r in report.checkpoints)
    rss = [r["rss_mb"] for r in report.checkpoints]
    assert report.rss_spread == pytest.approx((max(rss) - min(rss)) / rss[0])

    # costs: positive; the detector runs inside the frame's push, so it never costs more
    # (per frame, hence also in the medians); one thread's CPU time never exceeds its wall
    for start_end in report.costs.values():
        assert all(np.isfinite(v) and v > 0 for v in start_end)
    for i in (0, 1):
        c = {k: v[i] for k, v in report.costs.items()}
        assert c["detector_wall_ms"] <= c["frame_wall_ms"]
        assert c["detector_cpu_ms"] <= c["frame_cpu_ms"] + TICK_MS
        for part in ("fusion", "detector", "frame"):
            assert c[f"{part}_cpu_ms"] <= c[f"{part}_wall_ms"] * 1.05 + TICK_MS
    for r in report.checkpoints:
        assert 0 < r["detector_wall_ms"] <= r["frame_wall_ms"]


def test_bench_soak_writes_its_json_and_reuses_a_cached_drive(
    drive: Recording, tmp_path: Path
) -> None:
    assert BENCHMARKS["soak"] == "roadpreview.bench.soak"
    assert "soak" in LONG  # not in 'bench all'
    options = SoakOptions(minutes=3 / 60, width=320, height=180, fps=30.0, seed=0)
    shutil.copytree(drive.folder, tmp_path / "cache" / options.key)  # nothing to render
    out = tmp_path / "soak.json"
    table = run(
        seed=0,
        minutes=options.minutes,
        resolution="320x180",
        fps=30.0,
        json_path=out,
        cache=tmp_path / "cache",
    )
    assert "RSS MB" in table
    assert "RSS flat within 10 %" in table
    for q in ("10 %", "50 %", "90 %", "100 %"):
        assert any(line.startswith(q) for line in table.splitlines())
    data = json.loads(out.read_text())
    assert data["frames"] == len(_frame_times(drive.folder))
    assert data["render_s"] == 0.0  # the cached drive was used
    assert set(data["costs"]) >= {"fusion_cpu_ms", "detector_cpu_ms", "frame_cpu_ms"}
    assert len(data["checkpoints"]) == len(CHECKPOINTS)


class _Buffers:
    __module__ = "roadpreview.test"

    def __init__(self) -> None:
        self.log: list[int] = []
        self.ring: deque[int] = deque(maxlen=8)
        self.inner = _Inner()


class _Inner:
    __module__ = "roadpreview.test"

    def __init__(self) -> None:
        self.table: dict[int, int] = {}


def test_a_growing_buffer_is_named_and_a_bounded_one_is_not() -> None:
    obj = _Buffers()
    sizes = []
    for step in range(4):
        for i in range(50):
            obj.log.append(i)
            obj.ring.append(i)
            obj.inner.table[100 * step + i] = i
        sizes.append(container_sizes(obj))
    assert sizes[-1]["_Buffers.ring"] == 8
    grown = grown_containers(sizes)
    assert grown == {
        "_Buffers.log": [50, 100, 150, 200],
        "_Buffers.inner.table": [50, 100, 150, 200],
    }


def test_window_median_and_bad_options() -> None:
    t = np.arange(10.0)
    v = t * 2
    assert window_median(t, v, 2.0, 6.0) == 8.0  # median of 4, 6, 8, 10, 12
    assert np.isnan(window_median(t, v, 20.0, 30.0))
    assert parse_resolution("640x360") == (640, 360)
    with pytest.raises(ConfigError, match="--resolution"):
        parse_resolution("640by360")
    with pytest.raises(ConfigError, match="--minutes"):
        SoakOptions(minutes=0).validate()
