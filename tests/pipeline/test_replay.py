"""The streaming pipeline replaying simulator recordings: outputs, determinism, bad input."""

from __future__ import annotations

import json
import math
import shutil
import signal
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus import load_database, read_can_log
from roadpreview.canbus.received import (
    OutputDecoder,
    ReceivedAlert,
    ReceivedAlertDetail,
    ReceivedRoadStatus,
    ReceivedStatus,
)
from roadpreview.cli.main import main
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.pipeline import Pipeline, PipelineConfig
from roadpreview.sinks.files import AlertsJsonlSink
from roadpreview.types import Alert, CameraFrame, FusionMode


@pytest.fixture(scope="module")
def short_demo(make_recording):  # type: ignore[no-untyped-def]
    return make_recording("demo", seed=0, duration_s=8.0, width=1280, height=720)


def test_replay_writes_every_output_and_they_are_consistent(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    result = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path)
    n = short_demo.info["n_frames"]
    assert result.frames == n
    for name in ("alerts.blf", "alerts.jsonl", "frames.csv", "plots.png", "summary.json"):
        assert (tmp_path / name).is_file(), name
    rows = (tmp_path / "frames.csv").read_text().splitlines()
    assert len(rows) == n + 1  # header + one row per frame
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["frames"] == n
    assert summary["alerts"] == len(result.alerts)
    # the CAN output decodes: periodic status at about 10 Hz and every alert
    decoder = OutputDecoder()
    kinds = [decoder.decode(m) for m in read_can_log(tmp_path / "alerts.blf")]
    statuses = [k for k in kinds if isinstance(k, ReceivedStatus)]
    alerts = [k for k in kinds if isinstance(k, ReceivedAlert)]
    assert len(statuses) == pytest.approx(8.0 / 0.1, abs=3)
    # each alert repeated until the ego passed it (or the drive ended): its id, not its frames
    assert len({a.alert_id for a in alerts}) == len(result.alerts)
    # each RP_ALERT is followed by its RP_ALERT_DETAIL; RP_ROAD_STATUS goes with RP_STATUS
    for k, kind in enumerate(kinds):
        if isinstance(kind, ReceivedAlert):
            detail = kinds[k + 1]
            assert isinstance(detail, ReceivedAlertDetail)
            assert detail.alert_id == kind.alert_id
    roads = [k for k in kinds if isinstance(k, ReceivedRoadStatus)]
    assert [r.t_rx_s for r in roads] == [s.t_rx_s for s in statuses]
    assert decoder.problems == {}
    assert load_database().get_message_by_name("RP_STATUS") is not None


