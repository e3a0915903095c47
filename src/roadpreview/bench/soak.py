"""``roadpreview bench soak``: memory and per-frame cost over a long replay (issue 17).

One continuous simulated drive (the ``wild`` preset: random speed and gap, rough road,
random anomalies, oncoming traffic, a smartphone IMU) of ``minutes`` of driving is
rendered at a low resolution and frame rate (rendering 30 min at 720p / 30 fps would take
hours here; nothing repeats: every frame, IMU sample and CAN frame is new), then replayed
through the product's composition: the recording's video and CAN log as file sources on
one clock (`roadpreview.apps.replay.ReplayInputs`), one `Pipeline`, the run loop, and
the CAN output encoded into a BLF log as the daemon records it. The drive is rendered in
a child process, so that the simulator's memory is not in the replay's RSS.

Measured while the replay runs, in preallocated arrays (the probe does not grow):

* the process's resident set (VmRSS) every ``rss_every_s`` of drive time;
* per frame, the CPU time (``time.thread_time``: the loop's thread, so the other
  processes of a loaded machine do not count) and the wall time of the fusion (every
  call into `StreamingPitchFusion` since the previous frame: its gyro samples, the
  visual measurement or failure, the estimate), of the detector (``push`` /
  ``restart``) and of the whole ``Pipeline.push`` of the frame;
* at 10, 50, 90 and 100 % of the drive: the number of Python objects the collector
  tracks and the length of every container reachable from the pipeline's attributes
  (lists, dicts, deques, sets, arrays), so that a buffer that grows is named.

Reported: RSS at 10/50/90/100 % and whether it stays within 10 % (max - min over the RSS
at 10 %), the per-frame costs as medians over the first and the last minute of drive
time (and the minute before each checkpoint), and the containers that grew after 50 %.
"""

from __future__ import annotations

import gc
import itertools
import json
import logging
import math
import multiprocessing
import os
import resource
import tempfile
import time
from array import array
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roadpreview.bench._timing import format_table
from roadpreview.errors import ConfigError
from roadpreview.pipeline.pipeline import FrameResult, Pipeline
from roadpreview.types import Alert, CameraFrame, Sample, Status

log = logging.getLogger(__name__)

#: the checkpoints, as fractions of the drive's frames
CHECKPOINTS = (0.1, 0.5, 0.9, 1.0)
#: RSS counts as flat when max - min over the checkpoints is within this share of the
#: RSS at the first checkpoint (issue 17)
FLAT_WITHIN = 0.10
#: the statistics' window: the median per-frame cost over one minute of drive time
WINDOW_S = 60.0
#: the StreamingPitchFusion calls a frame costs (its gyro samples come between frames)
FUSION_CALLS = ("push_gyro", "push_visual", "push_vision_failure", "estimate")
#: the detector's calls in a frame
DETECTOR_CALLS = ("push", "restart")


@dataclass(frozen=True)
class SoakOptions:
    """What the soak drives and how often it measures."""

    minutes: float = 30.0  #: minutes of simulated driving (issue 17: at least 30)
    width: int = 320  #: px; 320x180 renders at ~17 ms per frame here
    height: int = 180  #: px
    fps: float = 10.0  #: camera frames per second of the drive (30 fps: three times the time)
    seed: int = 0  #: the drive's seed (the ``wild`` preset)
    rss_every_s: float = 1.0  #: drive seconds between two RSS samples

    def validate(self) -> None:
        if not (self.minutes > 0 and math.isfinite(self.minutes)):
            raise ConfigError(f"--minutes {self.minutes}: a positive number of minutes")
        if self.width < 160 or self.height < 90:
            raise ConfigError(f"--resolution {self.width}x{self.height}: at least 160x90")
        if not 5.0 <= self.fps <= 120.0:
            raise ConfigError(f"--fps {self.fps}: 5 to 120 frames per second")

    @property
    def key(self) -> str:
        """The rendered drive's folder name in a cache."""
        return (
            f"wild-seed{self.seed}-{self.minutes:g}min-{self.width}x{self.height}-{self.fps:g}fps"
        )


