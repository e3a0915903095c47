"""Fixtures of the daemon's operations tests: a small recording (its video is the camera, its
CAN log the bus), a private virtual bus configuration, a systemd notification socket."""

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
from roadpreview.pipeline import PipelineConfig


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
        threading.Thread(target=self._read, name="notify-socket", daemon=True).start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                return
            self.messages.append((time.monotonic(), data.decode()))

    def close(self) -> None:
        self._stop.set()
        time.sleep(0.1)
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
        time.sleep(0.1)
        self.notifier.stop()
        self.bus.shutdown()
        out = []
        while (msg := self.reader.get_message(timeout=0.0)) is not None:
            out.append(msg)
        return out
