"""The streaming pipeline replaying simulator recordings: outputs, determinism, bad input."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from roadpreview.canbus import load_database, read_can_log
from roadpreview.canbus.output import OutputDecoder, ReceivedAlert, ReceivedStatus
from roadpreview.cli.main import main
from roadpreview.errors import InputDataError
from roadpreview.fusion.mode import FusionMode
from roadpreview.pipeline import Pipeline, PipelineConfig
from roadpreview.pipeline.replay import ReplayInputs, replay


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
    assert len(alerts) == len(result.alerts)
    assert load_database().get_message_by_name("RP_STATUS") is not None


def test_replay_is_deterministic(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    a = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path / "a")
    b = replay(ReplayInputs.from_recording(short_demo.folder), out=tmp_path / "b")
    assert (tmp_path / "a" / "frames.csv").read_bytes() == (tmp_path / "b" / "frames.csv").read_bytes()
    assert (tmp_path / "a" / "alerts.jsonl").read_bytes() == (tmp_path / "b" / "alerts.jsonl").read_bytes()
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
    with pytest.raises(InputDataError, match="video.mp4"):
        replay(ReplayInputs.from_recording(folder))
    assert main(["replay", str(folder), "--out", str(tmp_path / "o")]) == 1


def test_truncated_video_gives_outputs_for_what_was_valid(short_demo, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    folder = tmp_path / "rec"
    shutil.copytree(short_demo.folder, folder)
    data = (folder / "video.mp4").read_bytes()
    (folder / "video.mp4").write_bytes(data[: len(data) // 2])
    try:
        result = replay(ReplayInputs.from_recording(folder), out=tmp_path / "out")
    except InputDataError as exc:  # the container index may be lost with the tail
        assert "video.mp4" in str(exc)
    else:
        assert 0 < result.frames <= short_demo.info["n_frames"]
        assert (tmp_path / "out" / "frames.csv").is_file()


def test_garbage_frames_are_no_target_not_a_crash(short_demo) -> None:  # type: ignore[no-untyped-def]
    pipe = Pipeline(short_demo.camera, PipelineConfig())
    for i, frame in enumerate([None, np.zeros((720, 1280, 3), np.uint8), np.zeros((10, 10)), "x"]):
        r = pipe.push_frame(0.1 * (i + 1), frame)
        assert not r.lead_found
        assert r.vision_reason
        assert math.isnan(r.y_c)


def test_no_imu_on_the_bus_falls_back_to_visual_only(short_demo) -> None:  # type: ignore[no-untyped-def]
    # the CAN log holds no frame the pipeline can map (another car's log): no gyro
    inputs = ReplayInputs.from_recording(short_demo.folder)
    inputs.can_logs = []
    result = replay(inputs, max_frames=120)
    assert result.mode_changes[-1][1] == FusionMode.VISUAL_ONLY