def parse_resolution(text: str) -> tuple[int, int]:
    """``"320x180"`` -> (320, 180)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ConfigError(f"--resolution {text!r}: WIDTHxHEIGHT in pixels, e.g. 320x180") from None
    return w, h


# -- measuring -----------------------------------------------------------------------------
def rss_mb() -> float:
    """The process's resident set now, MB (Linux ``/proc/self/statm``; elsewhere the peak
    from ``getrusage``)."""
    try:
        with open("/proc/self/statm", "rb") as fh:
            pages = int(fh.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):  # not Linux
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


class CostClock:
    """CPU and wall seconds spent in the calls wrapped by `time_calls`, since `take`."""

    def __init__(self) -> None:
        self.cpu = 0.0
        self.wall = 0.0

    def take(self) -> tuple[float, float]:
        """(cpu, wall) seconds since the last take; starts again from zero."""
        out = (self.cpu, self.wall)
        self.cpu = self.wall = 0.0
        return out


def time_calls(obj: object, names: tuple[str, ...], clock: CostClock) -> None:
    """Shadow ``obj``'s methods ``names`` with instance attributes that add their CPU
    (thread) and wall time to ``clock``."""
    for name in names:
        method = getattr(obj, name)

        def timed(*args: Any, _m: Callable[..., Any] = method, **kwargs: Any) -> Any:
            c0, w0 = time.thread_time(), time.perf_counter()
            try:
                return _m(*args, **kwargs)
            finally:
                clock.cpu += time.thread_time() - c0
                clock.wall += time.perf_counter() - w0

        setattr(obj, name, timed)


_CONTAINERS = (list, dict, deque, set, array, np.ndarray)


def container_sizes(root: object, *, max_depth: int = 6) -> dict[str, int]:
    """Length (arrays: size) of every container reachable from ``root`` through the
    attributes of roadpreview objects (and dataclass fields), by attribute path. The
    elements of containers are not walked (a buffer of 10,000 samples costs one entry)."""
    out: dict[str, int] = {}
    seen: set[int] = set()

    def walk(obj: object, path: str, depth: int) -> None:
        if id(obj) in seen or depth > max_depth:
            return
        seen.add(id(obj))
        attrs: dict[str, object] = {}
        if hasattr(obj, "__dict__"):
            attrs.update(vars(obj))
        for cls in type(obj).__mro__:
            for slot in getattr(cls, "__slots__", ()):
                if isinstance(slot, str) and hasattr(obj, slot):
                    attrs[slot] = getattr(obj, slot)
        for name, value in attrs.items():
            sub = f"{path}.{name}"
            if isinstance(value, np.ndarray):
                out[sub] = int(value.size)
            elif isinstance(value, _CONTAINERS):
                out[sub] = len(value)
            elif type(value).__module__.startswith("roadpreview"):
                walk(value, sub, depth + 1)

    walk(root, type(root).__name__, 0)
    return out


class SoakProbe:
    """A `roadpreview.loop.Stage` around a `Pipeline` that records, per frame, the costs
    of the fusion, the detector and the whole push, and samples the RSS and the
    containers (module docstring). Arrays are sized for ``n_frames`` up front."""

    def __init__(self, pipeline: Pipeline, n_frames: int, rss_every_frames: int) -> None:
        self.pipeline = pipeline
        self.fusion_clock = CostClock()
        self.detector_clock = CostClock()
        time_calls(pipeline.fusion, FUSION_CALLS, self.fusion_clock)
        time_calls(pipeline.detector, DETECTOR_CALLS, self.detector_clock)
        self.n = 0
        self.t = np.full(n_frames, np.nan)
        #: per frame, ms: columns fusion, detector, frame (CPU), then the same as wall time
        self.ms = np.full((n_frames, 6), np.nan)
        self.every = max(1, rss_every_frames)
        n_rss = n_frames // self.every + 2
        self.rss_t = np.full(n_rss, np.nan)
        self.rss = np.full(n_rss, np.nan)
        self.n_rss = 0
        self.marks = [max(1, math.ceil(q * n_frames)) for q in CHECKPOINTS]
        self.snapshots: dict[int, dict[str, Any]] = {}

    @property
    def input_errors(self) -> int:
        return self.pipeline.input_errors

    @input_errors.setter
    def input_errors(self, value: int) -> None:
        self.pipeline.input_errors = value

    def push(self, sample: Sample) -> FrameResult | None:
        if not isinstance(sample, CameraFrame):
            return self.pipeline.push(sample)
        c0, w0 = time.thread_time(), time.perf_counter()
        result = self.pipeline.push(sample)
        frame_cpu, frame_wall = time.thread_time() - c0, time.perf_counter() - w0
        fusion_cpu, fusion_wall = self.fusion_clock.take()
        det_cpu, det_wall = self.detector_clock.take()
        i = self.n
        if i < self.t.size:  # a video longer than announced: not recorded
            self.t[i] = sample.t_s
            costs = (fusion_cpu, det_cpu, frame_cpu, fusion_wall, det_wall, frame_wall)
            self.ms[i] = costs
            self.ms[i] *= 1e3
        self.n += 1
        if self.n % self.every == 0 or self.n == 1:
            self._sample_rss(sample.t_s)
        if self.n in self.marks:
            self._snapshot(sample.t_s)
        return result

    def finish(self) -> list[Alert]:
        return self.pipeline.finish()

    def status(self) -> Status:
        return self.pipeline.status()

    def _sample_rss(self, t: float) -> None:
        if self.n_rss < self.rss.size:
            self.rss_t[self.n_rss] = t
            self.rss[self.n_rss] = rss_mb()
            self.n_rss += 1

    def _snapshot(self, t: float) -> None:
        self._sample_rss(t)
        self.snapshots[self.n] = {
            "t_s": t,
            "rss_mb": rss_mb(),
            "gc_objects": len(gc.get_objects()),
            "containers": container_sizes(self.pipeline),
        }


# -- the statistics (pure) -------------------------------------------------------------------
def window_median(
    t: NDArray[np.float64], values: NDArray[np.float64], lo: float, hi: float
) -> float:
    """Median of ``values`` over the frames with ``lo <= t <= hi`` (NaN if none)."""
    sel = (t >= lo) & (t <= hi) & np.isfinite(values)
    return float(np.median(values[sel])) if np.any(sel) else math.nan


def grown_containers(sizes: list[dict[str, int]], *, min_growth: int = 16) -> dict[str, list[int]]:
    """The containers (paths) whose length rose from the second snapshot (50 %) to the
    last by at least ``min_growth`` and never fell in between: path -> lengths per
    snapshot (absent: 0). A bounded buffer is full by 50 % of a long drive."""
    if len(sizes) < 2:
        return {}
    paths = sorted(set().union(*sizes))
    out: dict[str, list[int]] = {}
    for p in paths:
        lengths = [s.get(p, 0) for s in sizes]
        tail = lengths[1:]
        if tail[-1] - tail[0] >= min_growth and all(b >= a for a, b in itertools.pairwise(tail)):
            out[p] = lengths
    return out


@dataclass
class SoakReport:
    """What the soak measured (`soak`)."""

    options: SoakOptions
    frames: int
    drive_s: float
    wall_s: float
    render_s: float
    #: one row per checkpoint: fraction, drive time from the first frame (s), RSS (MB), gc
    #: objects, and the median per-frame costs (ms) over the minute before it
    checkpoints: list[dict[str, float]]
    #: median per-frame costs (ms) over the first and the last minute: cost -> (start, end)
    costs: dict[str, tuple[float, float]]
    rss_flat: bool
    rss_spread: float  #: (max - min) / RSS at 10 %
    grown: dict[str, list[int]]
    window_s: float = WINDOW_S  #: the costs' window of drive time
    rss_series: list[tuple[float, float]] = field(default_factory=list)  #: (drive s, MB)
    alerts: int = 0
    mode_changes: int = 0
    source_errors: dict[str, int] = field(default_factory=dict)
    fusion_stats: dict[str, int] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["costs"] = {k: {"start_ms": a, "end_ms": b} for k, (a, b) in self.costs.items()}
        return out


#: the recorded costs: name -> column of `SoakProbe.ms`
COST_COLUMNS = {
    "fusion_cpu_ms": 0,
    "detector_cpu_ms": 1,
    "frame_cpu_ms": 2,
    "fusion_wall_ms": 3,
    "detector_wall_ms": 4,
    "frame_wall_ms": 5,
}


def summarise(
    probe: SoakProbe, window_s: float
) -> tuple[
    list[dict[str, float]], dict[str, tuple[float, float]], bool, float, dict[str, list[int]]
]:
    """Checkpoint rows, start/end costs, RSS flatness and grown containers of a run."""
    n = min(probe.n, probe.t.size)
    t, ms = probe.t[:n], probe.ms[:n]
    t0, t1 = float(t[0]), float(t[-1])
    rows: list[dict[str, float]] = []
    for q, mark in zip(CHECKPOINTS, probe.marks, strict=True):
        snap = probe.snapshots.get(mark)
        if snap is None:
            continue
        at = float(snap["t_s"])
        row = {
            "fraction": q,
            "drive_s": at - t0,
            "rss_mb": float(snap["rss_mb"]),
            "gc_objects": float(snap["gc_objects"]),
        }
        for name, col in COST_COLUMNS.items():
            row[name] = window_median(t, ms[:, col], at - window_s, at)
        rows.append(row)
    costs = {
        name: (
            window_median(t, ms[:, col], t0, t0 + window_s),
            window_median(t, ms[:, col], t1 - window_s, t1),
        )
        for name, col in COST_COLUMNS.items()
    }
    rss = [r["rss_mb"] for r in rows]
    spread = (max(rss) - min(rss)) / rss[0] if rss else math.nan
    grown = grown_containers([probe.snapshots[m]["containers"] for m in sorted(probe.snapshots)])
    return rows, costs, bool(spread <= FLAT_WITHIN), spread, grown


# -- the run -------------------------------------------------------------------------------
def drive_config(options: SoakOptions) -> Any:
    """The scenario of the soak's drive (``wild``, resized, no IMU CSV: the CAN log only)."""
    from roadpreview.sim.presets import wild
    from roadpreview.sim.scenario import CameraSpec

    cfg = wild(options.seed, duration_s=options.minutes * 60.0)
    cam = cfg.camera
    camera = CameraSpec(
        width=options.width,
        height=options.height,
        vfov_deg=cam.vfov_deg,
        fps=options.fps,
        forward=cam.forward,
    )
    return replace(cfg, camera=camera, output=replace(cfg.output, imu_csv=False))


