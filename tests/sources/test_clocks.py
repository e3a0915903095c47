"""One clock for a drive: the rules of `plan_clocks`, mixed clocks refused, the video's own
time from its container or its file time."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

from roadpreview.errors import InputDataError
from roadpreview.sources.clocks import (
    CameraClock,
    LogClock,
    VideoTime,
    mp4_creation_time,
    plan_clocks,
    video_file_time,
)

OWN = VideoTime(1_700_000_100.0, "test")
CAN_UNIX = 1_735_689_642.25


def _camera(start: float | None = None, first_rel: float = 0.0) -> CameraClock:
    return CameraClock("video v.mp4", first_rel, start, OWN)


def _can(first: float, offset: float | None = None) -> LogClock:
    return LogClock("CAN log a.blf", first, offset, "--can-offset")


def _imu(first: float, offset: float | None = None) -> LogClock:
    return LogClock("IMU CSV i.csv", first, offset, "--imu-offset")


def test_video_alone_is_put_at_its_own_time() -> None:
    plan = plan_clocks(_camera(), [])
    assert plan.camera_start_s == OWN.t_s
    assert "test" in plan.notes[0]


def test_the_video_starts_with_a_unix_log_and_a_floating_imu_csv_with_the_video() -> None:
    plan = plan_clocks(_camera(), [_can(CAN_UNIX)])
    assert plan.camera_start_s == CAN_UNIX
    assert plan.offsets_s == {"CAN log a.blf": 0.0}
    # a phone IMU on its since-boot clock, alone with the video: first sample at frame 0
    plan = plan_clocks(_camera(), [_imu(5321.25)])
    assert plan.camera_start_s == OWN.t_s
    assert plan.offsets_s["IMU CSV i.csv"] + 5321.25 == pytest.approx(OWN.t_s, abs=1e-6)


def test_an_offset_shifts_a_log_against_the_video() -> None:
    # the video started 2.5 s after the logger: the CAN log moves 2.5 s back, frame 0 stays
    plan = plan_clocks(_camera(), [_can(CAN_UNIX, offset=-2.5)])
    assert plan.camera_start_s == CAN_UNIX
    assert plan.offsets_s["CAN log a.blf"] == -2.5
    # an IMU offset onto the video's own clock (0 = frame 0), then all on the video's time
    plan = plan_clocks(_camera(), [_imu(5321.25, offset=-5321.0)])
    assert plan.camera_start_s == OWN.t_s
    assert 5321.25 + plan.offsets_s["IMU CSV i.csv"] == pytest.approx(OWN.t_s + 0.25, abs=1e-6)


@pytest.mark.parametrize(
    ("camera", "logs", "named"),
    [
        # a phone IMU CSV from 0 and a CAN log on Unix time (the silent mix of issue 16)
        (
            _camera(),
            [_can(CAN_UNIX), _imu(0.04)],
            ("CAN log a.blf", "IMU CSV i.csv", "--imu-offset"),
        ),
        # a video pinned near 0 and a CAN log on Unix time
        (_camera(start=0.0), [_can(CAN_UNIX)], ("video v.mp4", "CAN log a.blf", "--video-start")),
        # an offset that does not make them agree
        (_camera(), [_can(CAN_UNIX), _imu(0.04, offset=100.0)], ("IMU CSV i.csv", "--imu-offset")),
    ],
)
def test_mixed_clocks_are_refused_naming_both(
    camera: CameraClock, logs: list[LogClock], named: tuple[str, ...]
) -> None:
    with pytest.raises(InputDataError, match="mixed clocks") as err:
        plan_clocks(camera, logs)
    message = str(err.value)
    assert "\n" not in message
    for text in named:
        assert text in message
    assert f"{CAN_UNIX:.6f}" in message or "0.000000" in message


def test_an_offset_that_puts_both_on_unix_time_is_accepted() -> None:
    plan = plan_clocks(_camera(), [_can(CAN_UNIX), _imu(0.04, offset=CAN_UNIX - 0.04 + 1.0)])
    assert plan.camera_start_s == CAN_UNIX
    assert 0.04 + plan.offsets_s["IMU CSV i.csv"] == pytest.approx(CAN_UNIX + 1.0)
    assert plan.warnings == []


def test_a_drive_without_unix_clock_is_moved_as_a_whole() -> None:
    # a CAN logger without a clock (from 0) given an offset, the video pinned at 0
    plan = plan_clocks(_camera(start=0.0), [_can(12.0, offset=-10.0)])
    assert plan.camera_start_s == OWN.t_s
    assert 12.0 + plan.offsets_s["CAN log a.blf"] == pytest.approx(OWN.t_s + 2.0)


def test_a_log_far_from_the_video_is_reported() -> None:
    plan = plan_clocks(_camera(start=CAN_UNIX - 3600.0), [_can(CAN_UNIX)])
    assert len(plan.warnings) == 1
    assert "+3600.0 s" in plan.warnings[0]


def _tiny_mp4(path: Path) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), 10.0, (64, 48))
    for k in range(10):
        writer.write(np.full((48, 64, 3), 20 * k, np.uint8))
    writer.release()


def test_mp4_creation_time_read_from_the_mvhd_box(tmp_path: Path) -> None:
    path = tmp_path / "cam.mp4"
    _tiny_mp4(path)
    data = bytearray(path.read_bytes())
    at = data.index(b"mvhd") + 4
    assert data[at] == 0  # version 0: 32-bit seconds since 1904
    unix = 1_735_689_642
    struct.pack_into(">I", data, at + 4, unix + 2_082_844_800)
    path.write_bytes(bytes(data))
    assert mp4_creation_time(path) == float(unix)
    assert video_file_time(path, 1.0) == VideoTime(float(unix), "the container's creation time")
    # a camera without a clock writes 0: the file's time minus the duration is used
    struct.pack_into(">I", data, at + 4, 0)
    path.write_bytes(bytes(data))
    os.utime(path, (1_700_000_010.0, 1_700_000_010.0))
    assert mp4_creation_time(path) is None
    got = video_file_time(path, 1.0)
    assert got.t_s == pytest.approx(1_700_000_009.0, abs=1e-3)
    assert "modification time" in got.rule


def test_no_creation_time_in_other_files(tmp_path: Path) -> None:
    (tmp_path / "x.avi").write_bytes(b"RIFF" + bytes(100))
    assert mp4_creation_time(tmp_path / "x.avi") is None
    assert mp4_creation_time(tmp_path / "missing.mp4") is None
