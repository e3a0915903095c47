"""``roadpreview bench soak`` in miniature: a 3 s drive played twice for 5 s instead of
three 2 min drives cycled for 30 min. The report's structure and its physical sanity (RSS
sampled, costs positive, a part of a frame never costing more than the frame), the
chained drive's clock, never timing thresholds (docs/robustness.md)."""

from __future__ import annotations

import csv
import itertools
import json
import shutil
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

from roadpreview.bench import BENCHMARKS, LONG
from roadpreview.bench.soak import (
    CHECKPOINTS,
    ChainedDrive,
    SoakOptions,
    container_sizes,
    format_report,
    grown_containers,
    parse_resolution,
    run,
    soak,
    window_median,
)
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import Pipeline
from roadpreview.types import CameraFrame

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


def test_chained_drive_runs_on_one_clock_across_the_seam(drive: Recording) -> None:
    times = _frame_times(drive.folder)
    dt = 1.0 / drive.config.camera.fps
    chain = ChainedDrive([drive.folder], 5.0, PipelineConfig())
    samples = list(chain)
    chain.close()
    assert chain.passes == 2
    assert chain.errors == 0
    assert sum(chain.problems.values()) == 0  # a clean drive: no problem of any kind
    t = np.array([s.t_s for s in samples])
    assert np.all(np.diff(t) >= 0)  # one clock, never backwards
    frames = [s for s in samples if isinstance(s, CameraFrame)]
    assert [f.index for f in frames] == list(range(len(frames)))
    ft = np.array([f.t_s for f in frames])
    assert np.all(np.diff(ft) > 0)
    # the first pass is the recording itself; the second starts one frame interval after
    # the first pass's last sample and keeps the recording's frame spacing (1 µs: frames.csv)
    n = len(times)
    assert ft[:n] - ft[0] == pytest.approx(np.array(times) - times[0], abs=2e-6)
    assert np.diff(ft[n:]) == pytest.approx(np.diff(times[: len(ft) - n]), abs=2e-6)
    (_, end_1), (start_2, _) = chain.spans
    assert start_2 - end_1 == pytest.approx(dt, abs=1e-6)  # Unix times: 0.24 µs a step
    assert ft[n] >= start_2
    # 5 s from the first sample, not a frame more
    assert ft[-1] - t[0] <= 5.0
    assert ft[-1] - t[0] > 5.0 - 2 * dt


def test_soak_report_is_complete_and_physically_sane(drive: Recording) -> None:
    fps = drive.config.camera.fps
    options = SoakOptions(minutes=5 / 60, drives=1, fps=fps, rss_every_s=0.5)
    report = soak([drive.folder], options=options, window_s=1)

    # 5 s of frames over two passes of the 3 s drive, nothing lost
    assert report.passes == 2
    assert report.frames == pytest.approx(5 * fps, abs=2)
    assert 5.0 - 2 / fps < report.drive_s <= 5.0
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
    # one window per second of the 5 s drive, each with the same part <= whole order
    assert [w["end_s"] for w in report.window_costs] == [1.0, 2.0, 3.0, 4.0, 5.0]
    for w in report.window_costs:
        assert 0 < w["detector_wall_ms"] <= w["frame_wall_ms"]


def test_an_error_that_ends_the_drive_is_the_reports_finding(
    drive: Recording, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The soak does not die with the drive: it reports what ended it, when, and what it
    measured until then (the end checkpoint at the last frame that went through)."""
    times = _frame_times(drive.folder)
    fail_at = 40
    original = Pipeline.push_vision

    def push_vision(self: Pipeline, t: float, fv: Any) -> Any:
        if self.frames == fail_at:
            raise InputDataError("compensation: |phi| must be below pi/2 rad")
        return original(self, t, fv)

    monkeypatch.setattr(Pipeline, "push_vision", push_vision)
    options = SoakOptions(minutes=3 / 60, drives=1, fps=drive.config.camera.fps)
    report = soak([drive.folder], options=options, window_s=1)
    assert report.frames == fail_at
    assert report.error == "InputDataError: compensation: |phi| must be below pi/2 rad"
    assert report.error_at_s == pytest.approx(times[fail_at] - times[0], abs=1e-5)
    end = report.checkpoints[-1]
    assert end["fraction"] == 1.0
    assert end["drive_s"] == pytest.approx(times[fail_at - 1] - times[0], abs=1e-5)
    table = format_report(report)
    assert "THE RUN ENDED EARLY" in table
    assert "InputDataError" in table
    assert any(line.startswith("end ") for line in table.splitlines())


def test_bench_soak_writes_its_json_and_reuses_a_cached_drive(
    drive: Recording, tmp_path: Path
) -> None:
    assert BENCHMARKS["soak"] == "roadpreview.bench.soak"
    assert "soak" in LONG  # not in 'bench all'
    options = SoakOptions(
        minutes=3 / 60, drives=1, drive_minutes=0.25, width=320, height=180, fps=30.0, seed=0
    )
    shutil.copytree(drive.folder, tmp_path / "cache" / options.key(0))  # nothing to render
    out = tmp_path / "soak.json"
    table = run(
        seed=0,
        minutes=options.minutes,
        drives=1,
        drive_minutes=0.25,
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
    assert data["frames"] == len(_frame_times(drive.folder))  # 3 s: one pass, all of it
    assert data["passes"] == 1
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
    with pytest.raises(ConfigError, match="--drive-minutes"):
        SoakOptions(drive_minutes=0.1).validate()
