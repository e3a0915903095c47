"""One evaluation run: simulate what the plan needs, run every method over it, run the
experiments and draw their figures (`run_experiments`), write ``results.json`` (the report,
`roadpreview.eval.report`, is rendered from it).

    results = run_evaluation(EvalPlan.quick(), "runs/eval-quick", jobs=2)

The recordings run on the Dask engine `roadpreview batch` uses (`roadpreview.batch.engine`):
a local cluster of ``jobs`` worker processes, or an existing cluster (``scheduler``).
"""

from __future__ import annotations

import importlib
import json
import math
import platform
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roadpreview import __version__
from roadpreview.configtools import from_mapping, to_mapping
from roadpreview.errors import ConfigError
from roadpreview.eval import experiments as ex
from roadpreview.eval import figures
from roadpreview.eval.experiments import EvalData
from roadpreview.eval.experiments.budget import e7_budget
from roadpreview.eval.methods import METHODS, REFERENCE_METHOD, select_methods
from roadpreview.eval.metrics import require_sklearn
from roadpreview.eval.plan import EXPERIMENTS, EvalPlan
from roadpreview.eval.preview import preview_errors
from roadpreview.eval.product import e6_product
from roadpreview.eval.provisional import provisional_points
from roadpreview.eval.runner import MethodSet, RecordingOutcome, process_all
from roadpreview.fusion import BACKENDS
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pitch import ESTIMATORS

if TYPE_CHECKING:  # the engine imports Dask: only where it runs
    from roadpreview.batch.engine import Engine

Progress = Callable[[str], None]


@dataclass
class EvalResults:
    """Everything a run measured (JSON-ready in ``data``) and where it went."""

    out: Path
    data: dict[str, Any] = field(default_factory=dict)

    @property
    def figures_dir(self) -> Path:
        return self.out / "figures"

    def save(self) -> Path:
        path = self.out / "results.json"
        path.write_text(json.dumps(_clean(self.data), indent=1))
        return path

    @classmethod
    def load(cls, out: str | Path) -> EvalResults:
        out = Path(out)
        return cls(out, json.loads((out / "results.json").read_text()))


