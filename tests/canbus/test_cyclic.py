"""The cyclic status sender (`roadpreview.canbus.cyclic`, `CanBusSink` with a
`StatusCycle`) on virtual time: RP_STATUS keeps its period while the run loop's thread is
held up, a send error costs one frame, a sender that dies is restarted and one that keeps
dying gives up and says so; RP_INPUT_STATUS stays IfActive."""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, cast

import can
import pytest

from roadpreview.canbus.cyclic import CyclicSender
from roadpreview.canbus.received import OutputDecoder, ReceivedInputStatus, ReceivedStatus
from roadpreview.clock import VirtualClock, sleep_until
from roadpreview.loop import RunSummary, run
from roadpreview.pipeline import FrameResult
from roadpreview.sinks.can import CanBusSink, StatusCycle
from roadpreview.supervision import Supervision
from roadpreview.types import Alert, CameraFrame, FusionMode, Sample, Status

RP_STATUS, RP_ROAD_STATUS, RP_INPUT_STATUS = 0x201, 0x202, 0x206
PERIOD_S = 0.1
T0 = 1_735_689_600.0  # 2025-01-01, a Unix time as the daemon's clock reads


class _Bus(can.BusABC):
    """Keeps what is sent; ``refuse(msg)`` True makes a send raise (a driver's ENOBUFS)."""

    def __init__(self, refuse: Callable[[can.Message], bool] = lambda m: False) -> None:
        super().__init__(channel="memory")
        self.sent: list[can.Message] = []
        self.refuse = refuse

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.refuse(msg):
            raise OSError(105, "No buffer space available")
        self.sent.append(msg)

    def _recv_internal(self, timeout: float | None) -> tuple[None, bool]:
        return None, False

    def of(self, arbitration_id: int) -> list[can.Message]:
        return [m for m in self.sent if m.arbitration_id == arbitration_id]


@dataclass
class _Result:
    """The fields of a `FrameResult` the loop and the CAN sink read."""

    t: float
    mode: FusionMode = FusionMode.FUSED
    pitch_reason: str = ""
    ego_speed_mps: float | None = 10.0
    alerts: list[Alert] = field(default_factory=list)
    provisional: tuple[Alert, ...] = ()
    cancelled: tuple[Alert, ...] = ()
    preview: None = None
    confirmations: list[Any] = field(default_factory=list)


class _Stage:
    """Counts frames; holds the loop's thread on the clock at frame ``hold_at`` until
    ``release`` (a hang inside the pipeline, as a burst of input or a slow model)."""

    def __init__(self, clock: VirtualClock, hold_at: int = -1) -> None:
        self.clock = clock
        self.input_errors = 0
        self.frames = 0
        self.hold_at = hold_at
        self.holding = threading.Event()
        self.release = clock.event()
        self.problems: dict[str, int] = {}

    def push(self, sample: Sample) -> FrameResult | None:
        if not isinstance(sample, CameraFrame):
            return None
        self.frames += 1
        if self.frames == self.hold_at:
            self.holding.set()
            self.clock.wait(self.release, None)
        return cast("FrameResult", _Result(sample.t_s))

    def finish(self) -> list[Alert]:
        return []

    def status(self) -> Status:
        return Status(mode=FusionMode.FUSED, frames_processed=self.frames)


class _Camera:
    """A live camera on the virtual clock: a frame every 1/30 s, stamped when taken."""

    name = "camera"
    live = True
    errors = 0

    def __init__(self, clock: VirtualClock, n: int = 10_000) -> None:
        self.clock = clock
        self.n = n
        self.stop = clock.event()

    def __iter__(self) -> Iterator[Sample]:
        t0 = self.clock.now()
        for i in range(self.n):
            if sleep_until(self.clock, t0 + i / 30, self.stop):
                return
            yield CameraFrame(self.clock.now(), None, i)

    def close(self) -> None:
        self.stop.set()


def _until(condition: Callable[[], bool]) -> None:
    deadline = time.monotonic() + 30.0  # threads starting, not a timing
    while not condition():
        assert time.monotonic() < deadline, "never happened"
        time.sleep(0.001)


