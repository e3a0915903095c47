"""Run every method over the same recordings: one vision pass, one pipeline per method.

Per recording, the reference method's pipeline (`REFERENCE_METHOD`, the
product's fused Kalman) runs the vision front end once per frame; its
`FrameVision` goes to every method's ``Pipeline.push_vision``, and every
pipeline gets the same CAN frames (``push_can``) in time-stamp order, the
streams merged lazily as in ``roadpreview replay``. So the methods differ only
where their configurations do (pitch estimator, fusion back end, heave term).
Each method's per-frame output is kept as a compact `Trace` (.npz) in the run
folder, keyed by the recording,
the method and a digest of the configurations, the package version and the
source of the modules that produce it: a second run reuses it.

Recordings are simulated on demand (deterministic by seed, reused when their
scenario and the simulator's source are unchanged). Work is parallel over
recordings on the Dask engine of ``roadpreview batch`` (`roadpreview.batch.engine`:
a local cluster of single-thread worker processes, or an existing cluster), one
recording (generation + all methods) per task.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Callable, Generator, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from roadpreview import __version__
from roadpreview.anomaly.base import TrajectorySample
from roadpreview.camera import CameraModel
from roadpreview.configtools import to_mapping
from roadpreview.digests import digest, source_digest
from roadpreview.errors import InputDataError, OperationError
from roadpreview.eval.methods import REFERENCE_METHOD, MethodSpec, NanStdFallback, method_config
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pipeline.pipeline import FrameResult, Pipeline
from roadpreview.pitch import PitchEstimator, make_estimator
from roadpreview.sim.scenario import ScenarioConfig
from roadpreview.types import Alert, CameraFrame, FusionMode, Sample, Status

if TYPE_CHECKING:  # the engine imports Dask: only where it runs
    from roadpreview.batch.engine import Engine

log = logging.getLogger(__name__)

Array = NDArray[np.float64]

#: bump when the trace layout or the way traces are produced changes
TRACE_FORMAT = 5
#: sub-packages and modules whose source does not change what a trace holds (the detectors
#: and the preview run on the stored trajectory afterwards; the sinks only write files; the
#: apps compose; the truth matching, the run summary and the CAN output side come after)
_NOT_PIPELINE = (
    "eval",
    "cli",
    "bench",
    "sim",
    "anomaly",
    "preview",
    "sinks",
    "apps",
    "batch",
    "pipeline/truthmatch.py",
    "pipeline/run_summary.py",
    "canbus/output.py",
    "canbus/received.py",
    "canbus/receiver.py",
    "canbus/repetition.py",
)


# -- digests ------------------------------------------------------------------------------------
def pipeline_source_digest() -> str:
    """What the traces depend on besides the configuration: the pipeline's source code."""
    return source_digest(("",), _NOT_PIPELINE)


#: simulator modules a recording does not depend on: a preset only builds the
#: `ScenarioConfig` (which is in the recording's digest itself), the data set module only
#: draws clips from finished recordings
_NOT_RECORDING = ("sim/presets.py", "sim/dataset.py")


#: the modules outside sim/ that a recording is written with (camera model, log and CSV
#: writers, the sample conventions)
_RECORDING_DEPS = (
    "camera.py",
    "types.py",
    "canbus/imu_csv.py",
    "canbus/logio.py",
    "canbus/samples.py",
)


@cache
def _input_messages_digest() -> str:
    """Digest of how the simulator encodes its CAN frames: the DBC's input messages and the
    E2E protection's source. roadpreview's own output messages, and the rest of the DBC
    module, do not change a recording."""
    import inspect

    from roadpreview.canbus import dbc

    rows = [
        (m.frame_id, m.name, m.length, [_signal_layout(s) for s in m.signals])
        for m in dbc.load_database().messages
        if m.frame_id not in dbc.RESERVED_OUTPUT_IDS
    ]
    code = [inspect.getsource(f) for f in (dbc.encode_protected, dbc.e2e_layout)]
    return digest([sorted(rows), code])


