"""The execution engine of every multi-drive job (``roadpreview batch``, ``roadpreview
evaluate``): Dask's distributed scheduler, one drive (or one evaluation recording) per
task.

`open_engine` gives a connected `Engine`:

* ``scheduler`` given (``tcp://host:8786``), or Dask's own setting
  (``scheduler-address`` in a Dask config file, or ``DASK_SCHEDULER_ADDRESS`` in the
  environment): that cluster is used as it is; its workers get the thread pinning below
  when we connect.
* otherwise a `distributed.LocalCluster` of processes, one thread each, as many workers
  as cores (``workers``), each with a memory limit (``memory_limit``; ``"auto"``: the
  machine's memory shared evenly). Dask's nanny pauses a worker at 80 % of its limit and
  restarts it at 95 %; the task then runs again elsewhere.

Every worker runs OpenCV and BLAS on one thread (`PinThreads`): the workers already use
the cores, and N workers x M threads on N cores only adds contention. A worker that dies
mid-task (killed, out of memory, a segfault in a native library) is replaced by the
nanny and its task re-run, up to Dask's ``distributed.scheduler.allowed-failures`` (3)
times; after that the task ends in `distributed.KilledWorker`, which `Engine.map`
hands back as a failed result, not an exception.

`Engine.map` submits the tasks, reports progress (Dask's text bar on a terminal, a log
line every 10 s otherwise) and yields each result as it completes.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import distributed
from distributed import WorkerPlugin

from roadpreview.apps.progress import format_duration
from roadpreview.errors import ConfigError, OperationError

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")

#: environment of a local worker process, set before it imports numpy or OpenCV
PINNED_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
    "OPENCV_FOR_THREADS_NUM": "1",
}


#: a worker's own threads leave the drive's thread alone: Dask's statistical profiler
#: samples the task's stack every 10 ms, and its event loop ticks every 20 ms, checks
#: memory every 100 ms and the system every 500 ms, each taking the GIL; a drive runs
#: for minutes, so checking every second is soon enough (`roadpreview bench batch`)
CALM_WORKERS = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}


def pin_threads() -> None:
    """One thread for OpenCV and for every BLAS/OpenMP pool of this process."""
    import cv2

    cv2.setNumThreads(1)
    for var, value in PINNED_ENV.items():
        os.environ[var] = value
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


class PinThreads(WorkerPlugin):
    """Worker plugin: `pin_threads` on every worker, present and future (a worker that the
    nanny restarts runs it again). ``idempotent``: registering it twice is harmless."""

    name = "roadpreview-pin-threads"
    idempotent = True

    def setup(self, worker: Any) -> None:
        pin_threads()
        # the replay's modules (OpenCV, gtsam, scipy, matplotlib for plots.png, ...) load
        # once per worker as it starts, not inside the first drive's time
        importlib.import_module("roadpreview.apps.replay")
        import matplotlib

        matplotlib.use("Agg")
        importlib.import_module("matplotlib.pyplot")


@dataclass(frozen=True)
class TaskFailure:
    """A task that did not return: its worker died ``allowed-failures`` + 1 times, or the
    task raised (a bug: tasks catch their own input errors)."""

    item: Any
    message: str


class Engine:
    """A Dask client with its (local or remote) cluster; a context manager that closes
    what it opened (a remote cluster is left running)."""

    def __init__(self, client: Any, cluster: Any | None, *, workers: int) -> None:
        self.client = client
        self.cluster = cluster  #: the LocalCluster we started; None: an existing cluster
        self.workers = workers

    @property
    def address(self) -> str:
        return str(self.client.scheduler.address)

    @property
    def local(self) -> bool:
        return self.cluster is not None

    @property
    def dashboard(self) -> str | None:
        """The dashboard's address, when one is served (a local cluster needs bokeh)."""
        if self.local and importlib.util.find_spec("bokeh") is None:
            return None
        link = self.client.dashboard_link
        return str(link) if link else None

    def describe(self) -> str:
        where = "local cluster" if self.local else "cluster"
        n = len(self.client.scheduler_info().get("workers", {}))
        dash = self.dashboard
        board = f", dashboard {dash}" if dash else ""
        return f"{where} {self.address}: {n} worker(s){board}"

    def worker_pids(self) -> dict[str, int]:
        """Worker address -> process id (for tests that kill one)."""
        return dict(self.client.run(os.getpid))

    def map(
        self,
        fn: Callable[..., R],
        items: Sequence[T],
        *,
        keys: Sequence[str],
        label: str = "tasks",
        progress: bool = True,
        tty: bool | None = None,
        every_s: float = 10.0,
        **kwargs: Any,
    ) -> Iterator[tuple[T, R | TaskFailure]]:
        """``fn(item, **kwargs)`` for every item as a Dask task named by ``keys`` (unique),
        submitted in the given order (put the longest first). Yields ``(item, result)`` as
        they complete; a task whose worker kept dying, or that raised, gives a
        `TaskFailure`. Progress: Dask's text bar on a terminal (``tty``; default: stderr
        is one), else a log line every ``every_s`` seconds."""
        if len(set(keys)) != len(keys):
            raise ConfigError(f"{label}: two tasks share a name")
        futures = [
            self.client.submit(fn, item, key=f"{label}-{key}", pure=False, **kwargs)
            for item, key in zip(items, keys, strict=True)
        ]
        by_future = {f.key: item for f, item in zip(futures, items, strict=True)}
        if not futures:
            return
        on_tty = sys.stderr.isatty() if tty is None else tty
        if progress and on_tty:
            from distributed.diagnostics.progressbar import progress as dask_progress

            dask_progress(futures)  # blocks until every task is done (or failed)
        t0 = time.monotonic()
        next_log = t0 + every_s
        for done, fut in enumerate(distributed.as_completed(futures), start=1):
            item = by_future[fut.key]
            if progress and not on_tty and time.monotonic() >= next_log:
                next_log = time.monotonic() + every_s
                log.info(
                    "%s: %d/%d done, %s elapsed",
                    label,
                    done,
                    len(futures),
                    format_duration(time.monotonic() - t0),
                )
            try:
                result = fut.result()
            except distributed.KilledWorker:
                import dask

                deaths = int(dask.config.get("distributed.scheduler.allowed-failures")) + 1
                yield (
                    item,
                    TaskFailure(
                        item,
                        f"its worker died {deaths} time(s) while running it (killed, out of"
                        " memory, or a crash in a native library); see the workers' logs",
                    ),
                )
            except Exception as exc:  # a bug in a task: keep it to that task
                yield item, TaskFailure(item, f"{type(exc).__name__}: {exc}")
            else:
                yield item, result
            fut.release()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def default_workers() -> int:
    """As many workers as cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def quiet_dask_logs() -> None:
    """Dask's scheduler and nanny log each worker's start, stop and restart at INFO; with
    the command line's logging set up first, Dask adds no handler of its own and those
    lines would reach the console. They are kept to warnings (a worker restarted, memory
    pressure) unless the root logger is at DEBUG (``-vv``)."""
    if logging.getLogger().getEffectiveLevel() > logging.DEBUG:
        logger = logging.getLogger("distributed")
        if logger.level == logging.NOTSET or logger.level < logging.WARNING:
            logger.setLevel(logging.WARNING)


def open_engine(
    scheduler: str | None = None,
    *,
    workers: int | None = None,
    memory_limit: str | float | None = "auto",
    dashboard: bool = True,
) -> Engine:
    """Connect to ``scheduler`` (or Dask's configured ``scheduler-address``), else start a
    local cluster of ``workers`` processes (module docstring)."""
    import dask

    address = scheduler or dask.config.get("scheduler-address", None)
    quiet_dask_logs()
    if address:
        if workers is not None:
            log.warning("the local worker count is ignored with an existing cluster (%s)", address)
        try:
            client = distributed.Client(address, timeout="10s")
        except OSError as exc:
            raise OperationError(f"--scheduler {address}: cannot connect ({exc})") from None
        client.register_plugin(PinThreads())
        n = len(client.scheduler_info().get("workers", {}))
        if n == 0:
            log.warning("cluster %s has no worker yet: tasks wait for one", address)
        return Engine(client, None, workers=n)
    n = workers or default_workers()
    if n < 1:
        raise ConfigError(f"--workers {n}: need at least 1")
    env = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **PINNED_ENV}
    # Dask sets glibc's trim threshold to return memory to the system sooner; a fixed
    # threshold also turns off glibc's adaptive mmap threshold, so every decoded frame
    # (> 128 KiB) is mmap'ed, page-faulted and unmapped again: replay ran 1.6x slower
    # in a worker than in a plain process (`roadpreview bench batch`). The pipeline
    # streams (its memory is flat: docs/robustness.md), so glibc's default is kept.
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    # the scheduler's HTTP server (metrics, and the dashboard when bokeh is installed) on a
    # free port: a second batch, or an evaluation, on the same machine must not collide
    board = ":0"
    with dask.config.set({"distributed.nanny.pre-spawn-environ": env, **CALM_WORKERS}):
        cluster = distributed.LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            memory_limit=memory_limit,
            dashboard_address=board,
            scheduler_kwargs={"dashboard": dashboard},
            silence_logs=logging.ERROR,
        )
    client = distributed.Client(cluster)
    client.register_plugin(PinThreads())
    return Engine(client, cluster, workers=n)


__all__ = [
    "PINNED_ENV",
    "Engine",
    "PinThreads",
    "TaskFailure",
    "default_workers",
    "open_engine",
    "pin_threads",
    "quiet_dask_logs",
]
