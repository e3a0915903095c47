"""Every input kind replayed end to end on a short simulated drive: a video alone, a video
with a phone IMU CSV on its own clock, a video with a CAN log in every format python-can
reads, mixed clocks refused before processing."""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.apps.result import ReplayResult
from roadpreview.canbus import read_can_log
from roadpreview.canbus.logio import LOG_SUFFIXES, write_can_log
from roadpreview.cli.main import main
from roadpreview.errors import InputDataError
from roadpreview.sources.clocks import is_unix_time
from roadpreview.types import FusionMode

#: the phone's since-boot clock at the start of the drive (its IMU CSV's first stamps)
BOOT_S = 5321.25
#: camera-IMU offset the estimator must find, s: it resolves the 2 ms grid plus a parabola
OFFSET_TOL_S = 0.003
#: vehicle speed through the pipeline vs the simulator's true speed, m/s (CAN: 0.01 km/h
#: resolution, 20 ms means; the pipeline holds the last sample)
SPEED_TOL_MPS = 0.3


def _run(inputs: ReplayInputs, out: Path | None = None) -> ReplayResult:
    return replay(inputs, out=out, keep_results=True)


def _final(result: ReplayResult) -> Any:
    assert result.results is not None
    return result.results[-1]


def _imu_offset(drive: Any) -> float:
    """The simulated IMU's stamp lag, s (stamps = true time + this)."""
    return float(drive.info["imu_time_offset_s"])


def _assert_speed(drive: Any, result: ReplayResult, start: float) -> None:
    assert result.results is not None
    t = np.array([r.t - start for r in result.results])
    v = np.array([np.nan if r.ego_speed_mps is None else r.ego_speed_mps for r in result.results])
    truth = np.interp(t, drive.truth["speed_t_stamp_s"], drive.truth["speed_true_m_s"])
    ok = np.isfinite(v)
    assert ok.sum() > 0.9 * len(v)
    assert np.max(np.abs(v[ok] - truth[ok])) < SPEED_TOL_MPS


# --- a video alone ---------------------------------------------------------------------------


