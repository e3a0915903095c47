"""The daemon end to end without hardware: a video file as the camera (paced), a python-can
``virtual`` bus fed at recorded pace with the recording's CAN log by the daemon's own player
(``can_log``, what ``run --can-log`` uses), alerts and status received on another bus object;
checked against the replay of the same recording. On virtual time (`VirtualRun`): the
daemon never falls behind, however loaded the machine."""

from __future__ import annotations

import uuid
from dataclasses import replace
from pathlib import Path

import pytest
from tests.daemon.conftest import SETTLE_S, VIRTUAL_T0, BusRecorder, VirtualRun

from roadpreview.apps.daemon import Daemon, DaemonOptions
from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus import read_can_log
from roadpreview.canbus.received import (
    OutputDecoder,
    ReceivedAlert,
    ReceivedAlertDetail,
    ReceivedOutput,
    ReceivedRoadStatus,
    ReceivedStatus,
)
from roadpreview.clock import VirtualClock
from roadpreview.loop import Pace
from roadpreview.pipeline import PipelineConfig
from roadpreview.types import FusionMode

START_DELAY_S = 1.0  # the daemon's threads and the feeder start before frame 0 is due


@pytest.fixture(scope="module")
def short_demo(make_recording):  # type: ignore[no-untyped-def]
    # the same arguments as test_replay.py: the session's cached recording is reused
    return make_recording("demo", seed=0, duration_s=8.0, width=1280, height=720)


def _config(channel: str, out_channel: str = "") -> PipelineConfig:
    cfg = PipelineConfig()
    can_cfg = replace(
        cfg.can,
        input_interface="virtual",
        input_channel=channel,
        output_interface="virtual" if out_channel else "",
        output_channel=out_channel,
    )
    return replace(cfg, can=can_cfg)


class _Collector(BusRecorder):
    """Receive everything on a bus object (its own notifier) for decoding afterwards."""

    def decoded(self) -> list[ReceivedOutput]:
        decoder = OutputDecoder()
        out: list[ReceivedOutput] = []
        for msg in self.close():
            decoded = decoder.decode(msg)
            if decoded is not None:
                out.append(decoded)
        return out


def _clock() -> VirtualClock:
    return VirtualClock(VIRTUAL_T0, settle_timeout_s=SETTLE_S)


def test_daemon_on_virtual_bus_matches_the_replay(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """The daemon reading the video at recorded pace (half speed) with its CAN log played
    onto a virtual bus on the same clock by its player gives exactly the replay's frame
    table: the same frame time stamps, fusion inputs, modes, scores and alerts."""
    channel = f"roadpreview-daemon-{uuid.uuid4().hex}"
    recorded_t0 = float(short_demo.info["can_t0_unix_s"])
    n_frames = int(short_demo.info["n_frames"])
    fps = float(short_demo.info["fps"])
    collector = _Collector(channel)
    clock = _clock()
    started = clock.now()
    pace = Pace(0.5, t0=recorded_t0, wall0=started + START_DELAY_S, clock=clock)
    cfg = _config(channel)
    # CAN frames stamped before a frame reach the daemon within 0.2 s (sample clock)
    cfg = replace(cfg, daemon=replace(cfg.daemon, can_latency_s=0.2))
    daemon = Daemon(
        short_demo.camera,
        cfg,
        DaemonOptions(
            camera_source=str(short_demo.video),
            camera_start_s=recorded_t0,
            frames_csv=short_demo.folder / "frames.csv",
            pace=pace,
            alerts_log=tmp_path / "alerts.blf",
            frame_table=tmp_path / "daemon_frames.csv",
            can_log=short_demo.can_log(),
            video_start_s=recorded_t0,  # the log's stamps stay as recorded
            clock=clock,
        ),
    )
    summary = VirtualRun(daemon, clock).finish()  # stops at the end of the video
    assert daemon.player is not None
    assert not daemon.player.running  # stopped with the daemon
    received = collector.decoded()
    # paced: the run took the video's length at half speed on the daemon's clock
    assert clock.now() - started >= START_DELAY_S + (n_frames - 1) / fps / pace.rate
    assert summary.frames_dropped == 0, "the daemon fell behind"
    assert summary.camera_read_failures == 0
    assert summary.frames_processed == n_frames
    assert summary.frames_out_of_order == 0
    assert summary.frame_ms.n == summary.frames_processed
    assert 0.0 < summary.frame_ms.quantile(0.5) <= summary.frame_ms.quantile(0.99)
    assert summary.frame_ms.quantile(0.99) <= summary.frame_ms.max
    assert summary.fields()["frame_ms_max"] == round(summary.frame_ms.max, 2)
    assert summary.can_frames > 0
    assert summary.can_input_errors == 0
    assert summary.can_queue_drops == 0
    assert summary.imu_timeouts == 0  # the gyro kept pace with the camera
    assert summary.can_log_errors == 0
    # the player sent the log up to the end of the video (and the daemon received it all)
    assert summary.can_log_sent >= summary.can_frames > 0

    # the replay of the same recording: identical frame by frame, and the same alerts
    ref = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path / "replay")
    daemon_rows = (tmp_path / "daemon_frames.csv").read_text().splitlines()
    replay_rows = (tmp_path / "replay" / "frames.csv").read_text().splitlines()
    assert len(daemon_rows) == len(replay_rows) == n_frames + 1
    for k, (d, r) in enumerate(zip(daemon_rows, replay_rows, strict=True)):
        assert d == r, f"frame row {k} differs"
    assert summary.mode_changes == ref.mode_changes
    assert summary.alerts == ref.alerts

    # status: 10 Hz of the frames' clock over the run, E2E-valid (OutputDecoder checks CRC
    # and counter), stamped on the frames' clock
    statuses = [m for m in received if isinstance(m, ReceivedStatus)]
    span = statuses[-1].t_rx_s - statuses[0].t_rx_s
    assert span > 0.8 * n_frames / fps
    assert len(statuses) == pytest.approx(n_frames / fps / 0.1 + 1, rel=0.2)
    assert statuses[-1].mode == summary.mode_changes[-1][1]  # the pipeline's mode
    assert statuses[-1].alert_count == len(summary.alerts) % 16
    # the road status goes with every status
    roads = [m for m in received if isinstance(m, ReceivedRoadStatus)]
    assert len(roads) == pytest.approx(len(statuses), abs=2)

    # the alerts on the bus are the daemon's own, in order, each with its details
    # (each alert repeated until the ego passed it: its first frame)
    got = [m for m in received if isinstance(m, ReceivedAlert)]
    got = [m for k, m in enumerate(got) if m.alert_id not in {g.alert_id for g in got[:k]}]
    details = {m.alert_id: m for m in received if isinstance(m, ReceivedAlertDetail)}
    assert len(got) == len(summary.alerts)
    assert len(details) == len(summary.alerts)
    for rx, sent in zip(got, summary.alerts, strict=True):
        assert rx.alert_id == sent.alert_id % 256
        assert rx.side == sent.side
        assert rx.mode == sent.mode
        detail = details[rx.alert_id]
        assert detail.detector == _config(channel).anomaly.detector
        assert detail.score == pytest.approx(min(sent.severity_px, 50.8), abs=0.11)
    # ... and the alerts log holds them too (written, flushed, closed)
    logged = [OutputDecoder().decode(m) for m in read_can_log(tmp_path / "alerts.blf")]
    assert len({m.alert_id for m in logged if isinstance(m, ReceivedAlert)}) == len(summary.alerts)
    assert len({m.alert_id for m in logged if isinstance(m, ReceivedAlertDetail)}) == len(
        summary.alerts
    )