def _signal_layout(sig: Any) -> tuple[Any, ...]:
    return (sig.name, sig.start, sig.length, sig.byte_order, sig.is_signed, sig.scale, sig.offset)


def simulator_source_digest() -> str:
    """What a recording depends on besides its scenario: the simulator's source code, the
    modules it writes with and the DBC's input messages."""
    return digest(
        [source_digest(("sim", *_RECORDING_DEPS), _NOT_RECORDING), _input_messages_digest()]
    )


def scenario_digest(cfg: ScenarioConfig, sim: str | None = None) -> str:
    """What a recording of ``cfg`` is: its scenario and the simulator's source."""
    return digest({"scenario": to_mapping(cfg), "sim": sim or simulator_source_digest()})


# -- traces -------------------------------------------------------------------------------------
#: per-frame float columns of a trace: the frame's pipeline state
FLOAT_COLUMNS = (
    "t",
    "y",
    "y_c",
    "phi",
    "phi_std",
    "lead_distance_m",
    "y_left",
    "y_right",
    "heave_px",
    "bias",
    "time_offset",
    "box_x0",
    "box_y0",
    "box_x1",
    "box_y1",
)
#: per-frame integer columns (mode: `FusionMode` value)
INT_COLUMNS = ("mode", "lead_found", "textured", "target_changed")
#: the detector's input (`TrajectorySample`) per frame, stored as ``traj_<field>`` (None ->
#: NaN; mode as its value, valid as 0/1): every detector runs on it afterwards
#: (`roadpreview.eval.detectors`), so the traces do not depend on the detectors
TRAJECTORY_FIELDS = tuple(f.name for f in fields(TrajectorySample) if f.name != "t")


@dataclass(frozen=True)
class Trace:
    """One method's output on one recording, per frame, on the recording's clock
    (0 = the simulation's t = 0, the time base of ``truth.json`` and ``truth.npz``)."""

    method: str
    columns: dict[str, NDArray[Any]]  #: `FLOAT_COLUMNS` + `INT_COLUMNS` + trajectory
    seconds: float = math.nan  #: processing time of this method (its share), s
    focal_px: float = math.nan  #: the camera's focal length (vertical), px

    def __getitem__(self, name: str) -> NDArray[Any]:
        return self.columns[name]

    @property
    def t(self) -> Array:
        return self.columns["t"]

    def __len__(self) -> int:
        return int(self.columns["t"].size)

    def samples(self) -> list[TrajectorySample]:
        """The detector's input per frame, as the pipeline gave it (recording clock)."""
        cols = [self.columns[f"traj_{f}"].tolist() for f in TRAJECTORY_FIELDS]
        out = []
        for t, row in zip(self.t.tolist(), zip(*cols, strict=True), strict=True):
            kw = dict(zip(TRAJECTORY_FIELDS, row, strict=True))
            kw["mode"] = FusionMode(int(kw["mode"]))
            kw["valid"] = bool(kw["valid"])
            for name in ("lead_accel_mps2", "ego_speed_mps"):
                if not math.isfinite(kw[name]):
                    kw[name] = None
            out.append(TrajectorySample(t=t, **kw))
        return out

    def save(self, path: Path) -> None:
        """Write the trace as .npz (atomically: a killed run leaves no half file)."""
        arrays: dict[str, NDArray[Any]] = {f"col_{k}": v for k, v in self.columns.items()}
        arrays["seconds"] = np.asarray(self.seconds)
        arrays["focal_px"] = np.asarray(self.focal_px)
        arrays["method"] = np.asarray(self.method)
        tmp = path.with_name(path.name + ".tmp.npz")
        savez: Any = np.savez_compressed  # numpy's stub types **kwds as allow_pickle
        savez(tmp, **arrays)
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> Trace:
        try:
            with np.load(path, allow_pickle=False) as npz:
                data = {k: npz[k] for k in npz.files}
        except (OSError, ValueError) as exc:
            raise InputDataError(f"{path}: not a readable trace ({exc})") from None
        return cls(
            method=str(data["method"]),
            columns={k[4:]: v for k, v in data.items() if k.startswith("col_")},
            seconds=float(data["seconds"]),
            focal_px=float(data["focal_px"]),
        )


