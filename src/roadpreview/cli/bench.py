"""``roadpreview bench NAME``: run a benchmark and print its table."""

from __future__ import annotations

import argparse
from typing import Any

from roadpreview.bench import BENCHMARKS, LONG, run_benchmark


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "bench",
        help="speed benchmarks (medians over repeats, ratios measured in one run)",
        description="Speed benchmarks. Each prints a table; ratios are measured in one run. "
        f"'all' runs every one but {', '.join(sorted(LONG))} (tens of minutes).",
    )
    p.add_argument("name", choices=[*BENCHMARKS, "all"], help="which benchmark")
    p.add_argument(
        "--repeats", type=int, default=None, help="repeats per case; default: each bench's own"
    )
    p.add_argument("--quick", action="store_true", help="fewer repeats and sizes (smoke run)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the synthetic inputs")
    soak = p.add_argument_group("soak", "options of 'roadpreview bench soak' (docs/robustness.md)")
    soak.add_argument(
        "--minutes",
        type=float,
        default=30.0,
        metavar="MIN",
        help="minutes of driving the pipeline sees (--quick: 4)",
    )
    soak.add_argument(
        "--drives", type=int, default=3, help="distinct simulated drives, cycled to fill --minutes"
    )
    soak.add_argument(
        "--drive-minutes", type=float, default=2.0, metavar="MIN", help="minutes of each drive"
    )
    soak.add_argument(
        "--resolution", default="640x360", metavar="WxH", help="camera size of the drive, px"
    )
    soak.add_argument("--fps", type=float, default=15.0, help="camera frames per second")
    soak.add_argument(
        "--json", default="soak.json", metavar="PATH", help="where the JSON report goes"
    )
    soak.add_argument(
        "--cache",
        default=None,
        metavar="DIR",
        help="keep the rendered drive(s) in DIR and reuse them, also for 'bench batch' and"
        " 'bench status'"
        " (default: render into a temporary folder)",
    )
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    names = [n for n in BENCHMARKS if n not in LONG] if args.name == "all" else [args.name]
    for name in names:
        options: dict[str, object] = {}
        if name == "soak":
            options = {
                "minutes": None if args.quick and args.minutes == 30.0 else args.minutes,
                "drives": args.drives,
                "drive_minutes": args.drive_minutes,
                "resolution": args.resolution,
                "fps": args.fps,
                "json_path": args.json,
                "cache": args.cache,
            }
        elif name in ("batch", "status"):
            options = {"cache": args.cache}
        print(
            run_benchmark(name, repeats=args.repeats, quick=args.quick, seed=args.seed, **options)
        )
        print()
    return 0
