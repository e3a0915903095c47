"""Fixtures of the daemon's operations tests: a small recording (its video is the camera, its
CAN log the bus), a private virtual bus configuration, a systemd notification socket, and
`VirtualRun`: a daemon run on virtual time, moved on by the test (no sleeps, no wall-clock
deadlines: the same answers on an idle and on a loaded machine)."""

from __future__ import annotations

import os
import shutil
import socket
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import can
import pytest

from roadpreview.apps.daemon import Daemon, DaemonSummary
from roadpreview.apps.monitoring import SystemdNotifier
from roadpreview.clock import VirtualClock
from roadpreview.pipeline import PipelineConfig

#: where virtual time starts in the daemon tests (2025-01-01, a Unix time as the daemon reads)
VIRTUAL_T0 = 1_735_689_600.0
#: real seconds a daemon's thread may take to do what is due at one virtual time
SETTLE_S = 120.0


@pytest.fixture(scope="module")
def small_drive(make_recording):  # type: ignore[no-untyped-def]
    # the same arguments as tests/eval/test_runner.py: the session's cached recording is reused
    return make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180)


def _virtual_config(**daemon: Any) -> PipelineConfig:
    """The default configuration on a private python-can ``virtual`` channel, with
    ``daemon`` overrides."""
    cfg = PipelineConfig()
    can_cfg = replace(
        cfg.can, input_interface="virtual", input_channel=f"rp-test-{uuid.uuid4().hex}"
    )
    return replace(cfg, can=can_cfg, daemon=replace(cfg.daemon, **daemon))


def _run_in_thread(daemon: Daemon) -> tuple[threading.Thread, list[DaemonSummary]]:
    box: list[DaemonSummary] = []
    thread = threading.Thread(target=lambda: box.append(daemon.run()), name="daemon")
    thread.start()
    return thread, box


class VirtualRun:
    """``daemon`` (built with ``DaemonOptions(clock=clock)``) run in a thread on ``clock``,
    a `VirtualClock` the test moves on with `advance`. Lockstep: after every step of
    virtual time each thread of the daemon has done what was due (the clock settles on
    the threads that wait on it), the CAN frames the log player sent have reached the
    daemon's CAN source (python-can's notifier thread in between does not use the
    clock: waited for by its counts) and the loop has processed them. The loop never
    falls behind in virtual time, so a run is the same on an idle and on a loaded
    machine; only the real time it takes differs."""

    def __init__(self, daemon: Daemon, clock: VirtualClock) -> None:
        self.daemon = daemon
        self.clock = clock
        self.box: list[DaemonSummary] = []
        self.error: list[BaseException] = []
        self.thread = threading.Thread(target=self._run, name="daemon", daemon=True)
        cfg = daemon.config.daemon
        ping = bool(os.environ.get("NOTIFY_SOCKET")) and (
            SystemdNotifier.watchdog_period_s(cfg.watchdog_ping_s) > 0
        )
        # the loop (its merge), the camera and the CAN bus readers, the log player, the pinger
        waiting = 3 + (daemon.player is not None) + ping
        self.thread.start()
        _until(lambda: clock.waiting >= waiting or not self.thread.is_alive(), "start")
        clock.settle()

    def _run(self) -> None:
        try:
            self.box.append(self.daemon.run())
        except BaseException as exc:  # re-raised by `summary`
            self.error.append(exc)

    def _drained(self) -> None:
        _drain(self.daemon, self.clock, self.thread.is_alive)

    def advance(self, dt: float, step_s: float = 0.01) -> None:
        """Move virtual time on by ``dt`` in steps of ``step_s`` (or until the daemon ends)."""
        end = self.clock.now() + dt
        while self.clock.now() < end - 1e-9 and self.thread.is_alive():
            self.clock.advance_to(min(self.clock.now() + step_s, end))
            self._drained()

    def advance_until(
        self, condition: Callable[[], bool], limit_s: float, step_s: float = 0.01
    ) -> bool:
        """`advance` until ``condition()``, at most ``limit_s`` of virtual time; whether it
        came true."""
        end = self.clock.now() + limit_s
        while not condition():
            if self.clock.now() >= end or not self.thread.is_alive():
                return condition()
            self.advance(step_s, step_s)
        return True

    @property
    def summary(self) -> DaemonSummary:
        """The daemon's summary once it ended (its exception raised here)."""
        self.thread.join(timeout=SETTLE_S)
        assert not self.thread.is_alive(), "the daemon did not end"
        if self.error:
            raise self.error[0]
        return self.box[0]

    def finish(self, limit_s: float = 120.0) -> DaemonSummary:
        """Let the daemon run to its end (a file camera's last frame), at most ``limit_s``
        of virtual time."""
        self.advance_until(lambda: not self.thread.is_alive(), limit_s)
        return self.summary

    def stop(self) -> DaemonSummary:
        """What SIGTERM does (`Daemon.stop_event`), then the daemon's summary."""
        self.daemon.stop_event.set()
        return self.finish(limit_s=10.0)


def _drain(daemon: Daemon, clock: VirtualClock, running: Callable[[], bool]) -> None:
    """The frames the CAN log player sent have reached the daemon's CAN source (through
    python-can's notifier thread, which does not use the clock), unless the daemon is
    ending (``running()`` False), and the clock settled on what they caused."""
    player, can_in = daemon.player, daemon.can_in
    if player is not None:
        _until(lambda: can_in.frames + can_in.dropped >= player.sent or not running(), "CAN")
    clock.settle()