class _TraceRecorder:
    """Collects `FrameResult`s of one pipeline into a `Trace` (one append per frame)."""

    def __init__(self, method: str, t0: float, focal_px: float) -> None:
        self.method = method
        self.t0 = t0
        self.focal_px = focal_px
        names = (*FLOAT_COLUMNS, *INT_COLUMNS, *(f"traj_{f}" for f in TRAJECTORY_FIELDS))
        self.rows: dict[str, list[float]] = {c: [] for c in names}
        self.seconds = 0.0

    def add(self, r: FrameResult) -> None:
        rows = self.rows
        rows["t"].append(r.t - self.t0)
        for c in FLOAT_COLUMNS[1:-4]:
            rows[c].append(getattr(r, c))
        box = r.lead_box if r.lead_box is not None else (math.nan,) * 4
        for c, v in zip(FLOAT_COLUMNS[-4:], box, strict=True):
            rows[c].append(float(v))
        for c in INT_COLUMNS:
            rows[c].append(int(getattr(r, c)))
        sample = r.sample
        for f in TRAJECTORY_FIELDS:
            v = math.nan if sample is None else getattr(sample, f)
            rows[f"traj_{f}"].append(math.nan if v is None else float(v))

    def trace(self) -> Trace:
        cols: dict[str, NDArray[Any]] = {
            c: np.asarray(v, dtype=np.int64 if c in INT_COLUMNS else np.float64)
            for c, v in self.rows.items()
        }
        return Trace(self.method, cols, self.seconds, self.focal_px)


# -- recordings ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class RecordingJob:
    """One recording of the evaluation: its scenario, where it lives, where its traces go."""

    dataset: str  #: data set name (``wild``, ``texture-loss``, ``controlled``, ...)
    name: str  #: recording name within the data set
    scenario: ScenarioConfig
    root: Path  #: the run folder; recording in ``data/<dataset>/<name>``
    #: the simulator's source digest, taken when the job is made (in the parent process)
    sim: str = field(default_factory=lambda: simulator_source_digest(), compare=False)

    @property
    def digest(self) -> str:
        return scenario_digest(self.scenario, self.sim)

    @property
    def folder(self) -> Path:
        return self.root / "data" / self.dataset / self.name

    @property
    def trace_dir(self) -> Path:
        return self.root / "traces" / self.dataset / self.name

    @property
    def key(self) -> str:
        return f"{self.dataset}/{self.name}"

    @property
    def n_frames(self) -> int:
        return round(self.scenario.motion.duration_s * self.scenario.camera.fps)

    @property
    def cost(self) -> float:
        """Relative cost (frames x pixels^0.5, x 1.4 with fog, night or tunnel segments:
        they render and track at about 30 fps where a clear drive runs at 42-45 fps), to
        schedule the longest jobs first."""
        cam = self.scenario.camera
        slow = 1.4 if self.scenario.conditions else 1.0
        return slow * self.n_frames * math.sqrt(cam.width * cam.height)


_META = "eval_recording.json"


def recording_is_current(job: RecordingJob) -> bool:
    """The folder holds a complete recording of exactly this scenario and simulator."""
    try:
        meta = json.loads((job.folder / _META).read_text())
    except (OSError, json.JSONDecodeError):
        return False
    return bool(meta.get("scenario_digest") == job.digest)


def ensure_recording(job: RecordingJob) -> float:
    """Simulate the recording unless it is current; returns the seconds spent (0: reused)."""
    if recording_is_current(job):
        return 0.0
    from roadpreview.sim.recording import write_recording

    t0 = time.perf_counter()
    (job.folder / _META).unlink(missing_ok=True)
    write_recording(job.scenario, job.folder)
    meta = {"scenario_digest": job.digest, "dataset": job.dataset}
    (job.folder / _META).write_text(json.dumps(meta, indent=1))
    return time.perf_counter() - t0