def _clean(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if hasattr(x, "item") and callable(x.item):  # numpy scalars
        return _clean(x.item())
    return x


def component_settings(
    registry: Mapping[str, tuple[str, str, str | None]],
    name: str,
    options: Mapping[str, Any],
    config_module: str | None = None,
) -> dict[str, Any]:
    """Every setting of a registered component (its config dataclass with ``options``
    applied, defaults included), for the report."""
    module_name, _, cfg_name = registry[name]
    if cfg_name is None:
        return {}
    holder = importlib.import_module(config_module or module_name)
    cfg = from_mapping(getattr(holder, cfg_name), dict(options), where=name)
    out: dict[str, Any] = to_mapping(cfg)
    return out


def _git_commit() -> str | None:
    """The checkout's commit (short hash, "+dirty" with local changes) when the package runs
    from a git working tree; None otherwise (an installed wheel)."""
    import subprocess

    root = str(Path(__file__).resolve().parents[3])

    def git(*args: str) -> str:
        done = subprocess.run(
            ["git", "-C", root, *args], capture_output=True, text=True, timeout=10, check=True
        )
        return done.stdout.strip()

    try:
        rev = git("rev-parse", "--short", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no")
    except (OSError, subprocess.SubprocessError):
        return None
    return rev + ("+dirty" if dirty else "") if rev else None


def _open_engine(scheduler: str | None, jobs: int) -> Engine | None:
    """The engine of the run: the cluster at ``scheduler`` or at Dask's configured
    ``scheduler-address`` (``jobs`` does not apply there), else a local cluster of ``jobs``
    workers; None (this process) for one job and no cluster."""
    import dask

    from roadpreview.batch.engine import open_engine

    address = scheduler or dask.config.get("scheduler-address", None)
    if address:
        return open_engine(str(address))
    if jobs > 1:
        return open_engine(workers=jobs)
    return None


def _worker_count(engine: Engine) -> int:
    """The workers the recordings ran on: a local cluster's own, an existing cluster's at
    the end of the run (workers may have joined since it was connected)."""
    if engine.local:
        return engine.workers
    return len(engine.client.scheduler_info().get("workers", {})) or engine.workers


def parse_experiments(text: str | None) -> tuple[str, ...]:
    """``"e1,e4"`` -> ("e1", "e4"); None or "all": every experiment."""
    if not text or text == "all":
        return EXPERIMENTS
    names = tuple(dict.fromkeys(p.strip().lower() for p in text.split(",") if p.strip()))
    unknown = [n for n in names if n not in EXPERIMENTS]
    if unknown:
        raise ConfigError(f"--experiments: unknown {unknown}; choose from {','.join(EXPERIMENTS)}")
    return tuple(n for n in EXPERIMENTS if n in names)


def run_experiments(
    data: EvalData,
    fig_dir: Path,
    experiments: Sequence[str] = EXPERIMENTS,
    *,
    default_threshold_px: float = 1.0,
) -> dict[str, Any]:
    """Each experiment of ``experiments`` on ``data``, its figure drawn into ``fig_dir``:
    ``results.json``'s ``results`` (the result's ``as_dict()`` with its figure's file
    name). ``default_threshold_px``: E3's common threshold (the configured one)."""
    res: dict[str, Any] = {}

    def with_figure(numbers: dict[str, Any], name: str) -> dict[str, Any]:
        return {**numbers, "figure": name}

    if "e4" in experiments:
        t1 = ex.table1(data)
        res["e4"] = with_figure(t1.as_dict(), figures.plot_roc(t1, fig_dir / "e4_roc.png"))
    thresholds = ex.thresholds_of(data) if {"e3", "e5"} & set(experiments) else {}
    if "e1" in experiments:
        e1 = ex.signal_vs_distance(data)
        path = fig_dir / "e1_signal_vs_distance.png"
        res["e1"] = with_figure(e1.as_dict(), figures.plot_signal_vs_distance(e1, path))
    if "e2" in experiments:
        e2 = ex.ego_bump(data)
        res["e2"] = with_figure(
            e2.as_dict(), figures.plot_ego_bump(e2, fig_dir / "e2_ego_bump.png")
        )
    if "e3" in experiments:
        e3 = ex.fpr_vs_rotation(data, thresholds, default_threshold_px)
        path = fig_dir / "e3_fpr_vs_rotation.png"
        res["e3"] = with_figure(e3.as_dict(), figures.plot_fpr_vs_rotation(e3, path))
    if "e5" in experiments:
        tl = ex.texture_loss(data, thresholds)
        rng = ex.detection_range(data)
        lt = ex.lead_time(data)
        res["e5"] = {
            "texture_loss": with_figure(
                tl.as_dict(), figures.plot_texture_loss(tl, fig_dir / "e5_texture_loss.png")
            ),
            "range": with_figure(rng.as_dict(), figures.plot_range(rng, fig_dir / "e5_range.png")),
            "lead_time": with_figure(
                lt.as_dict(), figures.plot_lead_time(lt, fig_dir / "e5_lead_time.png")
            ),
        }
    if "e6" in experiments:
        e6 = e6_product(data)
        ref = data.methods.configs[data.methods.reference]
        if data.product_detector == "two-axle" and ref.anomaly.two_axle.provisional:
            e6["provisional"] = provisional_points(data)
        if ref.preview.enabled:
            e6["preview"] = preview_errors(data)
        if "calibration" in e6:
            e6["reliability_figure"] = figures.plot_reliability(
                e6["calibration"], fig_dir / "e6_reliability.png"
            )
        res["e6"] = e6
    if "e7" in experiments:
        res["e7"] = e7_budget(data)
    return res


def run_evaluation(
    plan: EvalPlan,
    out: str | Path,
    *,
    experiments: Sequence[str] = EXPERIMENTS,
    jobs: int = 2,
    scheduler: str | None = None,
    base_config: PipelineConfig | None = None,
    methods: Sequence[str] | None = None,
    fresh: bool = False,
    progress: Progress | None = None,
) -> EvalResults:
    """Simulate and process the recordings the experiments need, run them, save results.

    The recordings run as tasks on the Dask engine of ``roadpreview batch``: the cluster at
    ``scheduler`` (or Dask's ``scheduler-address`` setting) when there is one, else a local
    cluster of ``jobs`` single-thread processes; with ``jobs`` 1 and no cluster, in this
    process. The engine is closed once the recordings are done (the experiments run here)."""
    t_start = time.perf_counter()
    require_sklearn()  # before the long part: the experiments' ROC, AUC and folds need it
    plan.validate()
    exps = tuple(e for e in EXPERIMENTS if e in experiments)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    base = base_config or PipelineConfig()
    specs = select_methods(list(methods) if methods is not None else None)
    if REFERENCE_METHOD not in specs:
        specs = {REFERENCE_METHOD: METHODS[REFERENCE_METHOD], **specs}
    mset = MethodSet.build(base, specs)
    say = progress or (lambda _msg: None)
    job_sets = plan.jobs(out, exps)
    all_jobs = [j for js in job_sets.values() for j in js]
    say(
        f"{len(all_jobs)} recordings ({', '.join(f'{k}: {len(v)}' for k, v in job_sets.items())}),"
        f" {len(mset.configs)} methods"
    )

    def on_done(n: int, total: int, o: RecordingOutcome) -> None:
        parts = []
        if o.generate_s > 0:
            parts.append(f"simulated in {o.generate_s:.1f} s ({o.frames / o.generate_s:.0f} fps)")
        if o.evaluate_s > 0:
            parts.append(f"{len(o.methods_run)} methods in {o.evaluate_s:.1f} s ({o.fps:.0f} fps)")
        say(f"[{n}/{total}] {o.key}: {o.frames} frames, " + (", ".join(parts) or "cached"))

    t_proc = time.perf_counter()
    engine = _open_engine(scheduler, jobs)
    if engine is None:
        say("in this process (one job, no cluster)")
        workers, where = 1, "in-process"
        outcomes = process_all(all_jobs, mset, fresh=fresh, progress=on_done)
    else:
        with engine:
            where = engine.describe()
            say(where)
            outcomes = process_all(all_jobs, mset, engine=engine, fresh=fresh, progress=on_done)
            workers = _worker_count(engine)
    proc_s = time.perf_counter() - t_proc

    data = EvalData(plan=plan, methods=mset, jobs=job_sets)
    t_exp = time.perf_counter()
    res = run_experiments(
        data, out / "figures", exps, default_threshold_px=base.anomaly.std.threshold_px
    )
    exp_s = time.perf_counter() - t_exp

    frames_gen = sum(o.frames for o in outcomes if o.generate_s > 0)
    frames_eval = sum(o.frames for o in outcomes if o.evaluate_s > 0)
    method_s: dict[str, float] = {}
    for o in outcomes:
        for m, s in o.method_seconds.items():
            method_s[m] = method_s.get(m, 0.0) + s
    results = EvalResults(out)
    results.data = {
        "plan": plan.as_dict(),
        "experiments": list(exps),
        "version": __version__,
        "git_commit": _git_commit(),
        "pipeline_source": mset.source,
        "python": platform.python_version(),
        "methods": {
            m: {
                "label": specs[m].label,
                "estimator": specs[m].estimator,
                "backend": specs[m].backend,
                "compensated": specs[m].compensated,
                "nan_std_rad": specs[m].nan_std_rad,
                "heave": (
                    bool(mset.configs[m].heave.enabled)
                    if hasattr(mset.configs[m], "heave")
                    else None
                ),
                "pitch": to_mapping(mset.configs[m].pitch),
                "fusion": to_mapping(mset.configs[m].fusion),
                "pitch_settings": component_settings(
                    ESTIMATORS, specs[m].estimator, mset.configs[m].pitch.options
                ),
                "fusion_settings": component_settings(
                    BACKENDS,
                    specs[m].backend,
                    mset.configs[m].fusion.options,
                    "roadpreview.fusion.config",
                ),
            }
            for m in mset.configs
        },
        "detector": to_mapping(base.anomaly.std),
        "anomaly": to_mapping(base.anomaly),
        "alert": to_mapping(base.anomaly.alert),
        "vision": to_mapping(base.vision),
        "heave_settings": to_mapping(base.heave) if hasattr(base, "heave") else None,
        "datasets": {
            name: {
                "recordings": [j.name for j in js],
                "seeds": [j.scenario.seed for j in js],
                "size": [js[0].scenario.camera.width, js[0].scenario.camera.height] if js else None,
                "duration_s": [j.scenario.motion.duration_s for j in js],
                "frames": sum(j.n_frames for j in js),
            }
            for name, js in job_sets.items()
        },
        "timing": {
            "wall_s": time.perf_counter() - t_start,
            "processing_wall_s": proc_s,
            "experiments_wall_s": exp_s,
            "workers": workers,
            "engine": where,
            "frames_simulated": frames_gen,
            "frames_evaluated": frames_eval,
            "simulate_wall_s": sum(o.generate_s for o in outcomes),
            "evaluate_wall_s": sum(o.evaluate_s for o in outcomes),
            "simulate_cpu_s": sum(o.generate_cpu_s for o in outcomes),
            "evaluate_cpu_s": sum(o.evaluate_cpu_s for o in outcomes),
            "simulate_cpu_ms_per_frame": 1000 * sum(o.generate_cpu_s for o in outcomes) / frames_gen
            if frames_gen
            else None,
            "evaluate_cpu_ms_per_frame": 1000
            * sum(o.evaluate_cpu_s for o in outcomes)
            / frames_eval
            if frames_eval
            else None,
            "method_cpu_s": method_s,
        },
        "results": res,
    }
    results.save()
    return results
