"""``roadpreview evaluate``: every method over the same simulated recordings, the paper's
experiments and ours, and the report (``docs/evaluation.md``). The recordings run as
tasks on the Dask engine ``roadpreview batch`` uses: a local cluster of ``--jobs``
processes, or an existing cluster (``--scheduler``)."""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path
from typing import Any


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "evaluate",
        help="compare every method on simulated data sets and write the evaluation report",
        description=(
            "Simulate the evaluation's data sets (cached), run every method over the same "
            "recordings (one shared vision pass), run the experiments (E1 signal vs distance, "
            "E2 ego bump, E3 FPR vs rotation, E4 Table I + ROC, E5 texture loss / range / lead "
            "time, E6 the product's operating points, E7 the compensation's error budget) and "
            "write results.json, the figures and optionally the Markdown report."
        ),
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="a small, fast configuration (few short drives at 640x360): the test suite's",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="run folder, also the cache of recordings and traces: a second run reuses"
        " them (--fresh recomputes the traces); default: runs/eval, or runs/eval-quick",
    )
    p.add_argument(
        "--report", type=Path, default=None, metavar="FILE", help="write the Markdown report here"
    )
    p.add_argument("--jobs", type=int, default=2, help="local worker processes (one thread each)")
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="use an existing Dask cluster, e.g. tcp://host:8786; default: Dask's"
        " scheduler-address config / DASK_SCHEDULER_ADDRESS, else a local cluster of --jobs"
        " worker processes",
    )
    p.add_argument(
        "--experiments",
        default="all",
        help="comma-separated subset of e1,e2,e3,e4,e5,e6,e7, or all",
    )
    p.add_argument("--seed", type=int, default=0, help="base seed of the data sets")
    p.add_argument("--config", type=Path, help="pipeline configuration (TOML) for every method")
    p.add_argument(
        "--fresh", action="store_true", help="recompute every trace (recordings are reused)"
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roadpreview.errors import ConfigError
    from roadpreview.eval.plan import EvalPlan
    from roadpreview.eval.report.console import headline, table1_text
    from roadpreview.eval.report.markdown import write_report
    from roadpreview.eval.suite import parse_experiments, run_evaluation
    from roadpreview.pipeline.config import PipelineConfig

    if args.jobs < 1:
        raise ConfigError(f"--jobs: must be at least 1, got {args.jobs}")
    experiments = parse_experiments(args.experiments)
    plan = EvalPlan.quick(args.seed) if args.quick else EvalPlan.full(args.seed)
    out = args.out or Path("runs/eval-quick" if args.quick else "runs/eval")
    base = PipelineConfig.load(args.config) if args.config else None
    t0 = time.perf_counter()

    def say(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", flush=True)

    say(f"evaluation ({plan.name}) into {out}")
    results = run_evaluation(
        plan,
        out,
        experiments=experiments,
        jobs=args.jobs,
        scheduler=args.scheduler,
        base_config=base,
        fresh=args.fresh,
        progress=say,
    )
    d = results.data
    if "e4" in d["results"]:
        print("\nTable I (BA and F: mean ± std over the folds; AUC):")
        print(table1_text(d))
    print()
    print(headline(d))
    print(f"\nresults: {out / 'results.json'}, figures: {results.figures_dir}")
    if args.report is not None:
        argv = ["roadpreview", "evaluate", *sys.argv[2:]] if sys.argv[1:2] == ["evaluate"] else []
        command = shlex.join(argv) if argv else ""
        path = write_report(results, args.report, command=command)
        print(f"report: {path}")
    return 0