def test_replay_is_deterministic(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    a = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path / "a")
    b = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path / "b")
    for name in ("frames.csv", "alerts.jsonl"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert a.mode_changes == b.mode_changes


def test_compensated_pitch_tracks_the_true_pitch_at_high_frequency(short_demo) -> None:  # type: ignore[no-untyped-def]
    result = replay(ReplayInputs.from_recording(short_demo.folder), keep_results=True)
    assert result.results is not None
    phi = np.array([r.phi for r in result.results])
    truth = short_demo.truth["cam_pitch_rad"][: len(phi)]
    err = phi - (truth - truth[0])
    ok = np.isfinite(err)
    # remove the slow part (1 s moving average): what the 1 s detector window sees
    kernel = np.ones(31) / 31
    hp = err[ok] - np.convolve(err[ok], kernel, mode="same")
    assert np.degrees(np.std(hp[30:-30])) < 0.05


def test_missing_video_names_the_file(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    folder = tmp_path / "rec"
    shutil.copytree(short_demo.folder, folder)
    (folder / "video.mp4").unlink()
    with pytest.raises(InputDataError, match=r"video\.mp4"):
        replay(ReplayInputs.from_recording(folder))
    assert main(["replay", str(folder), "--out", str(tmp_path / "o")]) == 1


def test_truncated_video_is_a_clear_error(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    folder = tmp_path / "rec"
    shutil.copytree(short_demo.folder, folder)
    data = (folder / "video.mp4").read_bytes()
    (folder / "video.mp4").write_bytes(data[: len(data) // 2])  # the mp4 index is lost
    with pytest.raises(InputDataError, match=r"video\.mp4"):
        replay(ReplayInputs.from_recording(folder))


def test_corrupt_frame_in_the_middle_loses_no_other_frame(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    # an MJPG AVI (frames coded independently) with one frame's bytes overwritten
    src = cv2.VideoCapture(str(short_demo.video))
    avi = tmp_path / "cam.avi"
    writer = cv2.VideoWriter(str(avi), cv2.VideoWriter.fourcc(*"MJPG"), 30.0, (1280, 720))
    for _ in range(60):
        ok, frame = src.read()
        assert ok
        writer.write(frame)
    writer.release()
    data = bytearray(avi.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 4000] = bytes(4000)
    avi.write_bytes(bytes(data))
    inputs = ReplayInputs(
        video=avi,
        camera=short_demo.camera,
        can_logs=[short_demo.can_log()],
        video_start_s=float(short_demo.info["can_t0_unix_s"]),
    )
    result = replay(inputs, out=tmp_path / "out")
    assert result.frames + result.decode_failures >= 59
    assert (tmp_path / "out" / "frames.csv").is_file()


def test_garbage_frames_are_no_target_not_a_crash(short_demo) -> None:  # type: ignore[no-untyped-def]
    pipe = Pipeline(short_demo.camera, PipelineConfig())
    for i, frame in enumerate([None, np.zeros((720, 1280, 3), np.uint8), np.zeros((10, 10)), "x"]):
        r = pipe.push(CameraFrame(0.1 * (i + 1), frame))  # type: ignore[arg-type]
        assert not r.lead_found
        assert r.vision_reason
        assert math.isnan(r.y_c)


def test_no_imu_on_the_bus_falls_back_to_visual_only(short_demo) -> None:  # type: ignore[no-untyped-def]
    # the CAN log holds no frame the pipeline can map (another car's log): no gyro
    inputs = ReplayInputs.from_recording(short_demo.folder)
    inputs.can_logs = []
    result = replay(inputs, max_frames=120)
    assert result.mode_changes[-1][1] == FusionMode.VISUAL_ONLY


def test_example_configuration_loads_and_unknown_keys_are_named(tmp_path: Path) -> None:
    example = Path(__file__).resolve().parents[2] / "data" / "roadpreview.example.toml"
    assert PipelineConfig.load(example) == PipelineConfig()
    bad = tmp_path / "bad.toml"
    bad.write_text("[fusion]\nbackend = 'kalman'\nbakend = 'x'\n")
    with pytest.raises(ConfigError, match=r"fusion\.bakend"):
        PipelineConfig.load(bad)


def test_sigint_during_replay_keeps_every_alert_emitted_so_far(  # type: ignore[no-untyped-def]
    short_demo, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C in the middle of a drive: the outputs are complete and readable up to that
    point, and the summary says the replay was interrupted. The SIGINT is a real signal to
    this process (`signal.raise_signal`), raised right after the first alert reached the
    disk: at the same point of the drive however loaded the machine is."""
    import roadpreview.apps.replay as replay_module

    out = tmp_path / "out"
    alerts_jsonl = out / "alerts.jsonl"
    on_disk: list[str] = []

    class InterruptAfterFirstAlert(AlertsJsonlSink):
        def _append(self, alerts: Sequence[Alert]) -> None:
            super()._append(alerts)
            if alerts and not on_disk:
                # streamed: the first alert is on disk while the replay runs
                on_disk.extend(alerts_jsonl.read_text().splitlines())
                signal.raise_signal(signal.SIGINT)

    monkeypatch.setattr(replay_module, "AlertsJsonlSink", InterruptAfterFirstAlert)
    code = main(["replay", str(short_demo.folder), "--out", str(out), "-q"])
    err = capsys.readouterr().err
    assert code == 130, err
    assert len(on_disk) >= 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert 0 < summary["frames"] < int(short_demo.info["n_frames"])
    lines = [json.loads(x) for x in alerts_jsonl.read_text().splitlines()]
    assert len(lines) == summary["alerts"] >= 1
    rows = (out / "frames.csv").read_text().splitlines()
    assert len(rows) == summary["frames"] + 1  # every processed frame, and the header
    can_alerts = [
        m for m in read_can_log(out / "alerts.blf", errors="raise") if m.arbitration_id == 0x200
    ]
    # each alert repeated until passed (or the stop): its id once, in order
    ids = list(dict.fromkeys(m.data[2] for m in can_alerts))
    assert ids == [a["alert_id"] % 256 for a in lines]


def test_a_receiver_follows_each_alert_and_reassembles_the_preview_from_the_replay_log(  # type: ignore[no-untyped-def]
    short_demo,
    tmp_path: Path,
) -> None:
    """Issue 27 on a replayed drive: the CAN log's alerts, through the reference receiver,
    go PROVISIONAL -> CONFIRMED -> ENDED, or PROVISIONAL -> ENDED (CANCELLED, NOT_CONFIRMED),
    or CONFIRMED -> ENDED; every one ends; the confirmed ones are the run's alerts and the
    provisional ones the run's provisional alerts. RP_PREVIEW reassembles to snapshots with
    valid bins, whose heights on this smooth road are those of a road (centimetres)."""
    from roadpreview.canbus import AlertReceiver, PreviewAssembler
    from roadpreview.canbus.receiver import ReceiverState
    from roadpreview.canbus.repetition import EndCause, EndReason

    result = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path)
    frames = read_can_log(tmp_path / "alerts.blf")
    dec = OutputDecoder()
    rx = AlertReceiver()
    previews = PreviewAssembler()
    snapshots = []
    for msg in frames:
        item = dec.decode(msg)
        rx.push(item)
        p = previews.push(item)
        if p is not None:
            snapshots.append(p)
    lives: dict[int, list[ReceiverState]] = {}
    for tr in rx.transitions:
        lives.setdefault(tr.alert_id, []).append(tr.after)
    assert lives, "the 8 s demo raises alerts"
    allowed = (
        [ReceiverState.PROVISIONAL, ReceiverState.CONFIRMED, ReceiverState.ENDED],
        [ReceiverState.PROVISIONAL, ReceiverState.ENDED],
    )
    for states in lives.values():
        assert states in allowed
    ended = {tr.alert_id: tr.life for tr in rx.transitions if tr.after is ReceiverState.ENDED}
    confirmed = {i for i, s in lives.items() if ReceiverState.CONFIRMED in s}
    for alert_id, life in ended.items():
        if alert_id not in confirmed:  # never confirmed: cancelled (or stopped at the end)
            assert life.reason is EndReason.CANCELLED
            assert life.cause in (EndCause.NOT_CONFIRMED, EndCause.STOPPED)
    run = result.run
    assert len(confirmed) == len(run.alerts)
    assert len(lives) == len(run.provisional) + sum(
        not math.isfinite(a.t_first_s) for a in run.alerts
    )
    assert not rx.problems
    assert snapshots, "RP_PREVIEW goes out while a lead is tracked"
    valid = np.concatenate([s.height_m[s.valid] for s in snapshots])
    assert valid.size > 0
    assert np.percentile(np.abs(valid), 95) < 0.1  # within 10 cm: a road, not a blow-up