def _render(cfg: Any, folder: str) -> float:
    from roadpreview.sim.recording import write_recording

    return write_recording(cfg, folder).seconds


def render_drive(options: SoakOptions, folder: Path) -> float:
    """Render the soak's drive into ``folder`` in a child process (seconds taken; 0 when
    ``folder`` already holds it)."""
    if (folder / "truth.json").is_file():
        log.info("soak: reusing the drive in %s", folder)
        return 0.0
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool:
        return float(pool.submit(_render, drive_config(options), str(folder)).result())


def soak(
    recording: Path,
    *,
    options: SoakOptions | None = None,
    window_s: float = WINDOW_S,
    render_s: float = 0.0,
) -> SoakReport:
    """Replay ``recording`` (a recording folder) through the pipeline into a CAN log,
    measuring as the module docstring says."""
    from roadpreview.apps.replay import ReplayInputs
    from roadpreview.loop import run
    from roadpreview.pipeline.config import PipelineConfig
    from roadpreview.sinks.can import CanLogSink, repetition_config

    options = options or SoakOptions()
    config = PipelineConfig()
    inputs = ReplayInputs.from_recording(recording)
    video, sources = inputs.sources(config)
    n_frames = video.n_frames
    fps = video.fps if video.fps > 0 else options.fps
    probe = SoakProbe(
        Pipeline(inputs.camera, config),
        n_frames,
        rss_every_frames=round(options.rss_every_s * fps),
    )
    with tempfile.TemporaryDirectory() as tmp:
        sink = CanLogSink(
            Path(tmp) / "alerts.blf",
            detector=config.anomaly.detector,
            repetition=repetition_config(config),
        )
        summary = run(sources, probe, [sink], status_period_s=config.can.status_period_s)
    rows, costs, flat, spread, grown = summarise(probe, window_s)
    n = min(probe.n, probe.t.size)
    t0 = float(probe.t[0]) if n else math.nan
    return SoakReport(
        options=options,
        frames=summary.frames,
        drive_s=float(probe.t[n - 1] - probe.t[0]) if n else 0.0,
        wall_s=summary.seconds,
        render_s=render_s,
        window_s=window_s,
        checkpoints=rows,
        costs=costs,
        rss_flat=flat,
        rss_spread=spread,
        grown=grown,
        rss_series=[
            (float(a - t0), float(b))
            for a, b in zip(probe.rss_t[: probe.n_rss], probe.rss[: probe.n_rss], strict=True)
        ],
        alerts=len(summary.alerts),
        mode_changes=len(summary.mode_changes),
        source_errors=dict(summary.source_errors),
        fusion_stats=dict(getattr(probe.pipeline.fusion, "stats", {})),
    )


