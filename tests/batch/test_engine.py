"""The engine under `roadpreview batch` and `evaluate`: workers with one thread, OpenCV
and BLAS pinned, a memory limit; a task whose worker keeps dying comes back as a
`TaskFailure`, not an exception that ends the batch."""

from __future__ import annotations

import os
from typing import Any

import dask
import pytest

from roadpreview.batch.engine import TaskFailure, open_engine

pytestmark = pytest.mark.slow


def _threads(_: int) -> dict[str, Any]:
    import cv2
    from threadpoolctl import threadpool_info

    return {
        "cv2": cv2.getNumThreads(),
        "blas": [p["num_threads"] for p in threadpool_info()],
        "omp_env": os.environ.get("OMP_NUM_THREADS"),
        "malloc_trim": os.environ.get("MALLOC_TRIM_THRESHOLD_"),
    }


def _die_on_odd(n: int) -> int:
    if n % 2:
        os._exit(3)  # the worker process dies, as on a segfault or the OOM killer
    return n


def test_workers_are_pinned_bounded_and_a_dying_task_is_reported() -> None:
    # one death is enough to give up on a task here (Dask's default allows 3 retries)
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 0}),
        open_engine(workers=1, memory_limit="1.5GiB") as engine,
    ):
        (info,) = engine.client.scheduler_info()["workers"].values()
        assert info["nthreads"] == 1
        assert info["memory_limit"] == int(1.5 * 2**30)
        results = dict(engine.map(_threads, [0], keys=["t"], label="pin", progress=False))
        pinned = results[0]
        assert not isinstance(pinned, TaskFailure)
        assert pinned["cv2"] == 1
        assert set(pinned["blas"]) <= {1}
        assert pinned["omp_env"] == "1"
        assert pinned["malloc_trim"] is None  # glibc's adaptive mmap threshold kept
        ((_, failed),) = engine.map(_die_on_odd, [1], keys=["1"], label="die", progress=False)
        assert isinstance(failed, TaskFailure)
        assert "worker died 1 time(s)" in failed.message
        # the nanny started a new worker: the next task runs
        assert list(engine.map(_die_on_odd, [2], keys=["2"], label="die", progress=False)) == [
            (2, 2)
        ]