def test_video_alone_is_vision_only_with_unix_time_stamps(
    drive: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    video = tmp_path / "dashcam.mp4"
    shutil.copy(drive.video, video)
    end = 1_735_690_000.0
    os.utime(video, (end, end))  # the camera closed the file at the end of the drive
    caplog.set_level(logging.INFO)
    result = _run(ReplayInputs(video=video, camera=drive.camera), tmp_path / "out")
    n = drive.info["n_frames"]
    assert result.frames == n
    # frame 0 at the file's time minus the duration (n / fps), to the µs of the stamps
    assert result.video_start_s == pytest.approx(end - n / 30.0, abs=1e-6)
    assert "modification time minus its duration" in caplog.text
    assert "no IMU input: vision-only fusion" in caplog.text
    # every output was written, stamped in Unix time within the drive
    for name in ("alerts.blf", "alerts.jsonl", "frames.csv", "plots.png", "summary.json"):
        assert (tmp_path / "out" / name).is_file(), name
    stamps = [m.timestamp for m in read_can_log(tmp_path / "out" / "alerts.blf")]
    assert len(stamps) == pytest.approx(2 * 4.0 / 0.1, abs=4)  # RP_STATUS + RP_ROAD_STATUS
    assert all(end - 4.1 <= t <= end + 0.1 for t in stamps)
    # no IMU: never FUSED nor IMU_ONLY
    assert {m for _, m, _ in result.mode_changes} <= {FusionMode.VISUAL_ONLY, FusionMode.DEGRADED}
    assert _final(result).mode is FusionMode.VISUAL_ONLY
    assert "no IMU input" in result.mode_changes[-1][2]  # the mode said plainly
    # the summary says which clock rule was used
    rules = json.loads((tmp_path / "out" / "summary.json").read_text())["clock"]["rules"]
    assert any("modification time minus its duration" in r for r in rules)


# --- a video and a phone IMU CSV on its own clock ---------------------------------------------


def _boot_clock_csv(drive: Any, path: Path) -> Path:
    """The drive's IMU CSV as a phone logs it: stamps on its since-boot clock."""
    lines = drive.imu_csv.read_text().splitlines()
    out = []
    for line in lines:
        if line[:1].isdigit():
            t, rest = line.split(",", 1)
            line = f"{float(t) + BOOT_S:.6f},{rest}"
        out.append(line)
    path.write_text("\n".join(out) + "\n")
    return path


def test_video_and_phone_imu_csv_are_aligned_by_the_offset_estimator(
    drive: Any, tmp_path: Path
) -> None:
    csv = _boot_clock_csv(drive, tmp_path / "phone_imu.csv")
    first = float(drive.imu_csv.read_text().splitlines()[2].split(",")[0])  # true t + lag
    result = _run(ReplayInputs(video=drive.video, camera=drive.camera, imu_csv=csv))
    assert is_unix_time(result.video_start_s)
    final = _final(result)
    assert final.mode is FusionMode.FUSED
    # coarse rule: the first IMU stamp is put at frame 0 (t = 0), i.e. the stamps are moved
    # by -first; they lag the true times by the IMU's offset: what is left for the estimator
    expected = _imu_offset(drive) - first
    assert final.time_offset == pytest.approx(expected, abs=OFFSET_TOL_S)


def test_imu_offset_flag_overrides_the_coarse_rule(drive: Any, tmp_path: Path) -> None:
    csv = _boot_clock_csv(drive, tmp_path / "phone_imu.csv")
    out = tmp_path / "out"
    code = main(
        [
            "replay",
            str(drive.video),
            "--camera",
            str(drive.folder / "camera.toml"),
            "--imu-csv",
            str(csv),
            "--imu-offset",
            str(-BOOT_S),
            "--out",
            str(out),
        ]
    )
    assert code == 0
    rows = (out / "frames.csv").read_text().splitlines()
    header = rows[0].split(",")
    last = dict(zip(header, rows[-1].split(","), strict=True))
    # the CSV is now on the video's clock exactly: only the IMU's own lag is left
    assert last["mode"] == "FUSED"
    assert float(last["imu_time_offset_s"]) == pytest.approx(_imu_offset(drive), abs=OFFSET_TOL_S)


# --- a video and a CAN log, in every format -----------------------------------------------------

#: every suffix the log reader takes; at least the formats python-can reads and writes
CAN_SUFFIXES = list(LOG_SUFFIXES)
assert {".blf", ".asc", ".log", ".trc", ".csv", ".mf4", ".db"} <= set(CAN_SUFFIXES)


@pytest.mark.parametrize("suffix", CAN_SUFFIXES)
def test_video_and_can_log_in_each_format(drive: Any, tmp_path: Path, suffix: str) -> None:
    frames = list(read_can_log(drive.can_log()))
    log = tmp_path / f"drive{suffix}"
    assert write_can_log(log, frames) == len(frames)
    result = _run(ReplayInputs(video=drive.video, camera=drive.camera, can_logs=[log]))
    # the video starts with the log's first frame as recorded (the default rule)
    assert result.video_start_s == pytest.approx(frames[0].timestamp, abs=2e-6)
    assert result.input_errors == 0
    final = _final(result)
    assert final.mode is FusionMode.FUSED
    t0 = float(drive.info["can_t0_unix_s"])
    expected = _imu_offset(drive) - (frames[0].timestamp - t0)
    assert final.time_offset == pytest.approx(expected, abs=OFFSET_TOL_S)
    _assert_speed(drive, result, t0)


# --- mixed clocks ---------------------------------------------------------------------------------


def test_mixed_clocks_are_refused_before_processing(drive: Any, tmp_path: Path) -> None:
    out = tmp_path / "out"
    argv = [
        "replay",
        str(drive.video),
        "--camera",
        str(drive.folder / "camera.toml"),
        "--can",
        str(drive.can_log()),
        "--imu-csv",
        str(drive.imu_csv),
        "--out",
        str(out),
    ]
    inputs = ReplayInputs(
        video=drive.video, camera=drive.camera, can_logs=[drive.can_log()], imu_csv=drive.imu_csv
    )
    with pytest.raises(InputDataError, match="mixed clocks") as err:
        replay(inputs, out=out)
    message = str(err.value)
    for named in (str(drive.can_log()), str(drive.imu_csv), "0.039", "1735689600.0"):
        assert named in message  # both inputs and their first stamps
    assert "--imu-offset" in message
    assert not out.exists()  # nothing was processed
    assert main(argv) == 1
    # the offset that puts the CSV on the CAN log's clock makes them agree
    t0 = float(drive.info["can_t0_unix_s"])
    assert main([*argv, "--imu-offset", str(t0)]) == 0
    assert (out / "frames.csv").read_text().count("\n") == drive.info["n_frames"] + 1