# -- running the methods ------------------------------------------------------------------------
@dataclass(frozen=True)
class MethodSet:
    """The pipelines to run: one configuration per method, and the reference method
    whose pipeline runs the vision front end."""

    configs: dict[str, PipelineConfig]
    reference: str = REFERENCE_METHOD
    #: method -> std for estimates without one (`MethodSpec.nan_std_rad`)
    nan_std: dict[str, float] = field(default_factory=dict)
    #: the pipeline's source digest, taken once when the set is built, so that every
    #: worker of a run and the loading afterwards agree even if the source changes meanwhile
    source: str = field(default_factory=lambda: pipeline_source_digest())

    def __post_init__(self) -> None:
        if self.reference not in self.configs:
            raise InputDataError(
                f"methods: the reference method {self.reference!r} is not among "
                f"{list(self.configs)}"
            )

    @classmethod
    def build(
        cls,
        base: PipelineConfig,
        specs: Mapping[str, MethodSpec],
        reference: str = REFERENCE_METHOD,
    ) -> MethodSet:
        """Each method's configuration derived from ``base`` (`method_config`)."""
        return cls(
            configs={m: method_config(base, spec) for m, spec in specs.items()},
            reference=reference,
            nan_std={m: s.nan_std_rad for m, s in specs.items() if s.nan_std_rad is not None},
        )

    def subset(self, names: Iterable[str]) -> MethodSet:
        """These methods and the reference."""
        keep = set(names) | {self.reference}
        return MethodSet(
            {m: c for m, c in self.configs.items() if m in keep},
            self.reference,
            {m: v for m, v in self.nan_std.items() if m in keep},
            self.source,
        )


def trace_keys(methods: MethodSet, job: RecordingJob) -> dict[str, str]:
    """Cache key per method: its configuration, the reference's (it drives the vision),
    the scenario, the package version and the pipeline's source code."""
    common = {
        "format": TRACE_FORMAT,
        "version": __version__,
        "source": methods.source,
        "scenario": job.digest,
        "reference": _trajectory_settings(methods.configs[methods.reference]),
    }
    return {
        m: digest(
            {**common, "method": _trajectory_settings(cfg), "nan_std": methods.nan_std.get(m)}
        )
        for m, cfg in methods.configs.items()
    }


def _trajectory_settings(cfg: PipelineConfig) -> dict[str, Any]:
    """The settings a trace depends on: all but the detectors' (``[anomaly]``) and the
    preview's (``[preview]``), which run on the stored trajectory afterwards."""
    out: dict[str, Any] = to_mapping(cfg)
    out.pop("anomaly", None)
    out.pop("preview", None)  # computed from the trajectory too, never stored in a trace
    return out


def trace_path(job: RecordingJob, method: str, key: str) -> Path:
    return job.trace_dir / f"{method}-{key}.npz"


class SharedVision:
    """Several pipelines, one per method, driven by the run loop as one stage: the
    reference pipeline's vision front end runs once per frame and its `FrameVision` goes
    to every pipeline's ``push_vision`` (exactly `Pipeline.push` of a frame, split), IMU
    and speed samples go to every pipeline. Each method's frames are recorded as a
    `Trace`; the loop sees the reference's results."""

    def __init__(
        self, pipes: dict[str, Pipeline], reference: str, recorders: dict[str, _TraceRecorder]
    ) -> None:
        self.pipes = pipes
        self.ref = pipes[reference]
        self.reference = reference
        self.recorders = recorders
        self.vision_s = 0.0
        self.input_errors = 0

    def push(self, sample: Sample) -> FrameResult | None:
        if not isinstance(sample, CameraFrame):
            for p in self.pipes.values():
                p.push(sample)
            return None
        clock = time.perf_counter
        c0 = clock()
        fv = self.ref.vision.process(sample.t_s, sample.image, pitch_rad=self.ref.pitch_rad)
        self.vision_s += clock() - c0
        out: FrameResult | None = None
        for m, p in self.pipes.items():
            c1 = clock()
            r = p.push_vision(sample.t_s, fv)
            rec = self.recorders[m]
            rec.seconds += clock() - c1
            rec.add(r)
            if m == self.reference:
                out = r
        return out

    def finish(self) -> list[Alert]:
        return self.ref.finish()

    def status(self) -> Status:
        return self.ref.status()


