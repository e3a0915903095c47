"""The periodic status line (`StatusMonitor`) and the CAN log player (`CanLogPlayer`, what
``run --can-log`` uses): content on synthetic input and on a short daemon run; a garbled log
and a bus that refuses frames are counted, never fatal. Daemon runs and the player's pace
are on virtual time (`VirtualRun`, `VirtualClock`)."""

from __future__ import annotations

import itertools
import logging
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import can
import pytest
from tests.daemon.conftest import BusRecorder, VirtualRun

from roadpreview.apps.daemon import Daemon, DaemonOptions, iter_summary_lines
from roadpreview.apps.monitoring import StatusMonitor
from roadpreview.canbus import read_can_log
from roadpreview.canbus.live import CanLogPlayer, open_bus
from roadpreview.clock import VirtualClock
from roadpreview.pipeline import FrameResult, PipelineConfig
from roadpreview.types import CameraFrame, FusionMode, Status

FILES = Path(__file__).resolve().parents[1] / "files"


def _fields(line: str) -> dict[str, str]:
    return dict(kv.split("=", 1) for kv in line.split())


def test_status_line_counts_fps_drops_and_alerts_on_the_frames_clock() -> None:
    lines: list[str] = []
    monitor = StatusMonitor(1.0, lambda: {"bus_errors": 7, "camera": "ok"}, on_line=lines.append)
    status = Status(mode=FusionMode.FUSED)
    no_alert = cast("FrameResult", SimpleNamespace(alerts=[]))
    one_alert = cast("FrameResult", SimpleNamespace(alerts=[object()]))
    for i in range(31):  # 10 Hz for 3 s; frames 5 and 6 never reach the loop's end
        t = 100.0 + i / 10
        if i in (5, 6):
            continue
        monitor.on_frame(CameraFrame(t, None, i), one_alert if i == 12 else no_alert, status)
        monitor.on_status(t, status)
    # an image-less frame of the camera watchdog is neither a frame nor a drop
    monitor.on_frame(CameraFrame(103.05, None, -1), no_alert, status)
    assert monitor.frames == 29
    assert monitor.drops == 2
    assert len(lines) == monitor.lines == 3
    first, second, _ = (_fields(line) for line in lines)
    assert first["event"] == "status"
    assert first["t"] == "101"
    assert first["mode"] == "FUSED"
    assert float(first["fps"]) == pytest.approx(8.0)  # 8 frames (2 dropped) in 1 s
    assert (first["frames"], first["drops"], first["alerts"]) == ("9", "2", "0")
    assert (first["bus_errors"], first["camera"]) == ("7", "ok")
    assert float(second["fps"]) == pytest.approx(10.0)
    assert (second["frames"], second["alerts"]) == ("19", "1")


def test_status_line_on_a_short_run(
    small_drive: Any,
    virtual_config: Callable[..., PipelineConfig],
    virtual_clock: VirtualClock,
    caplog: pytest.LogCaptureFixture,
) -> None:
    cfg = virtual_config(status_log_period_s=0.5)
    options = DaemonOptions(
        camera_source=str(small_drive.video), can_log=small_drive.can_log(), clock=virtual_clock
    )
    daemon = Daemon(small_drive.camera, cfg, options)
    with caplog.at_level(logging.INFO, logger="roadpreview.apps.daemon"):
        summary = VirtualRun(daemon, virtual_clock).finish()
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("event=status ")]
    assert len(lines) == summary.status_lines
    duration = int(small_drive.info["n_frames"]) / float(small_drive.info["fps"])
    assert len(lines) == pytest.approx(duration / 0.5 - 1, abs=1)
    rows = [_fields(line) for line in lines]
    keys = "t mode fps frames drops alerts bus_errors can_in can_errors imu camera can_log_sent"
    assert all(set(keys.split()) <= set(r) for r in rows)
    times = [float(r["t"]) for r in rows]
    assert all(0.45 <= b - a <= 0.65 for a, b in itertools.pairwise(times))
    for a, b in itertools.pairwise(rows):  # fps: the frames between two lines
        frames = int(b["frames"]) - int(a["frames"])
        assert float(b["fps"]) * (float(b["t"]) - float(a["t"])) == pytest.approx(frames, abs=0.6)
    last = rows[-1]
    assert last["mode"] == "FUSED"  # the log's IMU on the bus
    assert (last["imu"], last["camera"], last["bus_errors"], last["can_errors"]) == (
        "ok",
        "ok",
        "0",
        "0",
    )
    assert 0 < int(last["can_in"]) <= int(last["can_log_sent"])
    assert int(last["frames"]) <= summary.frames_processed
    assert int(last["alerts"]) <= len(summary.alerts)
    # the drops seen from the frames' indices are the loop's own count
    assert daemon.monitor is not None
    assert daemon.monitor.drops == summary.frames_dropped + summary.frames_out_of_order


class _Now:
    """A schedule on which every time stamp is due at once (plays as fast as it can)."""

    def start(self, t0: float) -> None:
        pass

    def sleep_until(self, t: float, stop: threading.Event) -> bool:
        return stop.is_set()


@pytest.fixture
def channel() -> str:
    return f"rp-player-{uuid.uuid4().hex}"