def format_report(report: SoakReport) -> str:
    """The printed table."""
    o = report.options
    win = f"{report.window_s:g} s"
    head = (
        f"roadpreview bench soak: {report.drive_s / 60:.1f} min of simulated driving "
        f"(wild, seed {o.seed}, {o.width}x{o.height} at {o.fps:g} fps, {report.frames} frames) "
        f"replayed in {report.wall_s / 60:.1f} min; costs: CPU ms per frame, medians over the "
        f"{win} of drive before each checkpoint"
    )
    rows = [
        [
            f"{100 * r['fraction']:.0f} %",
            f"{r['drive_s'] / 60:.1f}",
            f"{r['rss_mb']:.1f}",
            f"{r['gc_objects']:.0f}",
            f"{r['fusion_cpu_ms']:.3f}",
            f"{r['detector_cpu_ms']:.3f}",
            f"{r['frame_cpu_ms']:.2f}",
        ]
        for r in report.checkpoints
    ]
    table = format_table(
        ["checkpoint", "drive min", "RSS MB", "gc objects", "fusion", "detector", "frame"], rows
    )
    c = report.costs
    lines = [head, "", table, ""]
    lines.append(
        f"RSS flat within {100 * FLAT_WITHIN:.0f} %: {'yes' if report.rss_flat else 'NO'} "
        f"(spread {100 * report.rss_spread:.1f} % of the RSS at 10 %)"
    )
    for name, label in (
        ("fusion_cpu_ms", "fusion"),
        ("detector_cpu_ms", "detector"),
        ("frame_cpu_ms", "whole frame"),
    ):
        a, b = c[name]
        ratio = f" (x{b / a:.2f})" if a > 0 else ""
        lines.append(f"{label:11s} per frame: first {win} {a:.3f} ms, last {win} {b:.3f} ms{ratio}")
    if report.grown:
        lines.append("containers still growing after 50 % (length at 10/50/90/100 %):")
        lines += [f"  {p}: {' -> '.join(map(str, v))}" for p, v in report.grown.items()]
    else:
        lines.append("containers still growing after 50 %: none")
    lines.append(
        f"alerts {report.alerts}, mode changes {report.mode_changes}, "
        f"source errors {report.source_errors}"
    )
    return "\n".join(lines)


