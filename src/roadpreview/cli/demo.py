"""``roadpreview demo``: the main job end to end on the built-in default.

Until the streaming pipeline exists this runs the pitch benchmark, the first
end-to-end capability (synthetic scene -> robust pitch -> accuracy and speed).
"""

from __future__ import annotations

import argparse
from typing import Any


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("demo", help="run the built-in demo")
    p.add_argument("--seed", type=int, default=0, help="random seed")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roadpreview.bench import run_benchmark

    print(run_benchmark("pitch", quick=False, seed=args.seed))
    return 0
