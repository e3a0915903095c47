"""The one run loop: sources -> pipeline -> sinks. Replay, the daemon and the evaluation
are thin compositions of it (`roadpreview.apps`, `roadpreview.eval.runner`).

``run(sources, pipeline, sinks, pace=..., watchdogs=...)``:

1. **Merge.** File sources are merged lazily in time-stamp order (one pending sample
   per source; IMU and speed samples before a frame stamped at the same instant).
   With a live source or a `Pace`, every source is read in a thread of its own into
   one bounded queue; a sample is released in time order once the clock has passed
   its stamp by ``latency_s`` (CAN frames stamped just before a frame may still be on
   their way), so a live run sees the samples in the order a replay does. When the
   pipeline falls behind, only the newest releasable camera frame is processed; the
   others are dropped and counted (a camera does not queue). A camera frame is merged
   ``frame_hold_s`` after its stamp (`roadpreview.sources.merge_key`; the configuration's
   ``[fusion] frame_hold_s``): the IMU samples for its instant are in the pipeline
   before it, so it is fused and compensated on the gyro, not on a bridged guess.
2. **Push** each sample into the pipeline. A camera frame not after the previous one is
   skipped and counted. After each frame the loop hands the `FrameResult` and the
   status to every sink, tracks the mode changes, and every ``status_period_s`` (on the
   frames' clock, `roadpreview.clock.Cycle`) sends the status to every sink: one
   schedule for a log and the status line. In a live run the schedule also runs between
   frames (after the first one), on the loop's clock. The live CAN bus does not wait for
   it: `roadpreview.sinks.can.CanBusSink` with a `StatusCycle` sends RP_STATUS from a
   thread of its own on the same cycle, from the newest status the loop handed it, so a
   loop held up by a burst of input or a slow frame does not hold the status up.
3. **Watchdogs** see every sample and are polled after each batch of released samples
   (at least every ``poll_s``); they log, count, and may inject samples (an image-less
   frame while the camera is lost).
4. **End.** At the end of input, on ``stop`` (a signal) or on an error: the detector's
   held-back events are flushed as alerts, and every sink is closed with the
   `RunSummary` (``interrupted`` says whether the input was cut short).

A sink that raises is logged and counted in ``summary.sink_errors``; it does not stop
the run.

**Memory.** Every `HEAP_TRIM_PERIOD_S` of the frames' clock the loop hands the C heap's
free memory back to the system (`release_free_heap`, glibc's ``malloc_trim``): the
frames' image buffers are freed every frame, and glibc keeps what they leave behind, so
that a long run's resident set crept up with no object growing (docs/robustness.md).

**Clocks.** A live run waits on a `roadpreview.clock.Clock` (``clock``; a `Pace` is one
too): the paced sources until a sample is due, the merge for arrivals (at most
``poll_s``), the supervisor's backoffs. Tests pass a `roadpreview.clock.VirtualClock`
and run on virtual time.

**Supervision.** Every source is read through a supervisor (`Supervision`): an exception
out of its iterator is logged (``event=thread_died source=... error=...``), counted
(``summary.thread_deaths``, and ``thread_died`` / ``restarted`` among the source's
problems) and the source is iterated again: a live source after a backoff (doubling up
to ``max_backoff_s``), a file source at once, resuming after the samples it gave. A
source that dies ``max_restarts`` times in a row (a live one that ran ``healthy_s``
between two deaths, a file one that got past its last failure, starts the count again)
ends the run: the sinks are closed with ``summary.error`` set and `SourceFailed`
(carrying the summary) is raised, so that the daemon exits non-zero and systemd's
``Restart=on-failure`` acts. At the end the sources' problem counts (the ``problems``
counter a source, its inner source or its decoder exposes) are collected into
``summary.source_problems``.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import heapq
import logging
import math
import queue
import signal
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import FrameType
from typing import Any, Protocol

from roadpreview.clock import Clock, Cycle, SystemClock
from roadpreview.errors import OperationError
from roadpreview.fusion.mode_machine import gyro_state, mode_reason
from roadpreview.pipeline.pipeline import FrameResult
from roadpreview.pipeline.run_summary import FrameTimes, RunSummary
from roadpreview.sinks import Sink
from roadpreview.sources import Source, merge_key, merge_sources
from roadpreview.supervision import Supervision
from roadpreview.types import (
    Alert,
    CameraFrame,
    ImuSample,
    Sample,
    SpeedSample,
    Status,
)

log = logging.getLogger(__name__)

#: how often the loop releases the C heap's free memory (`release_free_heap`), frames' s
HEAP_TRIM_PERIOD_S = 10.0


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None where the C library has none (musl, macOS)."""
    try:
        trim = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_heap() -> bool:
    """Hand the free memory of every C heap arena back to the system (glibc's
    ``malloc_trim(0)``: a millisecond or two); False where there is nothing to call.

    glibc raises its mmap threshold to the size of each large block freed, so that a
    frame's image buffers, freed at every frame, come from the heap after the first one;
    what they free there stays mapped between the long-lived blocks around it, and the
    resident set ratchets up over hours while no Python object grows."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True


class Stage(Protocol):
    """What the loop drives: `roadpreview.pipeline.Pipeline`, or the evaluation's fan-out
    of several pipelines over one vision pass."""

    #: samples the sources lost so far (the loop keeps it up to date, for the status)
    input_errors: int

    def push(self, sample: Sample) -> FrameResult | None: ...

    def finish(self) -> list[Alert]: ...

    def status(self) -> Status: ...


class Watchdog(Protocol):
    """Sees every sample the loop pushes; polled at least every ``poll_s`` while idle with
    the time up to which samples have been released (the clock minus ``latency_s``)."""

    def observe(self, sample: Sample) -> None: ...

    def check(self, now_s: float) -> list[Sample]:
        """Samples to push now (usually none)."""
        ...


@dataclass
class Pace:
    """Play at recorded speed (times ``rate``): sample time ``t`` is due at wall time
    ``wall0 + (t - t0) / rate`` of ``clock`` (default: the system's). ``t0`` defaults to
    the first sample's time, ``wall0`` to the moment the run starts; set both to line
    several players up on one clock. A pace is itself a `roadpreview.clock.Clock` on the
    samples' time: ``now``, ``wait`` (a timeout in sample seconds) and `sleep_until`."""

    rate: float = 1.0
    t0: float | None = None
    wall0: float | None = None
    clock: Clock = field(default_factory=SystemClock)

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError(f"pace rate {self.rate}: must be positive")
        self._lock = threading.Lock()

    def start(self, t0: float) -> None:
        """Anchor the clock at the first sample (thread-safe; the first call wins)."""
        with self._lock:
            if self.t0 is None:
                self.t0 = t0
            if self.wall0 is None:
                self.wall0 = self.clock.now()

    @property
    def started(self) -> bool:
        return self.t0 is not None and self.wall0 is not None

    def due_in(self, t: float) -> float:
        """Seconds (of ``clock``) until sample time ``t`` is due (negative: overdue)."""
        return self._wall0() + (t - self._t0()) / self.rate - self.clock.now()

    def now(self) -> float:
        """The sample clock now."""
        return self._t0() + (self.clock.now() - self._wall0()) * self.rate

    def wait(self, event: threading.Event, timeout_s: float | None) -> bool:
        """`Clock.wait` with the timeout in sample seconds."""
        return self.clock.wait(event, None if timeout_s is None else timeout_s / self.rate)

    def event(self) -> threading.Event:
        return self.clock.event()

    def sleep_until(self, t: float, stop: threading.Event) -> bool:
        """Wait until sample time ``t`` is due (`start` first) or ``stop`` is set; True if
        stopped."""
        if stop.is_set():
            return True
        wait = self.due_in(t)
        return wait > 0 and self.clock.wait(stop, wait)

    def _t0(self) -> float:
        if self.t0 is None:
            raise RuntimeError("Pace.start was not called")
        return self.t0

    def _wall0(self) -> float:
        if self.wall0 is None:
            raise RuntimeError("Pace.start was not called")
        return self.wall0


class SourceFailed(OperationError):
    """A source kept failing (`Supervision.max_restarts`); ``summary``: the run up to it,
    with the sinks closed."""

    def __init__(self, message: str, summary: RunSummary | None = None) -> None:
        super().__init__(message)
        self.summary = summary


class _Supervisor:
    """Reads each source through `samples`, restarting it when its iterator raises
    (module docstring); thread-safe counts per source name."""

    def __init__(self, policy: Supervision, stop: threading.Event, clock: Clock) -> None:
        self.policy = policy
        self.stop = stop
        self.clock = clock  #: a live source's backoff and healthy time run on it
        self.deaths: Counter[str] = Counter()  #: exceptions out of each source's iterator
        self.restarts: Counter[str] = Counter()  #: times each source was iterated again
        self.failed = ""  #: why the run must end ('' while every source is fine)
        self._lock = threading.Lock()

    def samples(self, source: Source) -> Iterator[Sample]:
        """The samples of ``source``, restarted after an exception; raises `SourceFailed`
        when it dies `Supervision.max_restarts` times in a row."""
        policy = self.policy
        in_row = 0  # deaths since the source last made progress
        given = 0  # samples given so far (a file source read again resumes after them)
        while True:
            started = self.clock.now()
            progressed = False
            try:
                # a file source reads the same samples again from its start: skip those
                # given (by count: one source's samples need not be in time order, e.g.
                # a calibrated IMU's stamps moved back against the speed's in one CAN log)
                skip = 0 if source.live else given
                for sample in source:
                    if skip:
                        skip -= 1
                        continue
                    given += 1
                    progressed = True
                    yield sample
                return
            except Exception as exc:
                error = f"{type(exc).__name__}: {exc}".splitlines()[0]
                healthy = self.clock.now() - started >= policy.healthy_s
                if progressed and (healthy or not source.live):
                    in_row = 0
                in_row += 1
                with self._lock:
                    self.deaths[source.name] += 1
                log.error(
                    "event=thread_died source=%s error=%r deaths=%d in_row=%d",
                    source.name,
                    error,
                    self.deaths[source.name],
                    in_row,
                )
                log.debug("source %s: the exception", source.name, exc_info=True)
                if in_row > policy.max_restarts:
                    message = (
                        f"{source.name}: the source failed {in_row} times in a row "
                        f"(last: {error}); giving up"
                    )
                    log.error("event=source_gave_up source=%s error=%r", source.name, error)
                    with self._lock:
                        self.failed = self.failed or message
                    raise SourceFailed(message) from exc
            if source.live and self.clock.wait(self.stop, policy.backoff(in_row)):
                return
            with self._lock:
                self.restarts[source.name] += 1
            log.warning(
                "event=source_restarted source=%s restarts=%d",
                source.name,
                self.restarts[source.name],
            )


class _End:
    """A source thread's end marker."""

    def __init__(self, source: Source) -> None:
        self.source = source


class _LiveMerge:
    """Samples of threaded sources in time order, released ``latency_s`` after their
    stamp on the clock (module docstring)."""

    def __init__(
        self,
        sources: Sequence[Source],
        *,
        pace: Pace | None,
        latency_s: float,
        stop: threading.Event,
        queue_size: int,
        supervisor: _Supervisor,
        clock: Clock,
        frame_hold_s: Callable[[], float] = lambda: 0.0,
    ) -> None:
        self.sources = sources
        self.supervisor = supervisor
        self.pace = pace
        self.latency_s = latency_s
        self.frame_hold_s = frame_hold_s
        self.stop = stop
        #: the clock of the samples without a pace; the merge's waits run on the pace's
        self.base_clock = clock if pace is None else pace.clock
        self.queue: queue.Queue[Sample | _End] = queue.Queue(maxsize=queue_size)
        self.arrived = self.base_clock.event()  #: set when a pump put something
        self.queue_drops = 0  #: samples lost because the queue was full
        self.frames_dropped = 0  #: frames skipped because a newer one was due
        #: called with the released samples' clock after each batch (the status cycle)
        self.on_tick: Callable[[float], None] | None = None
        self._threads = [
            threading.Thread(target=self._pump, args=(s,), name=f"source:{s.name}", daemon=True)
            for s in sources
        ]

    def clock(self) -> float:
        """The sample clock now (-inf while a pace has no anchor yet)."""
        if self.pace is None:
            return self.base_clock.now()
        return self.pace.now() if self.pace.started else -math.inf

    def _put(self, item: Sample | _End) -> None:
        while not self.stop.is_set():
            try:
                self.queue.put(item, timeout=0.1)
                self.arrived.set()
                return
            except queue.Full:
                if not isinstance(item, _End):
                    self.queue_drops += 1
                    return

    def _pump(self, source: Source) -> None:
        try:
            for sample in self.supervisor.samples(source):
                if self.stop.is_set():
                    return
                if self.pace is not None and not source.live:
                    self.pace.start(sample.t_s)
                    if self.pace.sleep_until(sample.t_s, self.stop):
                        return
                self._put(sample)
        except SourceFailed:
            pass  # logged; the merge ends the run (`samples`)
        except Exception:  # the supervisor's own failure: never silent
            log.exception("event=thread_died source=%s", source.name)
            self.supervisor.failed = self.supervisor.failed or f"{source.name}: thread died"
        finally:
            self._put(_End(source))

    def start(self) -> None:
        for th in self._threads:
            th.start()

    def samples(
        self, watchdogs: Sequence[Watchdog], *, poll_s: float, keep_running: bool
    ) -> Iterator[tuple[Sample, bool]]:
        """The samples in time order, each with whether a watchdog injected it (module
        docstring); ends with the last file source, never with a live one."""
        self.start()
        heap: list[tuple[tuple[float, int], int, Sample]] = []
        seq = 0
        files_open = sum(not s.live for s in self.sources)
        hold_of = self.frame_hold_s
        ends_by_itself = files_open > 0 and not keep_running
        while not self.stop.is_set():
            if self.supervisor.failed:
                raise SourceFailed(self.supervisor.failed)
            self.arrived.clear()
            item = self._next()
            if item is None:  # wait for an arrival, at most poll_s
                self.base_clock.wait(self.arrived, poll_s)
                item = self._next()
            while item is not None:
                if isinstance(item, _End):
                    files_open -= not item.source.live
                else:
                    if self.pace is not None:
                        self.pace.start(item.t_s)  # a live source's first sample anchors it
                    heapq.heappush(heap, (merge_key(item, hold_of()), seq, item))
                    seq += 1
                item = self._next()
            ended = ends_by_itself and files_open == 0
            horizon = math.inf if ended else self.clock() - self.latency_s
            ready: list[Sample] = []
            while heap and heap[0][0][0] <= horizon:  # (a frame's key: its stamp + hold)
                ready.append(heapq.heappop(heap)[2])
            frames = [i for i, s in enumerate(ready) if isinstance(s, CameraFrame)]
            skip = set(frames[:-1]) if not ended else set()  # behind: only the newest frame
            self.frames_dropped += len(skip)
            yield from ((s, False) for i, s in enumerate(ready) if i not in skip)
            if ended:
                return
            # also while CAN samples keep coming: a silent camera is noticed on time
            for wd in watchdogs:  # on the released samples' clock
                yield from ((s, True) for s in wd.check(horizon))
            if self.on_tick is not None:
                self.on_tick(horizon)

    def _next(self) -> Sample | _End | None:
        try:
            return self.queue.get_nowait()
        except queue.Empty:
            return None

    def close(self) -> None:
        for s in self.sources:
            s.close()
        for th in self._threads:
            th.join(timeout=5.0)
            if th.is_alive():
                log.error("event=source_thread_hangs thread=%s", th.name)


def hold_frames(
    samples: Iterable[Sample], hold_s: Callable[[], float]
) -> Generator[Sample, None, None]:
    """``samples`` (in time order) with each camera frame moved after the samples stamped up
    to ``hold_s()`` (asked when the frame comes) after it: `merge_key` with a hold that may
    change from frame to frame. Frames keep their order and stamps; a frame with no hold
    and none held goes straight through; at the end, and when the input fails, the frames
    still held come out first."""
    held: deque[tuple[float, Sample]] = deque()
    try:
        for s in samples:
            t = s.t_s
            while held and held[0][0] < t:
                yield held.popleft()[1]
            if isinstance(s, CameraFrame):
                hold = hold_s()
                if hold <= 0.0 and not held:
                    yield s
                    continue
                due = t + hold
                if held and due < held[-1][0]:
                    due = held[-1][0]  # (a shorter hold does not overtake a held frame)
                held.append((due, s))
            else:
                yield s
    except Exception:  # (not GeneratorExit: a closed generator yields nothing more)
        while held:  # what came before the failure is processed, then the failure
            yield held.popleft()[1]
        raise
    while held:
        yield held.popleft()[1]


def run(
    sources: Sequence[Source],
    pipeline: Stage,
    sinks: Sequence[Sink] = (),
    *,
    pace: Pace | None = None,
    watchdogs: Sequence[Watchdog] = (),
    stop: threading.Event | None = None,
    status_period_s: float = 0.1,
    latency_s: float = 0.0,
    frame_hold_s: float | Callable[[], float] = 0.0,
    queue_size: int = 100_000,
    poll_s: float = 0.05,
    max_frames: int | None = None,
    progress: Callable[[int, float], None] | None = None,
    keep_running: bool = False,
    supervision: Supervision | None = None,
    clock: Clock | None = None,
) -> RunSummary:
    """Run the pipeline over the sources into the sinks (module docstring). ``clock``: what
    a live run waits on and, without a pace, its samples' clock (default: the system's;
    the supervisor's backoffs then on the monotonic clock). Raises `SourceFailed` (after
    closing the sinks) when a source keeps failing."""
    stop = stop or threading.Event()
    hold_of = frame_hold_s if callable(frame_hold_s) else functools.partial(float, frame_hold_s)
    summary = RunSummary()
    timer = clock or SystemClock(time.monotonic)
    supervisor = _Supervisor(supervision or Supervision(), stop, timer)
    state = _LoopState(pipeline, sinks, summary, status_period_s, sources, supervisor.deaths)
    wall0 = time.perf_counter()
    live = pace is not None or any(s.live for s in sources)
    merge: _LiveMerge | None = None
    try:
        stream: Iterator[tuple[Sample, bool]]
        if live:
            merge = _LiveMerge(
                sources,
                pace=pace,
                latency_s=latency_s,
                frame_hold_s=hold_of,
                stop=stop,
                queue_size=queue_size,
                supervisor=supervisor,
                clock=clock or SystemClock(),
            )
            merge.on_tick = state.tick
            stream = merge.samples(watchdogs, poll_s=poll_s, keep_running=keep_running)
        else:
            supervised = [supervisor.samples(s) for s in sources]
            merged = hold_frames(merge_sources(supervised), hold_of)
            stream = ((sample, False) for sample in merged)
        cut = False  # stopped by max_frames
        for sample, injected in stream:
            if stop.is_set():
                break
            state.push(sample, watchdogs, injected=injected)
            if progress is not None and state.new_frame and summary.frames % 30 == 0:
                progress(summary.frames, time.perf_counter() - wall0)
            if max_frames is not None and summary.frames >= max_frames:
                cut = True
                break
        summary.interrupted = cut or stop.is_set()
    except KeyboardInterrupt:  # Ctrl-C without a handler: stop like a signal does
        summary.interrupted = True
        log.warning("event=interrupted frames=%d", summary.frames)
    except SourceFailed as exc:
        summary.interrupted = True
        summary.error = str(exc)
        exc.summary = summary
        raise
    except BaseException as exc:
        summary.interrupted = True
        summary.error = f"{type(exc).__name__}: {exc}"
        raise
    finally:
        if merge is not None:
            stop.set()
            merge.close()
            summary.queue_drops = merge.queue_drops
            summary.frames_dropped = merge.frames_dropped
        try:
            state.finish()
        finally:
            summary.seconds = time.perf_counter() - wall0
            summary.source_errors = {s.name: s.errors for s in sources}
            summary.thread_deaths = dict(supervisor.deaths)
            summary.source_problems = {
                s.name: source_problems(s, supervisor.deaths, supervisor.restarts) for s in sources
            }
            for sink in sinks:
                try:
                    sink.close(summary)
                except Exception:
                    summary.sink_errors += 1
                    log.exception("event=sink_close_failed sink=%s", type(sink).__name__)
    return summary


def source_problems(
    source: Source,
    deaths: Mapping[str, int] | None = None,
    restarts: Mapping[str, int] | None = None,
) -> dict[str, int]:
    """What went wrong with ``source``: reason -> count, from the ``problems`` counters of
    the source, of the source it wraps (``source``: a window) and of its decoder
    (``decoder``), each counted once, plus the loop's ``thread_died`` / ``restarted``."""
    merged: Counter[str] = Counter()
    seen: set[int] = set()
    for owner in (source, getattr(source, "source", None)):
        for holder in (owner, getattr(owner, "decoder", None)):
            problems = getattr(holder, "problems", None)
            if not isinstance(problems, Mapping) or id(problems) in seen:
                continue
            seen.add(id(problems))
            for reason, n in problems.items():
                if isinstance(n, int) and n:
                    merged[str(reason)] += n
    for reason, counts in (("thread_died", deaths), ("restarted", restarts)):
        if counts and counts.get(source.name):
            merged[reason] += counts[source.name]
    return dict(sorted(merged.items()))


class _LoopState:
    """The per-sample step of `run`, whichever merge the samples come from."""

    def __init__(
        self,
        pipeline: Stage,
        sinks: Sequence[Sink],
        summary: RunSummary,
        status_period_s: float,
        sources: Sequence[Source],
        deaths: Mapping[str, int],
    ) -> None:
        self.pipeline = pipeline
        self.deaths = deaths  #: the supervisor's (a source's death counts as an input error)
        self.sinks = sinks
        self.summary = summary
        self.sources = sources
        self.cycle = Cycle(status_period_s)  #: the status schedule, on the frames' clock
        self.trim = Cycle(HEAP_TRIM_PERIOD_S)  #: the heap's release (`release_free_heap`)
        self.last_t = -math.inf
        self.new_frame = False
        self.last_gyro_t = -math.inf  #: the newest gyro sample's time (mode reasons)
        self.gyro_state = ""  #: the gyro's state at the last entry of ``mode_changes``

    def _status(self) -> Status:
        # on CAN (StatusInputErrors): the samples lost and the sources' deaths
        self.pipeline.input_errors = sum(s.errors for s in self.sources) + sum(self.deaths.values())
        problems: Counter[str] = Counter()
        for s in self.sources:  # the per-source problems contract (RP_INPUT_STATUS)
            problems.update(getattr(s, "problems", {}))
        return replace(
            self.pipeline.status(),
            frames_processed=self.summary.frames,
            input_problems_total=dict(problems),
        )

    def _each_sink(self, call: Callable[[Sink], None]) -> None:
        for sink in self.sinks:
            try:
                call(sink)
            except Exception:
                self.summary.sink_errors += 1
                log.exception("event=sink_failed sink=%s", type(sink).__name__)

    def push(self, sample: Sample, watchdogs: Sequence[Watchdog], injected: bool = False) -> None:
        self.new_frame = False
        summary = self.summary
        if not isinstance(sample, CameraFrame):
            assert isinstance(sample, ImuSample | SpeedSample)
            if isinstance(sample, ImuSample) and math.isfinite(sample.pitch_rate_rad_s):
                self.last_gyro_t = max(self.last_gyro_t, sample.t_s)
            self.pipeline.push(sample)
            summary.samples += 1
            for wd in watchdogs:
                wd.observe(sample)
            return
        if sample.t_s <= self.last_t:
            if not injected:
                summary.frames_out_of_order += 1
                log.warning(
                    "frame at %.6f s is not after the previous one (%.6f s); skipped",
                    sample.t_s,
                    self.last_t,
                )
                return
            sample = replace(sample, t_s=self.last_t + 1e-3)
        self.last_t = sample.t_s
        for wd in watchdogs:
            wd.observe(sample)
        c0 = time.perf_counter()
        r = self.pipeline.push(sample)
        assert r is not None
        if injected:
            summary.injected_frames += 1
        else:
            summary.frames += 1
            self.new_frame = True
        if math.isnan(summary.first_t):
            summary.first_t = sample.t_s
        summary.last_t = sample.t_s
        summary.last = r
        modes = summary.mode_changes
        gyro_age = r.t - self.last_gyro_t
        gyro = gyro_state(gyro_age)
        # a new entry when the mode changes, or when the gyro's state does (the reason of
        # a VISUAL_ONLY that began before the first gyro sample would go stale)
        if not modes or modes[-1][1] != r.mode or gyro != self.gyro_state:
            why = mode_reason(r.mode, vision_failure=r.pitch_reason, gyro_age_s=gyro_age)
            self.gyro_state = gyro
            modes.append((r.t, r.mode, why))
            log.info("event=mode_change t=%.3f mode=%s reason=%r", r.t, r.mode.name, why)
        summary.alerts.extend(r.alerts)
        summary.provisional.extend(r.provisional)
        summary.cancelled.extend(r.cancelled)
        summary.confirmations.extend(r.confirmations)
        status = self._status()
        self._each_sink(lambda s: s.on_frame(sample, r, status))
        if self.cycle.due(r.t):
            self._each_sink(lambda s: s.on_status(r.t, status))
            self.cycle.sent(r.t)
        if not injected:
            summary.frame_ms.add((time.perf_counter() - c0) * 1e3)
        if self.trim.due(r.t):
            release_free_heap()
            self.trim.sent(r.t)

    def tick(self, t: float) -> None:
        """No sample is due up to ``t``: the status, if its period has passed since the last
        one (after the first frame: before it there is nothing to report)."""
        if self.summary.last is None or not math.isfinite(t) or not self.cycle.due(t):
            return
        t = max(t, self.last_t)
        status = self._status()
        self._each_sink(lambda s: s.on_status(t, status))
        self.cycle.sent(t)

    def finish(self) -> None:
        """The end of input: the held-back events as alerts, to every sink."""
        tail = self.pipeline.finish()
        self.summary.alerts.extend(tail)
        status = self._status()
        t = self.last_t
        if tail and math.isfinite(t):
            self._each_sink(lambda s: s.on_flush(t, tail, status))
            if self.cycle.due(t):
                self._each_sink(lambda s: s.on_status(t, status))
                self.cycle.sent(t)


@dataclass
class SignalHandlers:
    """SIGINT/SIGTERM set an event; `restore` puts the previous handlers back."""

    event: threading.Event
    previous: dict[int, Any] = field(default_factory=dict)

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        log.warning("event=signal name=%s", signal.Signals(signum).name)
        self.event.set()

    def install(self) -> SignalHandlers:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self.previous[sig] = signal.signal(sig, self._handle)
        return self

    def restore(self) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)
        self.previous.clear()


def install_signal_handlers(event: threading.Event) -> SignalHandlers:
    """SIGINT and SIGTERM set ``event`` (call from the main thread): the loop stops, the
    pipeline is flushed and every sink closed."""
    return SignalHandlers(event).install()


__all__ = [
    "FrameTimes",
    "Pace",
    "RunSummary",
    "SignalHandlers",
    "SourceFailed",
    "Stage",
    "Supervision",
    "Watchdog",
    "install_signal_handlers",
    "release_free_heap",
    "run",
    "source_problems",
]