class ClockDriver:
    """Moves ``clock`` on in steps of ``step_s`` from a thread of its own while the test's
    thread runs what waits on it (``roadpreview run`` through `main`, which installs its
    signal handlers and so must run in the main thread), for at most ``limit_s`` of
    virtual time; a context manager. Time starts moving once ``threads`` threads wait on
    the clock (the daemon's, started); ``daemon()`` gives the daemon once it is built: the
    steps are then lockstep as `VirtualRun`'s."""

    def __init__(
        self,
        clock: VirtualClock,
        *,
        step_s: float = 0.01,
        limit_s: float = 120.0,
        threads: int = 1,
        daemon: Callable[[], Daemon | None] = lambda: None,
    ) -> None:
        self.clock = clock
        self.step_s = step_s
        self.end = clock.now() + limit_s
        self.threads = threads
        self.daemon = daemon
        self.done = threading.Event()
        self.error: list[BaseException] = []
        self.thread = threading.Thread(target=self._drive, name="clock-driver", daemon=True)

    def _drive(self) -> None:
        try:
            _until(lambda: self.clock.waiting >= self.threads or self.done.is_set(), "start")
            while not self.done.is_set() and self.clock.now() < self.end:
                self.clock.advance(self.step_s)
                daemon = self.daemon()
                if daemon is not None:
                    _drain(daemon, self.clock, lambda: not self.done.is_set())
        except BaseException as exc:  # raised in the test's thread at exit
            self.error.append(exc)

    def __enter__(self) -> ClockDriver:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.clock.leave()  # the test's thread is done with the clock
        self.done.set()
        self.thread.join(timeout=SETTLE_S)
        if self.error:
            raise self.error[0]


def _until(condition: Callable[[], bool], what: str) -> None:
    """Wait in real time for another thread (generously: not a timing)."""
    deadline = time.monotonic() + SETTLE_S
    while not condition():
        assert time.monotonic() < deadline, f"{what}: never happened"
        time.sleep(0.0005)


@pytest.fixture
def virtual_clock() -> VirtualClock:
    """A `VirtualClock` at `VIRTUAL_T0` that names a stuck thread after `SETTLE_S`."""
    return VirtualClock(VIRTUAL_T0, settle_timeout_s=SETTLE_S)


def _wait_for(condition: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


@pytest.fixture
def virtual_config() -> Callable[..., PipelineConfig]:
    """``virtual_config(**daemon_fields)``: the default configuration on a private python-can
    ``virtual`` channel."""
    return _virtual_config


@pytest.fixture
def run_in_thread() -> Callable[[Daemon], tuple[threading.Thread, list[DaemonSummary]]]:
    """``run_in_thread(daemon)``: the thread running it and a box for its summary."""
    return _run_in_thread


@pytest.fixture
def wait_for() -> Callable[..., bool]:
    """``wait_for(condition, timeout_s=10)``: poll until true; False on timeout."""
    return _wait_for


@dataclass
class NotifySocket:
    """A unix datagram socket standing in for systemd's: the notifications with the
    ``time.monotonic()`` they arrived at, read by a thread."""

    sock: socket.socket
    messages: list[tuple[float, str]] = field(default_factory=list)
    _stop: threading.Event = field(default_factory=threading.Event)

    def start(self) -> None:
        self.sock.settimeout(0.05)
        self._reader = threading.Thread(target=self._read, name="notify-socket", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                if self._stop.is_set():
                    return  # stopped, and nothing left to read
                continue
            except OSError:
                return
            self.messages.append((time.monotonic(), data.decode()))

    def drained(self, n: int) -> list[str]:
        """The messages once ``n`` have arrived (waiting for the reader thread)."""
        _until(lambda: len(self.messages) >= n, "notifications")
        return [m for _, m in self.messages]

    def close(self) -> None:
        self._stop.set()
        self._reader.join(timeout=SETTLE_S)
        self.sock.close()

    def times(self, prefix: str) -> list[float]:
        """Arrival times of the notifications that start with ``prefix``."""
        return [t for t, m in self.messages if m.startswith(prefix)]


@pytest.fixture
def notify_socket(monkeypatch: pytest.MonkeyPatch) -> Iterator[NotifySocket]:
    """NOTIFY_SOCKET pointing to a bound socket (a short path: unix sockets allow ~100
    characters); WATCHDOG_USEC and WATCHDOG_PID cleared."""
    folder = tempfile.mkdtemp(prefix="rp-notify-", dir="/tmp")
    path = os.path.join(folder, "notify")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(path)
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    monkeypatch.delenv("WATCHDOG_USEC", raising=False)
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    ns = NotifySocket(sock)
    ns.start()
    yield ns
    ns.close()
    shutil.rmtree(folder, ignore_errors=True)


class BusRecorder:
    """Every frame on a virtual bus channel from now until `close` (a receiver, as a
    chassis ECU or a logger would sit on the bus)."""

    def __init__(self, channel: str, *, preserve_timestamps: bool = False) -> None:
        from roadpreview.canbus.live import open_bus

        self.bus = open_bus("virtual", channel, preserve_timestamps=preserve_timestamps)
        self.reader = can.BufferedReader()
        self.notifier = can.Notifier(self.bus, [self.reader], timeout=0.02)

    def close(self) -> list[can.Message]:
        """Every frame received: those the notifier handed on, then those still queued on
        the bus (no wait: what was sent before this call is there)."""
        self.notifier.stop()
        out = []
        while (msg := self.reader.get_message(timeout=0.0)) is not None:
            out.append(msg)
        while (msg := self.bus.recv(timeout=0.0)) is not None:
            out.append(msg)
        self.bus.shutdown()
        return out
