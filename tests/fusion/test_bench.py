"""``roadpreview bench fusion`` runs and prints its table (no timing is asserted)."""

from __future__ import annotations

from roadpreview.bench import BENCHMARKS, run_benchmark
from roadpreview.fusion import BACKENDS


def test_fusion_benchmark_table() -> None:
    assert BENCHMARKS["fusion"] == "roadpreview.bench.fusion"
    table = run_benchmark("fusion", repeats=1, quick=True, seed=1)
    lines = table.splitlines()
    assert "IMU samples/s" in lines[1]
    for name in BACKENDS:
        assert any(line.startswith(name) for line in lines[3:])
