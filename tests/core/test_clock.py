"""The clocks (`roadpreview.clock`): the system's, and the virtual one the real-time tests
run on (time moves only when the test moves it, and every thread it woke has done its
work before `advance` returns); `Cycle`, the one rule for periodic messages."""

from __future__ import annotations

import math
import threading
import time

import pytest

from roadpreview.clock import Cycle, SystemClock, VirtualClock, sleep_until


def _spawn(target: object, name: str) -> threading.Thread:
    th = threading.Thread(target=target, name=name, daemon=True)  # type: ignore[arg-type]
    th.start()
    return th


def _until_waiting(clock: VirtualClock, n: int) -> None:
    deadline = time.monotonic() + 30.0  # waiting for threads to start, not timing them
    while clock.waiting < n:
        assert time.monotonic() < deadline, "the threads did not start waiting"
        time.sleep(0.001)


def test_system_clock_reads_unix_time_and_waits_for_an_event() -> None:
    clock = SystemClock()
    assert abs(clock.now() - time.time()) < 1.0
    assert SystemClock(time.monotonic).now() == pytest.approx(time.monotonic(), abs=1.0)
    event = clock.event()
    assert clock.wait(event, 0.0) is False  # timed out at once
    event.set()
    assert clock.wait(event, None) is True
    assert sleep_until(clock, clock.now() + 60.0, event) is True  # stopped, not slept


def test_virtual_time_moves_only_when_advanced_and_wakes_in_deadline_order() -> None:
    clock = VirtualClock(100.0)
    woke: list[tuple[str, float]] = []
    stop = clock.event()

    def sleeper(name: str, at: float) -> None:
        if not sleep_until(clock, at, stop):
            woke.append((name, clock.now()))

    threads = [
        _spawn(lambda: sleeper("late", 100.3), "late"),
        _spawn(lambda: sleeper("early", 100.2), "early"),
    ]
    _until_waiting(clock, 2)
    time.sleep(0.05)  # real time passing moves nothing
    assert clock.now() == 100.0
    assert woke == []
    assert clock.next_deadline() == pytest.approx(100.2)
    assert clock.advance(0.25) == pytest.approx(100.25)
    assert [name for name, _ in woke] == ["early"]  # done by the time advance returned
    assert [t for _, t in woke] == pytest.approx([100.2])
    clock.advance(1.0)
    assert [name for name, _ in woke] == ["early", "late"]
    assert [t for _, t in woke] == pytest.approx([100.2, 100.3])
    assert clock.now() == pytest.approx(101.25)
    for th in threads:
        th.join(5.0)
        assert not th.is_alive()


def test_a_periodic_thread_runs_once_per_period_of_virtual_time() -> None:
    clock = VirtualClock()
    ticks: list[float] = []
    stop = clock.event()

    def ticker() -> None:
        t = 0.0
        while not sleep_until(clock, t, stop):
            ticks.append(clock.now())
            time.sleep(0.002)  # real work inside a tick: advance waits for it
            t += 0.1

    th = _spawn(ticker, "ticker")
    _until_waiting(clock, 1)
    clock.advance(1.0)
    assert ticks == pytest.approx([0.1 * k for k in range(11)])
    stop.set()  # the clock's own event: the ticker wakes at once, time stays
    th.join(5.0)
    assert not th.is_alive()
    assert clock.now() == pytest.approx(1.0)


def test_an_event_wakes_a_waiter_without_time_passing_and_settle_waits_for_it() -> None:
    clock = VirtualClock()
    work = clock.event()
    done: list[float] = []

    def worker() -> None:
        while clock.wait(work, 10.0):
            work.clear()
            time.sleep(0.01)
            done.append(clock.now())

    th = _spawn(worker, "worker")
    _until_waiting(clock, 1)
    work.set()
    clock.settle()
    assert done == [0.0]
    # a plain threading.Event (not the clock's) is looked at by polling: still seen
    plain = threading.Event()
    seen: list[bool] = []
    th2 = _spawn(lambda: seen.append(clock.wait(plain, None)), "plain")
    _until_waiting(clock, 2)
    plain.set()
    th2.join(5.0)
    assert seen == [True]
    clock.advance(10.0)  # the worker's timeout: it leaves the loop and ends
    th.join(5.0)
    assert not th.is_alive()


def test_a_thread_that_never_waits_again_is_named_not_waited_for_forever() -> None:
    clock = VirtualClock(settle_timeout_s=0.3)
    release = threading.Event()

    def stuck() -> None:
        sleep_until(clock, 1.0, clock.event())
        release.wait(10.0)  # blocked elsewhere, not on the clock

    th = _spawn(stuck, "stuck-thread")
    _until_waiting(clock, 1)
    with pytest.raises(TimeoutError, match="stuck-thread did not wait again"):
        clock.advance(2.0)
    release.set()
    th.join(5.0)


def test_a_thread_blocked_on_the_clock_lets_time_pass() -> None:
    """What a test does to hold a thread (the run loop) while time passes: the thread
    waits for an event with no timeout, which counts as waiting."""
    clock = VirtualClock()
    release = clock.event()
    after: list[float] = []

    def held() -> None:
        clock.wait(release, None)
        after.append(clock.now())

    th = _spawn(held, "held")
    _until_waiting(clock, 1)
    clock.advance(5.0)
    assert after == []
    release.set()
    clock.settle()
    assert after == [5.0]
    th.join(5.0)


def test_cycle_the_replay_rule_and_the_fixed_rate() -> None:
    frames = Cycle(0.25)  # the run loop's status on the frames' clock
    sent = []
    for k in range(12):
        t = k / 8 + (0.05 if k == 6 else 0.0)  # 8 fps, frame 6 late by 50 ms
        if frames.due(t):
            sent.append(k)
            frames.sent(t)
    assert sent == [0, 2, 4, 6, 9, 11]  # due a period after the frame that sent it
    timer = Cycle(0.1, fixed_rate=True)
    assert timer.due(5.0)
    timer.sent(5.0)
    assert timer.next_s == pytest.approx(5.1)
    timer.sent(5.13)  # 30 ms late: the grid holds
    assert timer.next_s == pytest.approx(5.2)
    timer.sent(5.45)  # more than a period late: the missed ones are skipped
    assert timer.next_s == pytest.approx(5.55)
    assert not timer.due(5.5)
    with pytest.raises(ValueError, match="period"):
        Cycle(0.0)
    assert Cycle(1.0).next_s == -math.inf
