"""``roadpreview bench batch``: the fleet replay's speed-up with workers, and the cost of
the engine against a plain replay.

Eight simulated ``demo`` drives (distinct seeds; 10 s at 1280x720 and 30 fps, or 4 s at
640x360 with ``--quick``) are replayed, in each repeat and in the same run:

* **plain**: one after the other in this process (`roadpreview.apps.replay.replay`, every
  output file written, as a batch drive writes them);
* **1 worker**: ``run_batch`` on a `LocalCluster` of one single-thread worker process;
* **2 workers**: the same on two.

Each batch run starts from an empty output folder (nothing to skip). Reported: the wall
time of the drives (``run_batch``: tasks, fleet tables, report) and of the whole job
(cluster start and shutdown included), medians over repeats; the speed-up 1 -> 2
workers; the engine's overhead per drive: the tasks' time on the 1-worker cluster
against the plain replays of the same repeat, pooled over the drives (median over
repeats) and drive by drive (median over drives and repeats);
the whole batch against the plain replays; and the frames per second per worker, the
input of the capacity estimate in ``docs/batch.md``.
"""

from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

from roadpreview.bench._timing import format_table, package_logs_at_errors

N_DRIVES = 8


def _drives(root: Path, seed: int, quick: bool) -> list[Path]:
    """The eight recordings (rendered once; reused from ``root`` when there)."""
    from roadpreview.sim.dataset import drive_config
    from roadpreview.sim.recording import write_recording

    seconds, (w, h) = (4.0, (640, 360)) if quick else (10.0, (1280, 720))
    folders = []
    for i in range(N_DRIVES):
        folder = root / f"demo_{w}x{h}_{seconds:.0f}s_seed{seed + i}"
        if not (folder / "truth.json").is_file():
            cfg = drive_config("demo", seed + i, duration_s=seconds, width=w, height=h)
            cfg = replace(cfg, output=replace(cfg.output, imu_csv=False))
            shutil.rmtree(folder, ignore_errors=True)
            write_recording(cfg, folder)
        folders.append(folder)
    return folders


def _plain(folders: list[Path], out: Path) -> dict[str, float]:
    """Each drive's replay wall time in this process, s (outputs written)."""
    from roadpreview.apps.replay import ReplayInputs, replay
    from roadpreview.pipeline.config import PipelineConfig

    times = {}
    for folder in folders:
        t0 = time.perf_counter()
        replay(ReplayInputs.from_recording(folder), PipelineConfig(), out / folder.name)
        times[folder.name] = time.perf_counter() - t0
    return times


@dataclass
class _BatchRun:
    drives_s: float  #: run_batch's wall time (tasks, tables, report)
    job_s: float  #: with the cluster's start and shutdown
    task_s: dict[str, float]  #: each drive's task wall time on its worker
    frames: int


def _batch(folders: list[Path], out: Path, workers: int) -> _BatchRun:
    from roadpreview.batch.drive import BatchSettings
    from roadpreview.batch.engine import open_engine
    from roadpreview.batch.fleet import run_batch
    from roadpreview.batch.manifest import DriveSpec
    from roadpreview.digests import replay_source_digest
    from roadpreview.pipeline.config import PipelineConfig

    specs = [DriveSpec(f.name, f) for f in folders]
    settings = BatchSettings(out, PipelineConfig(), replay_source_digest())
    t0 = time.perf_counter()
    with open_engine(workers=workers, dashboard=False) as engine:
        result = run_batch(specs, settings, engine, progress=False)
    job = time.perf_counter() - t0
    bad = [f"{o.drive}: {o.message}" for o in result.failed]
    if bad:
        raise RuntimeError(f"bench batch: drives failed: {bad}")
    return _BatchRun(
        result.seconds,
        job,
        {o.drive: o.task_s for o in result.outcomes},
        sum(o.frames for o in result.outcomes),
    )


def run(
    repeats: int | None = None,
    quick: bool = False,
    seed: int = 0,
    cache: str | None = None,
) -> str:
    repeats = repeats or (1 if quick else 3)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    plain: list[dict[str, float]] = []
    runs: dict[int, list[_BatchRun]] = {1: [], 2: []}
    with package_logs_at_errors(), tempfile.TemporaryDirectory() as tmp:
        root = Path(cache) if cache else Path(tmp) / "drives"
        root.mkdir(parents=True, exist_ok=True)
        folders = _drives(root, seed, quick)
        _plain(folders[:1], Path(tmp) / "warm-up")  # this process's imports, once
        for r in range(repeats):
            plain.append(_plain(folders, Path(tmp) / f"plain{r}"))
            for workers in (1, 2):
                runs[workers].append(_batch(folders, Path(tmp) / f"w{workers}_{r}", workers))
    frames = runs[1][0].frames
    med = statistics.median
    p = med(sum(t.values()) for t in plain)
    drives = {w: med(x.drives_s for x in v) for w, v in runs.items()}
    jobs = {w: med(x.job_s for x in v) for w, v in runs.items()}
    # per drive: its task on the 1-worker cluster against its plain replay, same repeat
    ratios = [
        run.task_s[d] / times[d] - 1.0
        for run, times in zip(runs[1], plain, strict=True)
        for d in times
    ]
    per_drive = med(ratios)
    # the same, pooled: all tasks' time against all plain replays', per repeat
    pooled = med(
        sum(run.task_s.values()) / sum(times.values()) - 1.0
        for run, times in zip(runs[1], plain, strict=True)
    )
    whole = drives[1] / p - 1.0
    speedup = drives[1] / drives[2]
    rows = [["plain replay, in process", f"{p:.1f}", f"{p:.1f}", f"{frames / p:.1f}", "-"]]
    for w in (1, 2):
        rows.append(
            [
                f"batch, {w} worker(s)",
                f"{drives[w]:.1f}",
                f"{jobs[w]:.1f}",
                f"{frames / drives[w]:.1f}",
                f"{drives[1] / drives[w]:.2f}",
            ]
        )
    head = (
        f"roadpreview bench batch: {N_DRIVES} simulated 'demo' drives, {frames} frames in all"
        f" ({folders[0].name.split('_seed')[0]}), {cores} core(s), median of {repeats}"
        " repeat(s). drives = wall time of run_batch (tasks, tables, report); job = with the"
        " cluster's start and shutdown."
    )
    table = format_table(["run", "drives s", "job s", "fps", "speed-up vs 1 worker"], rows)
    verdict = "\n".join(
        [
            f"speed-up 1 -> 2 workers: {speedup:.2f}x (target >= 1.7x:"
            f" {'met' if speedup >= 1.7 else 'NOT met'})",
            f"engine overhead per drive, pooled (all tasks on the worker / all plain replays"
            f" - 1, median of {repeats} repeat(s)): {100 * pooled:+.1f} % (target <= 10 %:"
            f" {'met' if pooled <= 0.10 else 'NOT met'}); drive by drive (median of"
            f" {len(ratios)} pairs): {100 * per_drive:+.1f} %",
            f"whole batch on 1 worker / plain replays - 1 (scheduling, the fleet tables and"
            f" report): {100 * whole:+.1f} %; with the cluster's start:"
            f" {100 * (jobs[1] / p - 1):+.1f} %",
            f"replay speed per worker: {frames / drives[1]:.1f} frames/s",
        ]
    )
    return f"{head}\n\n{table}\n\n{verdict}"
