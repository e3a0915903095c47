"""``roadpreview bench batch``: the fleet replay's speed-up with workers, and the cost of
the engine against a plain replay.

Eight simulated ``demo`` drives (distinct seeds; 10 s at 1280x720 and 30 fps, or 4 s at
640x360 with ``--quick``) are replayed, in each repeat and in the same run:

* **plain**: one after the other in this process (`roadpreview.apps.replay.replay`, every
  output file written, as a batch drive writes them);
* **1 worker**: ``run_batch`` on a `LocalCluster` of one single-thread worker process;
* **2 workers**: the same on two.

Each batch run starts from an empty output folder (nothing to skip). Reported: the wall
time of the drives (``run_batch``) and of the whole job (cluster start and shutdown
included), medians over repeats; the speed-up 1 -> 2 workers; the engine's overhead per
drive: 1-worker batch time / plain time - 1; and the frames per second per worker, the
input of the capacity estimate in ``docs/batch.md``.
"""

from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
from dataclasses import replace
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


def _plain(folders: list[Path], out: Path) -> tuple[float, int]:
    from roadpreview.apps.replay import ReplayInputs, replay
    from roadpreview.pipeline.config import PipelineConfig

    frames = 0
    t0 = time.perf_counter()
    for folder in folders:
        result = replay(ReplayInputs.from_recording(folder), PipelineConfig(), out / folder.name)
        frames += result.frames
    return time.perf_counter() - t0, frames


def _batch(folders: list[Path], out: Path, workers: int) -> tuple[float, float, int, str]:
    """(drives' wall time, whole job's wall time, frames, engine description)."""
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
        described = engine.describe()
    whole = time.perf_counter() - t0
    bad = [f"{o.drive}: {o.message}" for o in result.failed]
    if bad:
        raise RuntimeError(f"bench batch: drives failed: {bad}")
    return result.seconds, whole, sum(o.frames for o in result.outcomes), described


def run(
    repeats: int | None = None,
    quick: bool = False,
    seed: int = 0,
    cache: str | None = None,
) -> str:
    repeats = repeats or (1 if quick else 3)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    plain_s: list[float] = []
    runs: dict[int, list[tuple[float, float]]] = {1: [], 2: []}
    frames = 0
    with package_logs_at_errors(), tempfile.TemporaryDirectory() as tmp:
        root = Path(cache) if cache else Path(tmp) / "drives"
        root.mkdir(parents=True, exist_ok=True)
        folders = _drives(root, seed, quick)
        for r in range(repeats):
            dt, frames = _plain(folders, Path(tmp) / f"plain{r}")
            plain_s.append(dt)
            for workers in (1, 2):
                drives_s, whole_s, n, _ = _batch(folders, Path(tmp) / f"w{workers}_{r}", workers)
                if n != frames:
                    raise RuntimeError(f"bench batch: {n} frames with the engine, {frames} plain")
                runs[workers].append((drives_s, whole_s))
    p = statistics.median(plain_s)
    med = {w: tuple(statistics.median(x[i] for x in v) for i in (0, 1)) for w, v in runs.items()}
    rows = [["plain replay, in process", f"{p:.1f}", f"{p:.1f}", f"{frames / p:.1f}", "-", "-"]]
    for w in (1, 2):
        d, whole = med[w]
        rows.append(
            [
                f"batch, {w} worker(s)",
                f"{d:.1f}",
                f"{whole:.1f}",
                f"{frames / d:.1f}",
                f"{med[1][0] / d:.2f}",
                f"{100 * (d / p - 1):+.1f} %" if w == 1 else "-",
            ]
        )
    head = (
        f"roadpreview bench batch: {N_DRIVES} simulated 'demo' drives, {frames} frames in all"
        f" ({folders[0].name.split('_seed')[0]}), {cores} core(s), median of {repeats}"
        " repeat(s). drives = wall time of run_batch (tasks + tables + report); job = with"
        " the cluster's start and shutdown. overhead = 1-worker drives / plain - 1."
    )
    table = format_table(
        ["run", "drives s", "job s", "fps", "speed-up vs 1 worker", "engine overhead"], rows
    )
    speedup = med[1][0] / med[2][0]
    overhead = med[1][0] / p - 1
    verdict = (
        f"speed-up 1 -> 2 workers {speedup:.2f}x (target >= 1.7x: "
        f"{'met' if speedup >= 1.7 else 'NOT met'}); engine overhead per drive "
        f"{100 * overhead:+.1f} % (target <= 10 %: {'met' if overhead <= 0.10 else 'NOT met'}); "
        f"replay speed per worker {frames / med[1][0]:.1f} fps"
    )
    return f"{head}\n\n{table}\n\n{verdict}"
