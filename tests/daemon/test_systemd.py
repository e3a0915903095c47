"""systemd ``Type=notify``: READY at the first frame, WATCHDOG pings while frames go through
(and not while the loop hangs or, if asked, while the camera is lost), STATUS, STOPPING.
systemd's socket is a unix datagram socket bound here (NOTIFY_SOCKET). The daemon runs on
virtual time (`VirtualRun`): the pings' times are its clock's, noted as each notification
is sent, and the socket must have received the same notifications in the same order."""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import pytest
from tests.daemon.conftest import VirtualRun

from roadpreview.apps.daemon import Daemon, DaemonOptions
from roadpreview.apps.monitoring import SystemdNotifier
from roadpreview.clock import VirtualClock
from roadpreview.errors import ConfigError
from roadpreview.pipeline import PipelineConfig
from roadpreview.types import CameraFrame, Sample

if TYPE_CHECKING:
    from pathlib import Path

    from tests.daemon.conftest import NotifySocket

Sent = list[tuple[float, str]]


@pytest.fixture
def sent(monkeypatch: pytest.MonkeyPatch, virtual_clock: VirtualClock) -> Sent:
    """Every notification the daemon sends, with the virtual time it was sent at."""
    out: Sent = []
    notify = SystemdNotifier.notify

    def noted(self: SystemdNotifier, state: str) -> None:
        out.append((virtual_clock.now(), state))
        notify(self, state)

    monkeypatch.setattr(SystemdNotifier, "notify", noted)
    return out


def _times(sent: Sent, prefix: str) -> list[float]:
    return [t for t, m in sent if m.startswith(prefix)]


def _on_the_wire(sent: Sent, socket: NotifySocket) -> list[str]:
    """The notifications as systemd's socket received them: those sent, in order."""
    msgs = socket.drained(len(sent))
    assert msgs == [m for _, m in sent]
    return msgs


