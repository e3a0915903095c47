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
  (lists, dicts, deques, sets, arrays) and from the CAN sink's (the alerts' repetition),
  so that a buffer that grows is named.

Reported: RSS at 10/50/90/100 % and whether it stays within 10 % (max - min over the RSS
at 10 %), its slope after the warm-up (a least-squares line through the samples from the
10 % checkpoint on, MB per minute of drive), the per-frame costs as medians over the first
and the last minute of drive time (and the minute before each checkpoint), and the
containers that grew after 50 %.
"""

from __future__ import annotations

import gc
import itertools
import json
import logging
import math
import os
import resource
import tempfile
import time
from array import array
from collections import Counter, deque
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roadpreview.bench._timing import format_table, package_logs_at_errors
from roadpreview.errors import ConfigError
from roadpreview.pipeline.pipeline import FrameResult, Pipeline
from roadpreview.sources import Source
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

    minutes: float = 30.0  #: minutes of driving the pipeline sees (issue 17: at least 30)
    drives: int = 3  #: distinct simulated drives, played one after the other in a cycle
    drive_minutes: float = 2.0  #: minutes of each drive (rendering slows with the road's length)
    #: px; at 320x180 the vision's relative pitch is poor enough that the fused pitch
    #: drifts past 90 deg within 12-24 min (docs/robustness.md); 640x360 holds it
    width: int = 640
    height: int = 360  #: px
    fps: float = 15.0  #: camera frames per second of the drive (30 fps: twice the time)
    seed: int = 0  #: the first drive's seed (``wild`` preset); the others: seed + 1, ...
    rss_every_s: float = 1.0  #: drive seconds between two RSS samples

    def validate(self) -> None:
        if not (self.minutes > 0 and math.isfinite(self.minutes)):
            raise ConfigError(f"--minutes {self.minutes}: a positive number of minutes")
        if not (self.drive_minutes >= 0.25 and math.isfinite(self.drive_minutes)):
            raise ConfigError(
                f"--drive-minutes {self.drive_minutes}: at least 0.25 (the wild preset's "
                "manoeuvres fall between 5 s and the drive's last 5 s)"
            )
        if self.drives < 1:
            raise ConfigError(f"--drives {self.drives}: at least 1")
        if self.width < 160 or self.height < 90:
            raise ConfigError(f"--resolution {self.width}x{self.height}: at least 160x90")
        if not 5.0 <= self.fps <= 120.0:
            raise ConfigError(f"--fps {self.fps}: 5 to 120 frames per second")

    def key(self, index: int) -> str:
        """Drive ``index``'s folder name in a cache."""
        return (
            f"wild-seed{self.seed + index}-{self.drive_minutes:g}min-"
            f"{self.width}x{self.height}-{self.fps:g}fps"
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

    def __init__(
        self,
        pipeline: Pipeline,
        n_frames: int,
        rss_every_frames: int,
        *,
        watch: tuple[object, ...] = (),
    ) -> None:
        """``watch``: more objects whose containers are sized at the checkpoints (the
        sinks)."""
        self.pipeline = pipeline
        self.watch = (pipeline, *watch)
        self.fusion_clock = CostClock()
        self.detector_clock = CostClock()
        time_calls(pipeline.fusion, FUSION_CALLS, self.fusion_clock)
        time_calls(pipeline.detector, DETECTOR_CALLS, self.detector_clock)
        self.n = 0
        self.t = np.full(n_frames, np.nan)
        #: per frame, ms: columns fusion, detector, frame (CPU), then the same as wall time
        self.ms = np.full((n_frames, 6), np.nan)
        self.every = max(1, rss_every_frames)
        n_rss = n_frames // self.every + 2 + len(CHECKPOINTS)
        self.rss_t = np.full(n_rss, np.nan)
        self.rss = np.full(n_rss, np.nan)
        self.n_rss = 0
        #: frame count -> checkpoint, but the last: taken at the end of input, after the last
        #: frame (``n_frames`` is the frames expected: the drive may end a frame early)
        self.marks = {max(1, math.ceil(q * n_frames)): q for q in CHECKPOINTS[:-1]}
        self.snapshots: dict[float, dict[str, Any]] = {}  #: checkpoint -> what it saw
        self._last_t = math.nan
        self.alerts = 0  #: alerts raised (frames and the end's flush)
        self.mode_changes = 0  #: frames whose fusion mode differs from the previous one's
        self._mode: object = None
        self.failed_t = math.nan  #: the time of the frame whose push raised, if one did

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
        try:
            result = self.pipeline.push(sample)
        except Exception:
            self.failed_t = sample.t_s
            raise
        self.alerts += len(result.alerts)
        if result.mode != self._mode:
            self.mode_changes += self._mode is not None
            self._mode = result.mode
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
            self._snapshot(self.marks[self.n], sample.t_s)
        self._last_t = sample.t_s
        return result

    def finish(self) -> list[Alert]:
        if self.n:
            self._snapshot(CHECKPOINTS[-1], self._last_t)
        tail = self.pipeline.finish()
        self.alerts += len(tail)
        return tail

    def status(self) -> Status:
        return self.pipeline.status()

    def _sample_rss(self, t: float) -> None:
        if self.n_rss < self.rss.size:
            self.rss_t[self.n_rss] = t
            self.rss[self.n_rss] = rss_mb()
            self.n_rss += 1

    def _snapshot(self, checkpoint: float, t: float) -> None:
        self._sample_rss(t)
        self.snapshots[checkpoint] = {
            "t_s": t,
            "rss_mb": rss_mb(),
            "gc_objects": len(gc.get_objects()),
            "containers": {k: v for w in self.watch for k, v in container_sizes(w).items()},
        }


# -- the statistics (pure) -------------------------------------------------------------------
def window_median(
    t: NDArray[np.float64], values: NDArray[np.float64], lo: float, hi: float
) -> float:
    """Median of ``values`` over the frames with ``lo <= t <= hi`` (NaN if none)."""
    sel = (t >= lo) & (t <= hi) & np.isfinite(values)
    return float(np.median(values[sel])) if np.any(sel) else math.nan


def window_costs(
    t: NDArray[np.float64], ms: NDArray[np.float64], window_s: float
) -> list[dict[str, float]]:
    """Per consecutive window of ``window_s`` from the first frame: the window's end (s
    from the first frame) and the median of each cost (`COST_COLUMNS`), ms."""
    if t.size == 0:
        return []
    rel = t - t[0]
    n_win = max(1, math.ceil(float(rel[-1]) / window_s))
    which = np.minimum((rel // window_s).astype(np.int64), n_win - 1)  # the last frame: last
    out = []
    for k in range(n_win):  # windows, not frames
        row = {"end_s": (k + 1) * window_s}
        for name, col in COST_COLUMNS.items():
            v = ms[which == k, col]
            v = v[np.isfinite(v)]
            row[name] = float(np.median(v)) if v.size else math.nan
        out.append(row)
    return out


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
    passes: int  #: drives played (the last one cut at ``minutes``)
    #: one row per checkpoint: fraction, drive time from the first frame (s), RSS (MB), gc
    #: objects, and the median per-frame costs (ms) over the minute before it
    checkpoints: list[dict[str, float]]
    #: median per-frame costs (ms) over the first and the last minute: cost -> (start, end)
    costs: dict[str, tuple[float, float]]
    rss_flat: bool
    rss_spread: float  #: (max - min) / RSS at 10 %
    grown: dict[str, list[int]]
    window_s: float = WINDOW_S  #: the costs' window of drive time
    #: MB per minute of drive: least squares over the RSS samples from the 10 % checkpoint
    rss_slope_mb_min: float = math.nan
    rss_series: list[tuple[float, float]] = field(default_factory=list)  #: (drive s, MB)
    #: per window of drive time (``window_s``, from the first frame): its end (s) and the
    #: median of each cost (ms): the trend between the checkpoints
    window_costs: list[dict[str, float]] = field(default_factory=list)
    alerts: int = 0
    mode_changes: int = 0
    source_errors: dict[str, int] = field(default_factory=dict)
    source_problems: dict[str, int] = field(default_factory=dict)  #: reason -> count
    #: the exception that ended the run before ``minutes`` ('' if none), and the drive time
    #: (s from the first frame) of the frame whose push raised it
    error: str = ""
    error_at_s: float = math.nan
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
    for q in CHECKPOINTS:
        snap = probe.snapshots.get(q)
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
    grown = grown_containers([probe.snapshots[q]["containers"] for q in sorted(probe.snapshots)])
    return rows, costs, bool(spread <= FLAT_WITHIN), spread, grown


def rss_slope(probe: SoakProbe, rows: list[dict[str, float]]) -> float:
    """MB per minute of drive of the RSS samples from the first checkpoint (the warm-up's
    end) on, least squares; NaN with fewer than 3."""
    t, mb = probe.rss_t[: probe.n_rss], probe.rss[: probe.n_rss]
    rel = t - t[0] if t.size else t
    keep = rel >= (rows[0]["drive_s"] if rows else 0.0)
    if np.count_nonzero(keep) < 3:
        return math.nan
    return float(np.polyfit(rel[keep] / 60.0, mb[keep], 1)[0])


# -- the drive -----------------------------------------------------------------------------
class ChainedDrive:
    """Recording folders replayed one after the other, cycling, on one continuous clock,
    until ``duration_s`` of camera frames: a `roadpreview.sources.Source`.

    Each pass reads a folder's video and CAN log as `ReplayInputs.sources` puts them on
    the drive's clock, and moves every sample by the offset that puts the pass's first
    sample one frame interval after the previous pass's last. The seams are cuts (the
    scene, the lead and the speed jump), as a camera switch would be; frame numbers
    run on."""

    live = False

    def __init__(self, folders: list[Path], duration_s: float, config: Any) -> None:
        if not folders:
            raise ConfigError("soak: no recording to replay")
        self.folders = folders
        self.duration_s = duration_s
        self.config = config
        self.name = f"soak drive ({len(folders)} recordings, cycled)"
        self.passes = 0  #: passes that gave at least one frame
        #: per pass begun: the times (on the chain's clock) of its first and last samples
        self.spans: list[tuple[float, float]] = []
        self._lost = 0  #: samples the finished passes' sources lost
        self._problems: Counter[str] = Counter()  #: the finished passes' problem counts
        self._open: list[Source] = []

    @property
    def problems(self) -> Counter[str]:
        """Reason -> count over every pass, from the sources that count their problems
        (the shared per-source contract: ``problems``, a mapping)."""
        out = Counter(self._problems)
        for s in self._open:
            out.update(_problems_of(s))
        return out

    @property
    def errors(self) -> int:
        return self._lost + sum(s.errors for s in self._open)

    def __iter__(self) -> Iterator[Sample]:
        from roadpreview.apps.replay import ReplayInputs
        from roadpreview.sources import merge_sources

        first_t = math.nan
        last_t = -math.inf
        index = 0
        k = 0
        while True:
            folder = self.folders[k % len(self.folders)]
            k += 1
            inputs = ReplayInputs.from_recording(folder)
            video, sources = inputs.sources(self.config)
            gap = 1.0 / video.fps if video.fps > 0 else 0.1
            self._open = list(sources)
            offset = math.nan
            framed = False
            try:
                for sample in merge_sources(sources):
                    if math.isnan(offset):
                        offset = 0.0 if math.isnan(first_t) else last_t + gap - sample.t_s
                        self.spans.append((sample.t_s + offset, sample.t_s + offset))
                    t = sample.t_s + offset
                    if math.isnan(first_t):
                        first_t = t
                    if isinstance(sample, CameraFrame):
                        if t - first_t > self.duration_s:
                            return
                        if not framed:
                            framed = True
                            self.passes += 1
                        yield replace(sample, t_s=t, index=index)
                        index += 1
                    else:
                        yield replace(sample, t_s=t)
                    last_t = t
                    self.spans[-1] = (self.spans[-1][0], t)
            finally:
                self._lost += sum(s.errors for s in self._open)
                for s in self._open:
                    self._problems.update(_problems_of(s))
                    s.close()
                self._open = []
            if math.isnan(offset):  # an empty recording: stop rather than spin
                return

    def close(self) -> None:
        for s in self._open:
            s.close()


def _problems_of(source: object) -> Mapping[str, int]:
    problems = getattr(source, "problems", None)
    return problems if isinstance(problems, Mapping) else {}


def drive_config(options: SoakOptions, index: int) -> Any:
    """Drive ``index`` of the soak (``wild``, seed + index, resized, the CAN log only)."""
    from roadpreview.sim.presets import wild
    from roadpreview.sim.scenario import CameraSpec

    cfg = wild(options.seed + index, duration_s=options.drive_minutes * 60.0)
    cam = cfg.camera
    camera = CameraSpec(
        width=options.width,
        height=options.height,
        vfov_deg=cam.vfov_deg,
        fps=options.fps,
        forward=cam.forward,
    )
    return replace(cfg, camera=camera, output=replace(cfg.output, imu_csv=False))


def _render_one(item: tuple[Any, str]) -> float:
    """Render one drive (a task on the engine); its rendering seconds."""
    from roadpreview.sim.recording import write_recording

    cfg, folder = item
    return write_recording(cfg, folder).seconds


def render_drives(options: SoakOptions, base: Path) -> tuple[list[Path], float]:
    """The soak's drives in ``base`` (rendered on a local Dask cluster, two at a time,
    unless already there) and the CPU-bound seconds spent rendering (summed over the drives)."""
    folders = [base / options.key(i) for i in range(options.drives)]
    todo = [(i, f) for i, f in enumerate(folders) if not (f / "truth.json").is_file()]
    if not todo:
        return folders, 0.0
    from roadpreview.batch.engine import TaskFailure, open_engine

    items = [(drive_config(options, i), str(f)) for i, f in todo]
    seconds = 0.0
    with open_engine(workers=min(2, len(todo)), dashboard=False) as engine:
        keys = [Path(f).name for _, f in items]
        for (_, folder), result in engine.map(
            _render_one, items, keys=keys, label="soak-render", progress=False
        ):
            if isinstance(result, TaskFailure):
                raise RuntimeError(f"{folder}: rendering failed: {result.message}")
            seconds += result
    return folders, seconds


def soak(
    folders: list[Path],
    *,
    options: SoakOptions | None = None,
    window_s: float = WINDOW_S,
    render_s: float = 0.0,
) -> SoakReport:
    """Replay ``folders`` (recording folders, `ChainedDrive`) for ``options.minutes``
    through the pipeline into a CAN log, measuring as the module docstring says."""
    from roadpreview.apps.replay import ReplayInputs
    from roadpreview.loop import run
    from roadpreview.pipeline.config import PipelineConfig
    from roadpreview.sinks.can import CanLogSink, repetition_config

    options = options or SoakOptions()
    config = PipelineConfig()
    inputs = ReplayInputs.from_recording(folders[0])
    drive = ChainedDrive(folders, options.minutes * 60.0, config)
    fps = options.fps
    n_frames = math.floor(options.minutes * 60.0 * fps) + 2
    with tempfile.TemporaryDirectory() as tmp:
        sink = CanLogSink(
            Path(tmp) / "alerts.blf",
            detector=config.anomaly.detector,
            repetition=repetition_config(config),
        )
        pipeline = Pipeline(inputs.camera, config)
        probe = SoakProbe(
            pipeline,
            n_frames,
            rss_every_frames=round(options.rss_every_s * fps),
            watch=(sink,),
        )
        error = ""
        wall0 = time.perf_counter()
        try:
            run(
                [drive],
                probe,
                [sink],
                status_period_s=config.can.status_period_s,
                frame_hold_s=pipeline.frame_hold_s,
            )
        except Exception as exc:  # what ended the drive is the soak's finding: reported
            error = f"{type(exc).__name__}: {exc}"
            log.error("soak: the run ended at frame %d: %s", probe.n, error)
        wall_s = time.perf_counter() - wall0
    rows, costs, flat, spread, grown = summarise(probe, window_s)
    n = min(probe.n, probe.t.size)
    t0 = float(probe.t[0]) if n else math.nan
    return SoakReport(
        window_costs=window_costs(probe.t[:n], probe.ms[:n], window_s),
        options=options,
        frames=probe.n,
        drive_s=float(probe.t[n - 1] - probe.t[0]) if n else 0.0,
        wall_s=wall_s,
        render_s=render_s,
        passes=drive.passes,
        window_s=window_s,
        checkpoints=rows,
        costs=costs,
        rss_flat=flat,
        rss_spread=spread,
        rss_slope_mb_min=rss_slope(probe, rows),
        grown=grown,
        rss_series=[
            (float(a - t0), float(b))
            for a, b in zip(probe.rss_t[: probe.n_rss], probe.rss[: probe.n_rss], strict=True)
        ],
        alerts=probe.alerts,
        mode_changes=probe.mode_changes,
        source_errors={drive.name: drive.errors},
        error=error,
        error_at_s=probe.failed_t - t0 if error else math.nan,
        source_problems=dict(drive.problems),
        fusion_stats=dict(getattr(probe.pipeline.fusion, "stats", {})),
    )


def format_report(report: SoakReport) -> str:
    """The printed table."""
    o = report.options
    win = f"{report.window_s:g} s"
    head = (
        f"roadpreview bench soak: {report.drive_s / 60:.1f} min of simulated driving "
        f"({o.drives} wild drives of {o.drive_minutes:g} min, seeds {o.seed}-"
        f"{o.seed + o.drives - 1}, cycled: {report.passes} passes; {o.width}x{o.height} at "
        f"{o.fps:g} fps, {report.frames} frames) "
        f"replayed in {report.wall_s / 60:.1f} min; costs: CPU ms per frame, medians over the "
        f"{win} of drive before each checkpoint"
    )
    last = "end" if report.error else "100 %"
    rows = [
        [
            last if r["fraction"] == CHECKPOINTS[-1] else f"{100 * r['fraction']:.0f} %",
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
    if report.error:
        lines.append(
            f"THE RUN ENDED EARLY at {report.error_at_s / 60:.2f} min of drive (frame "
            f"{report.frames + 1}), not {o.minutes:g}: {report.error}"
        )
    lines.append(
        f"RSS flat within {100 * FLAT_WITHIN:.0f} %: {'yes' if report.rss_flat else 'NO'} "
        f"(spread {100 * report.rss_spread:.1f} % of the RSS at 10 %); slope from 10 % on "
        f"{report.rss_slope_mb_min:+.3f} MB/min"
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
    drives: int = 3,
    drive_minutes: float = 2.0,
    resolution: str | None = None,
    fps: float | None = None,
    json_path: str | Path | None = None,
    cache: str | Path | None = None,
) -> str:
    """The benchmark's entry (`roadpreview.bench`): render (or reuse from ``cache``) the
    drives, soak them, write the JSON report to ``json_path`` and return the table.
    ``repeats`` does not apply (one long run); ``quick``: 4 minutes."""
    del repeats
    w, h = parse_resolution(resolution) if resolution else (640, 360)
    options = SoakOptions(
        minutes=minutes if minutes is not None else (4.0 if quick else 30.0),
        drives=drives,
        drive_minutes=drive_minutes,
        width=w,
        height=h,
        fps=fps or 15.0,
        seed=seed,
    )
    options.validate()
    with package_logs_at_errors(), _cache_dir(cache) as base:  # 27,000 frames of warnings
        folders, render_s = render_drives(options, base)
        report = soak(folders, options=options, render_s=render_s)
    if json_path is not None:
        Path(json_path).write_text(json.dumps(report.to_json(), indent=1))
    return format_report(report)


@contextmanager
def _cache_dir(cache: str | Path | None) -> Iterator[Path]:
    """Where the drives go: ``cache`` (kept for the next run) or a temporary directory."""
    if cache is not None:
        Path(cache).mkdir(parents=True, exist_ok=True)
        yield Path(cache)
        return
    with tempfile.TemporaryDirectory() as tmp:
        yield Path(tmp)


__all__ = [
    "ChainedDrive",
    "SoakOptions",
    "SoakProbe",
    "SoakReport",
    "container_sizes",
    "format_report",
    "grown_containers",
    "render_drives",
    "rss_mb",
    "run",
    "soak",
    "window_median",
]