@dataclass
class _Run:
    clock: VirtualClock
    stage: _Stage
    sink: CanBusSink
    bus: _Bus
    stop: threading.Event
    thread: threading.Thread
    box: list[RunSummary]

    def end(self) -> RunSummary:
        self.stop.set()
        while self.thread.is_alive():  # the loop looks at its stop every poll
            self.clock.advance(0.05)
        self.bus.shutdown()
        return self.box[0]

    def statuses(self) -> list[ReceivedStatus]:
        decoder = OutputDecoder()
        out = [decoder.decode(m) for m in self.bus.of(RP_STATUS)]
        assert decoder.problems == {}  # CRC and counters of every frame received
        return [s for s in out if isinstance(s, ReceivedStatus)]


def _start(
    *, hold_at: int = -1, refuse: Callable[[can.Message], bool] = lambda m: False
) -> _Run:
    clock = VirtualClock(T0)
    stage = _Stage(clock, hold_at)
    bus = _Bus(refuse)
    sink = CanBusSink(bus, cycle=StatusCycle(clock, PERIOD_S))
    stop = clock.event()
    box: list[RunSummary] = []
    thread = threading.Thread(
        target=lambda: box.append(
            run([_Camera(clock)], stage, [sink], stop=stop, keep_running=True, clock=clock)
        ),
        name="loop",
        daemon=True,
    )
    thread.start()
    _until(lambda: stage.frames >= 1 and clock.waiting >= 3)  # camera, loop, sender
    return _Run(clock, stage, sink, bus, stop, thread, box)


def test_rp_status_keeps_its_period_while_the_loop_thread_is_held() -> None:
    """The acceptance check of the cyclic sender, on virtual time: the loop's thread is
    held for 2 s at frame 10; RP_STATUS goes on every 100 ms exactly, each frame with its
    E2E counter +1, and its heartbeat (frames processed) standing still while held."""
    r = _start(hold_at=10)
    r.clock.advance(1.0)
    assert r.stage.holding.is_set()
    held_from = r.clock.now() - T0
    r.clock.advance(2.0)
    assert r.stage.frames == 10  # the loop did not move
    r.stage.release.set()
    r.clock.settle()
    r.clock.advance(0.5)
    summary = r.end()
    assert summary.frames_dropped > 0  # behind after the hold: the newest frame only
    statuses = r.statuses()
    stamps = [s.t_rx_s - T0 for s in statuses]
    # from the first frame at T0 to the end, one every period, none missed, none extra
    assert stamps[0] == pytest.approx(0.0)
    assert len(stamps) >= 35
    gaps = [b - a for a, b in itertools.pairwise(stamps[:-1])]  # the last: at close
    assert gaps == pytest.approx([PERIOD_S] * len(gaps), abs=1e-6)
    assert stamps[-1] >= stamps[-2]
    assert [(b.counter - a.counter) % 15 for a, b in itertools.pairwise(statuses)] == [1] * (
        len(statuses) - 1
    )
    held = [s.heartbeat for s, t in zip(statuses, stamps, strict=True) if held_from < t < 3.0]
    assert len(held) >= 19
    assert set(held) == {9 % 8}  # 9 frames through, the 10th held: the DBC says stalled
    assert statuses[-1].heartbeat != 9 % 8
    assert len(r.bus.of(RP_ROAD_STATUS)) == len(statuses)  # with every RP_STATUS
    assert r.bus.of(RP_INPUT_STATUS) == []  # no input problem: IfActive sends none
    sender = r.sink.status_sender
    assert sender is not None
    assert (sender.deaths, sender.send_errors, sender.skipped) == (0, 0, 0)


def test_a_send_error_costs_one_frame_and_the_cycle_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    calls = itertools.count(1)

    def tenth_status(msg: can.Message) -> bool:
        return msg.arbitration_id == RP_STATUS and next(calls) == 10

    with caplog.at_level(logging.WARNING):
        r = _start(refuse=tenth_status)
        r.clock.advance(2.0)
        r.end()
    assert r.sink.send_errors == 1
    assert dict(r.sink.send_failures) == {RP_STATUS: 1}
    statuses = r.statuses()
    stamps = [s.t_rx_s - T0 for s in statuses]
    assert len(stamps) >= 20
    gaps = [round(b - a, 6) for a, b in itertools.pairwise(stamps[:-1])]
    assert sorted(set(gaps)) == [PERIOD_S, 2 * PERIOD_S]
    assert gaps.count(2 * PERIOD_S) == 1  # one period without RP_STATUS, no more
    steps = [(b.counter - a.counter) % 15 for a, b in itertools.pairwise(statuses)]
    assert steps.count(2) == 1  # the frame encoded but not sent
    assert set(steps) == {1, 2}
    assert len(r.bus.of(RP_ROAD_STATUS)) == len(statuses) + 1  # its RP_ROAD_STATUS went out
    lines = [rec.getMessage() for rec in caplog.records]
    assert sum(line.startswith("event=can_send_failed id=0x201") for line in lines) == 1
    assert any(line.startswith("event=can_send_recovered") for line in lines)