def test_player_restamps_onto_the_anchor_at_recorded_pace(channel: str) -> None:
    recorded = list(read_can_log(FILES / "imu_drive.log"))
    rx = BusRecorder(channel)
    tx = open_bus("virtual", channel, preserve_timestamps=True)
    clock = VirtualClock(1000.0)
    sent_at: list[float] = []  # the player's clock when each frame went out
    send = tx.send

    def noted(msg: can.Message, timeout: float | None = None) -> None:
        sent_at.append(clock.now())
        send(msg, timeout)

    tx.send = noted  # type: ignore[method-assign]
    anchor = clock.now() + 0.2
    player = CanLogPlayer(FILES / "imu_drive.log", tx, anchor_s=anchor, clock=clock)
    player.start()
    assert _waiting(clock)
    while player.running:  # the player's waits are on the clock: moved on here
        clock.advance(0.001)
    got = rx.close()
    tx.shutdown()
    assert player.sent == len(recorded) == len(got) == 50
    assert player.errors == 0
    shift = anchor - recorded[0].timestamp
    for sent, rec, at in zip(got, recorded, sent_at, strict=True):
        assert sent.arbitration_id == rec.arbitration_id
        assert bytes(sent.data) == bytes(rec.data)
        assert sent.timestamp == pytest.approx(rec.timestamp + shift, abs=1e-6)
        # at recorded pace: each frame sent when its new stamp is due, not at once
        assert at == pytest.approx(sent.timestamp, abs=1e-6)
    assert sent_at[-1] - sent_at[0] == pytest.approx(0.19, abs=0.01)


def _waiting(clock: VirtualClock) -> bool:
    """A thread waits on the clock (it started), within a generous real time."""
    deadline = time.monotonic() + 30.0
    while clock.waiting == 0 and time.monotonic() < deadline:
        time.sleep(0.001)
    return clock.waiting > 0


def _join(player: CanLogPlayer, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while player.running and time.monotonic() < deadline:
        time.sleep(0.01)
    return not player.running


def test_player_loops_with_later_stamps(channel: str) -> None:
    rx = BusRecorder(channel)
    tx = open_bus("virtual", channel, preserve_timestamps=True)
    player = CanLogPlayer(FILES / "imu_drive.log", tx, anchor_s=0.0, schedule=_Now(), loop=True)
    player.start()
    deadline = time.monotonic() + 5.0
    while player.laps < 3 and time.monotonic() < deadline:
        time.sleep(0.005)
    player.stop()
    got = rx.close()
    tx.shutdown()
    assert player.laps >= 3
    stamps = [m.timestamp for m in got]
    assert stamps == sorted(stamps)  # each lap after the previous one
    recorded = [m.timestamp for m in read_can_log(FILES / "imu_drive.log")]
    span = recorded[-1] - recorded[0] + player.lap_gap_s
    assert stamps[50] == pytest.approx(span, abs=1e-6)  # lap 2 starts one span later
    assert stamps[100] == pytest.approx(2 * span, abs=1e-6)


def test_player_counts_garbled_frames_and_refused_sends(channel: str) -> None:
    rx = BusRecorder(channel)
    tx = open_bus("virtual", channel, preserve_timestamps=True)
    player = CanLogPlayer(FILES / "garbled.asc", tx, schedule=_Now())
    player.start()
    assert _join(player, 5.0)
    got = rx.close()
    assert player.garbled == 3  # the three bad lines: logged, skipped
    assert player.sent == len(got) == 50  # every good frame, also those after a bad line
    assert player.failures == 0

    class Refusing(can.BusABC):
        def __init__(self) -> None:
            super().__init__(channel="refusing")
            self.calls = 0

        def send(self, msg: can.Message, timeout: float | None = None) -> None:
            self.calls += 1
            if self.calls % 2:
                raise can.CanOperationError("transmit buffer full")

        def _recv_internal(self, timeout: float | None) -> tuple[None, bool]:
            return None, False

    bus = Refusing()
    player = CanLogPlayer(FILES / "imu_drive.log", bus, schedule=_Now())
    player.start()
    assert _join(player, 5.0)
    bus.shutdown()
    tx.shutdown()
    assert bus.calls == 50  # the player went on after each refusal
    assert (player.send_errors, player.sent, player.failures) == (25, 25, 0)


def test_daemon_keeps_running_on_a_garbled_can_log(
    small_drive: Any,
    virtual_config: Callable[..., PipelineConfig],
    virtual_clock: VirtualClock,
) -> None:
    options = DaemonOptions(
        camera_source=str(small_drive.video),
        can_log=FILES / "garbled.log",
        can_log_loop=True,
        clock=virtual_clock,
    )
    daemon = Daemon(small_drive.camera, virtual_config(), options)
    summary = VirtualRun(daemon, virtual_clock).finish()
    assert summary.frames_processed == int(small_drive.info["n_frames"])  # to the video's end
    assert summary.can_log_errors >= 3  # garbled lines, every lap
    assert summary.can_log_sent > 0
    assert summary.can_input_errors > 0  # the E2E-failing and the short frames, decoded live
    assert daemon.player is not None
    assert daemon.player.failures == 0
    assert daemon.player.laps >= 5  # 0.19 s a lap over a 3 s video: it kept looping
    lines = list(iter_summary_lines(summary))
    assert f"CAN log player: {summary.can_log_sent} frames sent" in "\n".join(lines)
