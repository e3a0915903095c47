"""``roadpreview bench NAME``: run a benchmark and print its table."""

from __future__ import annotations

import argparse
from typing import Any

from roadpreview.bench import BENCHMARKS, run_benchmark


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "bench",
        help="speed benchmarks (medians over repeats, ratios measured in one run)",
        description="Speed benchmarks. Each prints a table; ratios are measured in one run.",
    )
    p.add_argument("name", choices=[*BENCHMARKS, "all"], help="which benchmark")
    p.add_argument(
        "--repeats", type=int, default=None, help="repeats per case; default: each bench's own"
    )
    p.add_argument("--quick", action="store_true", help="fewer repeats and sizes (smoke run)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the synthetic inputs")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    names = list(BENCHMARKS) if args.name == "all" else [args.name]
    for name in names:
        print(run_benchmark(name, repeats=args.repeats, quick=args.quick, seed=args.seed))
        print()
    return 0