def run(
    repeats: int | None = None,
    quick: bool = False,
    seed: int = 0,
    *,
    minutes: float | None = None,
    resolution: str | None = None,
    fps: float | None = None,
    json_path: str | Path | None = None,
    cache: str | Path | None = None,
) -> str:
    """The benchmark's entry (`roadpreview.bench`): render (or reuse from ``cache``) the
    drive, soak it, write the JSON report to ``json_path`` and return the table.
    ``repeats`` does not apply (one long run); ``quick``: 2 minutes."""
    del repeats
    w, h = parse_resolution(resolution) if resolution else (320, 180)
    options = SoakOptions(
        minutes=minutes if minutes is not None else (2.0 if quick else 30.0),
        width=w,
        height=h,
        fps=fps or 10.0,
        seed=seed,
    )
    options.validate()
    logging.getLogger("roadpreview").setLevel(logging.ERROR)  # 27,000 frames of warnings
    with _drive_folder(cache, options) as folder:
        render_s = render_drive(options, folder)
        report = soak(folder, options=options, render_s=render_s)
    if json_path is not None:
        Path(json_path).write_text(json.dumps(report.to_json(), indent=1))
    return format_report(report)


@contextmanager
def _drive_folder(cache: str | Path | None, options: SoakOptions) -> Iterator[Path]:
    """The drive's folder: in ``cache`` (kept for the next run) or a temporary directory."""
    if cache is not None:
        Path(cache).mkdir(parents=True, exist_ok=True)
        yield Path(cache) / options.key
        return
    with tempfile.TemporaryDirectory() as tmp:
        yield Path(tmp) / options.key


__all__ = [
    "SoakOptions",
    "SoakProbe",
    "SoakReport",
    "container_sizes",
    "format_report",
    "grown_containers",
    "rss_mb",
    "run",
    "soak",
    "window_median",
]