def test_a_sender_that_dies_is_restarted_and_one_that_keeps_dying_gives_up(
    caplog: pytest.LogCaptureFixture,
) -> None:
    clock = VirtualClock(0.0)
    sent: list[can.Message] = []
    failures: list[str] = []
    plan = iter([True, False, False, True, True, True, True] + [False] * 10)  # True: works

    def build() -> list[can.Message]:
        if not next(plan):
            raise RuntimeError("encoder bug")
        return [can.Message(arbitration_id=RP_STATUS, data=bytes(8))]

    policy = Supervision(max_restarts=3, backoff_s=0.25, max_backoff_s=0.45, healthy_s=0.3)
    def send(msg: can.Message) -> bool:
        sent.append(msg)
        return True

    sender = CyclicSender(
        "can-status",
        build,
        send,
        clock=clock,
        period_s=PERIOD_S,
        supervision=policy,
        on_failed=failures.append,
    )
    with caplog.at_level(logging.WARNING, logger="roadpreview.supervision"):
        sender.start()
        _until(lambda: clock.waiting >= 1)
        clock.advance(10.0)
    # sent at 0; died at 0.1 and, after a 0.25 s backoff, at 0.35 (the cycle carried on,
    # the periods missed skipped); after 0.45 s it sent at 0.8, 0.9, 1.0 and 1.1, then
    # died at 1.2: it had run 0.4 s, healthy, so that death is the first in a row again;
    # then at 1.45, 1.9 and 2.35: the 4th in a row, more than max_restarts: given up
    assert [round(m.timestamp, 6) for m in sent] == [0.0, 0.8, 0.9, 1.0, 1.1]
    assert sender.deaths == 6
    assert sender.thread.restarts == 5
    assert not sender.running
    assert failures == [sender.failed]
    assert sender.failed == (
        "can-status: the thread died 4 times in a row (last: RuntimeError: encoder bug); "
        "giving up"
    )
    lines = [rec.getMessage() for rec in caplog.records]
    assert sum(line.startswith("event=thread_died thread=can-status") for line in lines) == 6
    assert sum(line.startswith("event=thread_restarted") for line in lines) == 5
    assert lines[-1].startswith("event=thread_gave_up thread=can-status")


def test_rp_input_status_goes_out_while_inputs_are_rejected_then_once_more() -> None:
    clock = VirtualClock(T0)
    bus = _Bus()
    sink = CanBusSink(bus, cycle=StatusCycle(clock, PERIOD_S))
    frame = CameraFrame(T0, None, 0)
    result = cast("FrameResult", _Result(T0))
    totals = {"rejected_range": 0}

    def status() -> Status:
        return Status(mode=FusionMode.FUSED, input_problems_total=dict(totals))

    sink.on_frame(frame, result, status())  # starts the sender: first cycle at T0
    _until(lambda: clock.waiting >= 1)
    for _ in range(3):  # three periods with new rejects
        totals["rejected_range"] += 5
        sink.on_status(clock.now(), status())
        clock.advance(PERIOD_S)
    clock.advance(0.5)  # clean again
    sink.close(RunSummary())
    bus.shutdown()
    decoder = OutputDecoder()
    inputs = [decoder.decode(m) for m in bus.of(RP_INPUT_STATUS)]
    assert all(isinstance(i, ReceivedInputStatus) for i in inputs)
    got = [(i.degraded, i.counts["InputRangeRejects"]) for i in inputs]  # type: ignore[union-attr]
    assert got == [(True, 5), (True, 5), (True, 5), (False, 0)]  # then the all-clear, once