def test_watchdog_period_comes_from_the_environment_or_the_configuration(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    monkeypatch.setenv("WATCHDOG_USEC", "3000000")  # WatchdogSec=3
    assert SystemdNotifier.watchdog_period_s() == pytest.approx(1.5)
    assert SystemdNotifier.watchdog_period_s(0.2) == pytest.approx(0.2)  # configured wins
    monkeypatch.setenv("WATCHDOG_PID", str(os.getpid() + 1))  # meant for another process
    assert SystemdNotifier.watchdog_period_s() == 0.0
    monkeypatch.setenv("WATCHDOG_PID", str(os.getpid()))
    assert SystemdNotifier.watchdog_period_s() == pytest.approx(1.5)
    monkeypatch.delenv("WATCHDOG_USEC")
    assert SystemdNotifier.watchdog_period_s() == 0.0  # no WatchdogSec: no pings


def test_without_notify_socket_nothing_is_sent(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    notifier = SystemdNotifier()
    notifier.notify("READY=1")
    assert not notifier.enabled
    assert notifier.sent == 0


def test_ready_then_watchdog_pings_status_and_stopping(
    small_drive: Any,
    notify_socket: NotifySocket,
    monkeypatch: pytest.MonkeyPatch,
    virtual_config: Callable[..., PipelineConfig],
    virtual_clock: VirtualClock,
    sent: Sent,
) -> None:
    monkeypatch.setenv("WATCHDOG_USEC", "200000")  # WatchdogSec=0.2: a ping every 0.1 s
    cfg = virtual_config(status_log_period_s=1.0)
    options = DaemonOptions(
        camera_source=str(small_drive.video), can_log=small_drive.can_log(), clock=virtual_clock
    )
    summary = VirtualRun(Daemon(small_drive.camera, cfg, options), virtual_clock).finish()
    msgs = _on_the_wire(sent, notify_socket)
    assert msgs[0].startswith("READY=1\nSTATUS=running, first frame processed, camera ok")
    assert msgs[-1] == "STOPPING=1"
    ready = _times(sent, "READY=1")[0]
    pings = _times(sent, "WATCHDOG=1")
    assert pings[0] > ready
    # pinged every 0.1 s over the 3 s of video: never a gap systemd would take for a hang
    assert len(pings) >= 20
    assert max(b - a for a, b in itertools.pairwise(pings)) < 0.2
    statuses = [m for m in msgs if m.startswith("STATUS=t=")]
    assert len(statuses) == summary.status_lines >= 2  # every status line goes to systemd
    assert all(" mode=" in m and " fps=" in m and " camera=ok" in m for m in statuses)
    assert summary.watchdog_withheld == 0


def _block_after(
    daemon: Daemon, n_frames: int, release: threading.Event, clock: VirtualClock
) -> threading.Event:
    """Make the pipeline hang (as a deadlock would) at the ``n_frames``-th camera frame
    until ``release`` (waiting on the clock: virtual time goes on meanwhile); returns the
    event set when it starts hanging."""
    push = daemon.pipeline.push
    seen = [0]
    hanging = threading.Event()

    def hanging_push(sample: Sample) -> Any:
        if isinstance(sample, CameraFrame) and sample.index >= 0:
            seen[0] += 1
            if seen[0] == n_frames:
                hanging.set()
                clock.wait(release, None)
        return push(sample)

    daemon.pipeline.push = hanging_push  # type: ignore[method-assign]
    return hanging


def test_pings_stop_while_the_loop_hangs_and_resume_after(
    small_drive: Any,
    notify_socket: NotifySocket,
    virtual_config: Callable[..., PipelineConfig],
    virtual_clock: VirtualClock,
    sent: Sent,
) -> None:
    cfg = virtual_config(watchdog_ping_s=0.05, watchdog_stall_s=0.6, camera_timeout_s=0.3)
    options = DaemonOptions(camera_source=str(small_drive.video), clock=virtual_clock)
    daemon = Daemon(small_drive.camera, cfg, options)
    release = virtual_clock.event()
    hanging = _block_after(daemon, 15, release, virtual_clock)
    run = VirtualRun(daemon, virtual_clock)
    assert run.advance_until(hanging.is_set, limit_s=10.0)
    t_hang = virtual_clock.now()
    assert run.advance_until(lambda: bool(_times(sent, "STATUS=unhealthy")), limit_s=10.0)
    run.advance(0.6)  # well past the watchdog's period: no ping went out
    t_check = virtual_clock.now()
    release.set()
    summary = run.finish()
    _on_the_wire(sent, notify_socket)
    pings = _times(sent, "WATCHDOG=1")
    before = [t for t in pings if t < t_hang]
    assert len(before) >= 3  # healthy while the first frames went through
    # the last ping came within the stall time after the hang began; none after it
    during = [t for t in pings if t_hang <= t <= t_check]
    assert all(t < t_hang + 0.6 + 0.1 for t in during)
    unhealthy = [m for _, m in sent if m.startswith("STATUS=unhealthy")]
    assert unhealthy[0].startswith("STATUS=unhealthy: loop stalled: no frame processed for")
    assert _times(sent, "STATUS=unhealthy")[0] <= t_hang + 0.6 + 0.05 + 1e-9  # a period late
    assert any(t > t_check for t in pings), "the pings did not resume after the hang"
    assert summary.watchdog_withheld == 1


@pytest.mark.parametrize("camera_lost_s", [0.0, 0.5])
def test_a_lost_camera_stops_the_pings_only_when_configured(
    camera_lost_s: float,
    small_drive: Any,
    notify_socket: NotifySocket,
    virtual_config: Callable[..., PipelineConfig],
    virtual_clock: VirtualClock,
    sent: Sent,
    tmp_path: Path,
    first_frames: Callable[[Path, Path, int], Path],
) -> None:
    # a camera that delivers 10 frames and then goes silent; the loop goes on with the
    # camera watchdog's image-less frames (DEGRADED status on the bus)
    short = first_frames(small_drive.video, tmp_path / "short.avi", 10)
    cfg = virtual_config(
        watchdog_ping_s=0.05, camera_timeout_s=0.3, watchdog_camera_lost_s=camera_lost_s
    )
    options = DaemonOptions(camera_source=str(short), stop_at_end=False, clock=virtual_clock)
    daemon = Daemon(small_drive.camera, cfg, options)
    run = VirtualRun(daemon, virtual_clock)
    assert run.advance_until(lambda: daemon.camera_watchdog.gap_frames > 0, limit_s=10.0)
    t_lost = virtual_clock.now()
    run.advance(1.2)
    t_end = virtual_clock.now()
    run.stop()
    _on_the_wire(sent, notify_socket)
    late = [t for t in _times(sent, "WATCHDOG=1") if t_lost + 0.8 < t < t_end]
    if camera_lost_s == 0:
        assert len(late) >= 4  # the daemon is alive and says DEGRADED: no restart
    else:
        assert late == []
        unhealthy = [m for _, m in sent if m.startswith("STATUS=unhealthy")]
        assert unhealthy == [unhealthy[0]]
        assert unhealthy[0].startswith("STATUS=unhealthy: camera lost for")


def test_stall_time_must_exceed_the_camera_timeout(
    small_drive: Any, virtual_config: Callable[..., PipelineConfig]
) -> None:
    cfg = virtual_config(watchdog_stall_s=0.5, camera_timeout_s=0.5)
    with pytest.raises(
        ConfigError, match=r"watchdog_stall_s = 0\.5 s must exceed camera_timeout_s"
    ):
        Daemon(small_drive.camera, cfg, DaemonOptions(camera_source=str(small_drive.video)))