def run_methods(folder: Path, methods: MethodSet) -> dict[str, Trace]:
    """Every method over one recording folder, sharing the reference's vision pass: the
    replay's sources and the run loop, with `SharedVision` as the stage."""
    from roadpreview.apps.replay import ReplayInputs
    from roadpreview.loop import run

    inputs = ReplayInputs.from_recording(folder)
    reference = methods.reference
    order = [reference, *(m for m in methods.configs if m != reference)]
    video, sources = inputs.sources(methods.configs[reference])
    start = video.start_s
    pipes = {
        m: Pipeline(
            inputs.camera,
            methods.configs[m],
            pitch=_pitch_with_fallback(inputs.camera, methods.configs[m], methods.nan_std.get(m)),
        )
        for m in order
    }
    recorders = {m: _TraceRecorder(m, start, inputs.camera.fy) for m in order}
    stage = SharedVision(pipes, reference, recorders)
    ref = methods.configs[reference]
    run(
        sources,
        stage,
        status_period_s=ref.can.status_period_s,
        frame_hold_s=stage.ref.frame_hold_s,
    )
    if not recorders[reference].rows["t"]:
        raise InputDataError(f"{inputs.video}: no frame could be read")
    for rec in recorders.values():  # the shared vision step, split evenly
        rec.seconds += stage.vision_s / len(recorders)
    return {m: recorders[m].trace() for m in order}


def _pitch_with_fallback(
    camera: CameraModel, cfg: PipelineConfig, nan_std: float | None
) -> PitchEstimator | None:
    """The method's pitch estimator with `NanStdFallback` (None: the pipeline's default)."""
    if nan_std is None:
        return None
    return NanStdFallback(make_estimator(cfg.pitch.estimator, camera, **cfg.pitch.options), nan_std)


@dataclass(frozen=True)
class RecordingOutcome:
    """What one task did (for the progress line and the report's timings)."""

    key: str
    frames: int
    generate_s: float  #: 0: the recording was reused
    evaluate_s: float  #: 0: every trace came from the cache
    methods_run: tuple[str, ...]
    method_seconds: dict[str, float] = field(default_factory=dict)
    generate_cpu_s: float = 0.0  #: CPU time of the simulation (load-independent)
    evaluate_cpu_s: float = 0.0  #: CPU time of the methods

    @property
    def fps(self) -> float:
        return self.frames / self.evaluate_s if self.evaluate_s > 0 else math.nan


def process_recording(
    job: RecordingJob, methods: MethodSet, *, fresh: bool = False
) -> RecordingOutcome:
    """Simulate the recording if needed, then run the methods whose trace is not cached
    (with the reference, which drives the vision) and store their traces."""
    c0 = time.process_time()
    gen_s = ensure_recording(job)
    gen_cpu = time.process_time() - c0 if gen_s > 0 else 0.0
    keys = trace_keys(methods, job)
    missing = [m for m in methods.configs if fresh or not trace_path(job, m, keys[m]).is_file()]
    if not missing:
        return RecordingOutcome(job.key, job.n_frames, gen_s, 0.0, (), generate_cpu_s=gen_cpu)
    t0 = time.perf_counter()
    c0 = time.process_time()
    traces = run_methods(job.folder, methods.subset(missing))
    eval_s = time.perf_counter() - t0
    eval_cpu = time.process_time() - c0
    job.trace_dir.mkdir(parents=True, exist_ok=True)
    for m, tr in traces.items():
        for old in job.trace_dir.glob(f"{m}-*.npz"):  # stale keys of this method
            old.unlink()
        tr.save(trace_path(job, m, keys[m]))
    return RecordingOutcome(
        job.key,
        len(traces[methods.reference]),
        gen_s,
        eval_s,
        tuple(traces),
        {m: tr.seconds for m, tr in traces.items()},
        generate_cpu_s=gen_cpu,
        evaluate_cpu_s=eval_cpu,
    )


