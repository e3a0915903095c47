"""Benchmarks behind ``roadpreview bench``: medians over repeats, ratios from one run.

Each benchmark module exposes ``run(repeats, quick, seed) -> str`` returning
the printed table (a benchmark with options of its own takes them as keywords).
Modules are imported lazily by name.
"""

from __future__ import annotations

import importlib

#: benchmark name -> module
BENCHMARKS: dict[str, str] = {
    "pitch": "roadpreview.bench.pitch",
    "sim": "roadpreview.bench.sim",
    "vision": "roadpreview.bench.vision",
    "fusion": "roadpreview.bench.fusion",
    "detector": "roadpreview.bench.detector",
    "pipeline": "roadpreview.bench.pipeline",
    "soak": "roadpreview.bench.soak",
    "batch": "roadpreview.bench.batch",
    "status": "roadpreview.bench.status",
}

#: not run by ``roadpreview bench all``: they take many minutes (the soak's 30 min drive;
#: the batch's eight 720p drives, replayed three ways, three times)
LONG: frozenset[str] = frozenset({"soak", "batch"})


def run_benchmark(
    name: str,
    *,
    repeats: int | None = None,
    quick: bool = False,
    seed: int = 0,
    **options: object,
) -> str:
    """Run benchmark ``name`` and return its printed table; ``options``: the benchmark's
    own keywords (the soak's ``minutes``, ``resolution``, ...)."""
    module = importlib.import_module(BENCHMARKS[name])
    return str(module.run(repeats=repeats, quick=quick, seed=seed, **options))