def test_stop_event_shuts_down_cleanly_and_closes_the_log(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    channel = f"roadpreview-daemon-{uuid.uuid4().hex}"
    out_channel = f"roadpreview-daemon-out-{uuid.uuid4().hex}"
    collector = _Collector(out_channel)
    log_path = tmp_path / "alerts.asc"
    clock = _clock()
    daemon = Daemon(
        short_demo.camera,
        _config(channel, out_channel),
        DaemonOptions(camera_source=str(short_demo.video), alerts_log=log_path, clock=clock),
    )
    assert daemon.output_bus is not daemon.input_bus
    run = VirtualRun(daemon, clock)
    run.advance(1.5)
    summary = run.stop()  # what SIGINT / SIGTERM do
    received = collector.decoded()
    assert summary.interrupted
    assert 0 < summary.frames_processed < int(short_demo.info["n_frames"])
    assert daemon.input_bus._is_shutdown
    assert daemon.output_bus._is_shutdown
    # the log was flushed and closed: the ASC writer's footer is there
    assert log_path.read_text().rstrip().endswith("End TriggerBlock")
    statuses = [m for m in received if isinstance(m, ReceivedStatus)]
    assert statuses, "no RP_STATUS on the output bus"


def test_camera_watchdog_reports_vision_failure(short_demo, tmp_path: Path, first_frames) -> None:  # type: ignore[no-untyped-def]
    # a camera that delivers 10 frames and then goes silent (no IMU on the bus either)
    short = first_frames(short_demo.video, tmp_path / "short.avi", 10)
    channel = f"roadpreview-daemon-{uuid.uuid4().hex}"
    collector = _Collector(channel)
    cfg = _config(channel)
    cfg = replace(cfg, daemon=replace(cfg.daemon, camera_timeout_s=0.3))
    clock = _clock()
    options = DaemonOptions(camera_source=str(short), stop_at_end=False, clock=clock)
    run = VirtualRun(Daemon(short_demo.camera, cfg, options), clock)
    assert run.advance_until(lambda: run.daemon.camera_watchdog.gap_frames >= 5, limit_s=10.0)
    run.advance(0.3)  # a few status periods after the watchdog fired
    summary = run.stop()
    received = collector.decoded()
    assert summary.camera_timeouts == 1
    assert summary.camera_gap_frames >= 5
    assert summary.frames_processed + summary.frames_dropped == 10
    assert summary.imu_timeouts == 1  # no gyro on this bus
    statuses = [m for m in received if isinstance(m, ReceivedStatus)]
    assert statuses[-1].mode == FusionMode.DEGRADED
    assert summary.mode_changes[-1][1] == FusionMode.DEGRADED