def load_traces(job: RecordingJob, methods: MethodSet) -> dict[str, Trace]:
    """The cached traces of a processed recording, one per method."""
    keys = trace_keys(methods, job)
    out = {}
    for m in methods.configs:
        path = trace_path(job, m, keys[m])
        if not path.is_file():
            raise OperationError(f"{path}: no trace (run process_recording first)")
        out[m] = Trace.load(path)
    return out


def _evaluation_task(
    job: RecordingJob, methods: MethodSet, *, fresh: bool = False
) -> RecordingOutcome:
    """`process_recording` as an engine task: the package logs errors only meanwhile (a
    worker's warnings would interleave on the scheduler's terminal with nobody to read
    them; the outcome carries what the run needs) and its level is put back afterwards."""
    pkg = logging.getLogger("roadpreview")
    level = pkg.level
    pkg.setLevel(logging.ERROR)
    try:
        return process_recording(job, methods, fresh=fresh)
    finally:
        pkg.setLevel(level)


def process_all(
    jobs: Sequence[RecordingJob],
    methods: MethodSet,
    *,
    engine: Engine | None = None,
    workers: int = 1,
    fresh: bool = False,
    progress: Callable[[int, int, RecordingOutcome], None] | None = None,
) -> list[RecordingOutcome]:
    """`process_recording` for every job, longest first; returns the outcomes in the jobs'
    order. With an ``engine``: one Dask task per recording there (`roadpreview batch`'s
    execution path). Without one: in this process, one job after the other, when
    ``workers`` is 1; else on a local engine of ``workers`` processes opened for the call.

    ``progress(n, total, outcome)`` is called as each recording completes; when it is
    given, the engine's own progress (Dask's bar, periodic log lines) is left off so that
    one line per recording is all that is printed. A recording whose task failed (it
    raised, or its worker kept dying) is an `OperationError`: every experiment needs every
    recording."""
    keys = [j.key for j in jobs]
    if len(set(keys)) != len(keys):
        raise InputDataError("process_all: two jobs share a recording folder")
    order = sorted(range(len(jobs)), key=lambda i: -jobs[i].cost)
    outcomes: dict[int, RecordingOutcome] = {}
    if engine is None and workers <= 1:
        for n, i in enumerate(order, start=1):
            outcomes[i] = process_recording(jobs[i], methods, fresh=fresh)
            if progress:
                progress(n, len(jobs), outcomes[i])
        return [outcomes[i] for i in range(len(jobs))]
    if engine is None:
        from roadpreview.batch.engine import open_engine

        with open_engine(workers=workers) as local:
            return process_all(jobs, methods, engine=local, fresh=fresh, progress=progress)
    from roadpreview.batch.engine import TaskFailure

    index = {j.key: i for i, j in enumerate(jobs)}
    ordered = [jobs[i] for i in order]
    done = engine.map(
        _evaluation_task,
        ordered,
        keys=[j.key.replace("/", ":") for j in ordered],
        label="evaluate",
        progress=progress is None,
        methods=methods,
        fresh=fresh,
    )
    try:
        for n, (job, result) in enumerate(done, start=1):
            if isinstance(result, TaskFailure):
                raise OperationError(f"evaluate: recording {job.key} failed: {result.message}")
            outcomes[index[job.key]] = result
            if progress:
                progress(n, len(jobs), result)
    finally:
        if isinstance(done, Generator):  # an early failure: release the tasks still queued
            done.close()
    return [outcomes[i] for i in range(len(jobs))]


__all__ = [
    "MethodSet",
    "RecordingJob",
    "RecordingOutcome",
    "Trace",
    "ensure_recording",
    "load_traces",
    "process_all",
    "process_recording",
    "run_methods",
]
