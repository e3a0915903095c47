"""Issue 17, readers that resync: a damaged BLF, bad CAN log lines, bad frames.csv rows and a
damaged video each cost the samples they hold, not the drive; every case names the file,
counts what it lost and delivers the intact part as the clean file would."""

from __future__ import annotations

import logging
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus.logio import MAX_LOGGED_PROBLEMS, CanLogReader
from roadpreview.errors import InputDataError
from roadpreview.sim.canlog import write_drive_can
from roadpreview.sim.imu import ImuConfig, simulate_imu
from roadpreview.sources.can import CanLogSource, make_decoder
from roadpreview.sources.video import (
    ImageSequenceSource,
    VideoFileSource,
    fill_times,
    increasing_rows,
)
from roadpreview.types import ImuSample
from roadpreview.vision.frame_check import JUMP_GREY, FrameIntegrity, Verdict, thumbnail

FILES = Path(__file__).resolve().parents[1] / "files"
#: the drive of the input tests: 4 s at 30 fps, 640x360 (tests/sources/conftest.py)
DRIVE = {"duration_s": 4.0, "width": 640, "height": 360}


@pytest.fixture
def drive(make_recording: Callable[..., Any]) -> Any:
    return make_recording("demo", seed=0, **DRIVE)


def _decode_all(video: Path) -> list[np.ndarray | None]:
    """Every frame of ``video`` as OpenCV decodes it (None: undecodable), no checks."""
    cap = cv2.VideoCapture(str(video))
    frames = []
    for _ in range(int(cap.get(cv2.CAP_PROP_FRAME_COUNT))):
        ok, image = cap.read()
        frames.append(image if ok else None)
    cap.release()
    return frames


# --- CAN logs ---------------------------------------------------------------------------------


def _imu_log(path: Path, seconds: float) -> None:
    t = np.arange(0.0, seconds, 0.002)
    n = len(t)
    omega = np.column_stack([np.zeros(n), 0.2 * np.sin(7 * t), np.zeros(n)])
    imu = simulate_imu(
        t,
        omega,
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        ImuConfig.automotive(),
        np.random.default_rng(1),
    )
    write_drive_can(path, imu, None)


def _samples(path: Path) -> tuple[list[ImuSample], CanLogSource]:
    source = CanLogSource(path, make_decoder())
    samples = [s for s in source if isinstance(s, ImuSample)]
    return samples, source


def test_damaged_blf_costs_one_container_not_the_drive(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Before: 512 random bytes in the middle of a BLF lost everything after them."""
    clean = tmp_path / "clean.blf"
    _imu_log(clean, 60.0)  # 100 Hz IMU, two frames a sample: 12,000 frames, 5 containers
    data = clean.read_bytes()
    junk = np.random.default_rng(5).integers(0, 256, 512, dtype=np.uint8).tobytes()
    damaged = tmp_path / "damaged.blf"
    damaged.write_bytes(data[: len(data) // 2] + junk + data[len(data) // 2 :])
    want, _ = _samples(clean)
    with caplog.at_level(logging.WARNING):
        got, source = _samples(damaged)
    problems = source.problems
    assert problems["resynced"] == 1
    # the decoder sees the lost stretch as a time gap: the first frame of each ID after it
    # is held until the next confirms the new time (and the alive counter re-syncs)
    assert set(problems) <= {"resynced", "stamp_jump", "e2e_counter_jump"}
    assert problems["stamp_jump"] <= 2  # IMU_RATES and IMU_ACCEL, one frame each
    assert source.errors == 1 + source.decoder.stats.skipped
    assert "damaged.blf (byte " in caplog.text
    # what is missing is one stretch of at most one container: 128 KiB of 48-byte frames
    # (2,732 at most), at 200 frames/s at most 13.7 s of the log
    kept = {s.t_s for s in got}
    assert kept <= {s.t_s for s in want}  # nothing invented
    lost = [k for k, s in enumerate(want) if s.t_s not in kept]
    assert lost == list(range(lost[0], lost[-1] + 1))
    # (+ the frame the decoder holds after the gap: 10 ms)
    assert 0 < want[lost[-1]].t_s - want[lost[0]].t_s < 2732 / 200 + 0.011
    assert want[-1].t_s - want[lost[-1]].t_s > 15.0  # the drive goes on after the damage
    by_t = {s.t_s: s for s in want}
    assert all(s == by_t[s.t_s] for s in got)  # the samples kept are the clean ones


def test_bad_asc_lines_are_skipped_counted_and_not_logged_one_by_one(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    lines = (FILES / "imu_drive.asc").read_text().splitlines(True)
    head, body = lines[:5], lines[5:]
    garbled = head + [x for line in body for x in (line, "  0.5 1 12G Rx d 8 zz\n")]
    path = tmp_path / "noisy.asc"
    path.write_text("".join(garbled))
    clean = list(CanLogReader(FILES / "imu_drive.asc", errors="raise"))
    with caplog.at_level(logging.WARNING, logger="roadpreview.canbus.logio"):
        reader = CanLogReader(path)
        got = list(reader)
    assert [bytes(m.data) for m in got] == [bytes(m.data) for m in clean]
    n_bad = len(body) - 1  # (the one after the end-of-log line may count too)
    assert reader.counts["skipped_bad_line"] >= n_bad > 4 * MAX_LOGGED_PROBLEMS
    assert set(reader.counts) == {"skipped_bad_line"}
    # 10 lines, one saying the rest is only counted, one sum at the end; the file named
    records = [r for r in caplog.records if r.name == "roadpreview.canbus.logio"]
    assert len(records) == MAX_LOGGED_PROBLEMS + 2
    assert all(str(path) in r.getMessage() for r in records)
    assert f"skipped_bad_line {reader.counts['skipped_bad_line']}" in records[-1].getMessage()


# --- frames.csv -------------------------------------------------------------------------------


def test_increasing_rows_and_fill_times() -> None:
    t = np.arange(12) / 30.0
    t[3] = np.nan  # not a number
    t[6] = 5.0  # jumps ahead: later rows are not "out of order" because of it
    t[9] = 0.01  # jumps back
    good = increasing_rows(t)
    assert np.flatnonzero(~good).tolist() == [3, 6, 9]
    filled = fill_times(t, good, 1 / 30)
    np.testing.assert_allclose(filled, np.arange(12) / 30.0, atol=1e-12)
    ends = np.array([np.nan, 0.1, 0.2, 0.35, np.nan])  # ends: the median step, 0.125 s
    np.testing.assert_allclose(
        fill_times(ends, np.isfinite(ends), 1 / 30), [-0.025, 0.1, 0.2, 0.35, 0.475]
    )


def test_bad_frames_csv_rows_cost_their_frame_only(
    drive: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Before: one bad row stamped every later frame 33 ms late."""
    rows = drive.frames_csv.read_text().splitlines()
    true_t = np.array([float(r.split(",")[1]) for r in rows[1:]])
    bad = {10: "10,abc", 20: "20,nan", 30: "30,5.0", 40: "41,1.333333", 50: "50"}
    for k, text in bad.items():
        rows[k + 1] = text
    table = tmp_path / "frames.csv"
    table.write_text("\n".join(rows) + "\n")
    with caplog.at_level(logging.WARNING, logger="roadpreview.sources.video"):
        source = VideoFileSource(drive.video, frames_csv=table)
        stamps = np.array([f.t_s for f in source])
    assert stamps.size == true_t.size
    ok = np.ones(true_t.size, dtype=bool)
    ok[list(bad)] = False
    assert np.array_equal(stamps[ok], true_t[ok])  # the other frames keep their own stamps
    # a bad row's frame: interpolated from its neighbours on a 30 fps clock, < 1 µs off
    np.testing.assert_allclose(stamps[~ok], true_t[~ok], atol=1e-6)
    assert source.problems == {"bad_time_row": len(bad)}
    assert source.errors == 0  # no frame lost
    for k in bad:
        assert f"{table}:{k + 2}:" in caplog.text


@pytest.mark.parametrize("keep", [0.5, 1.05])
def test_frames_csv_with_the_wrong_number_of_rows_is_refused_before_processing(
    drive: Any, tmp_path: Path, keep: float
) -> None:
    """Before: a frames.csv with half its rows skipped half the video without a word."""
    folder = tmp_path / "rec"
    shutil.copytree(drive.folder, folder)
    rows = (folder / "frames.csv").read_text().splitlines()
    n = len(rows) - 1
    m = int(n * keep)
    extra = [f"{k},{k / 30:.6f}" for k in range(n, m)]
    (folder / "frames.csv").write_text("\n".join([*rows[: m + 1], *extra]) + "\n")
    match = rf"frames\.csv: {m} time stamps for the {n} frames of the video .*video\.mp4"
    with pytest.raises(InputDataError, match=match):
        replay(ReplayInputs.from_recording(folder), out=tmp_path / "out")
    assert not (tmp_path / "out" / "frames.csv").exists()  # refused before any frame


def test_image_folder_with_a_short_frames_csv_is_refused(tmp_path: Path) -> None:
    for k in range(4):
        cv2.imwrite(str(tmp_path / f"{k:03d}.png"), np.full((8, 8, 3), 40 * k, np.uint8))
    (tmp_path / "frames.csv").write_text("frame,t_s\n0,0.0\n1,0.1\n2,0.2\n")
    with pytest.raises(InputDataError, match=r"frames\.csv: 3 time stamps for the 4 frames"):
        ImageSequenceSource(tmp_path)


# --- a damaged video --------------------------------------------------------------------------


def _damage(video: Path, out: Path, n_bytes: int = 256 * 1024, seed: int = 0) -> Path:
    """``video`` with ``n_bytes`` random bytes written over its middle (bit rot: the
    container's index still points at the right places)."""
    data = video.read_bytes()
    junk = np.random.default_rng(seed).integers(0, 256, n_bytes, dtype=np.uint8).tobytes()
    mid = len(data) // 2
    out.write_bytes(data[:mid] + junk + data[mid + n_bytes :])
    return out


def test_clean_videos_have_no_corrupt_frame(drive: Any) -> None:
    source = VideoFileSource(drive.video)
    frames = list(source)
    assert all(f.image is not None for f in frames)
    assert source.problems == {}
    assert len(frames) == drive.info["n_frames"]


@pytest.mark.shared
def test_real_kitti_frames_are_no_content_jump(kitti_dir: Path) -> None:
    """The real frames at 10 fps (three times a 30 fps camera's motion per frame)."""
    check = FrameIntegrity()
    verdicts = []
    jumps = []
    for frame in ImageSequenceSource(kitti_dir / "frames", fps=10.0):
        assert frame.image is not None
        verdicts.append(check.check(thumbnail(frame.image)))
        jumps.append(check.last_jump)
    assert verdicts == [Verdict.GOOD] * 78
    assert max(jumps) < 0.9 * JUMP_GREY  # measured 9.4 grey levels


def test_damaged_video_delivers_only_true_frames_and_recovers(
    drive: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    clean = _decode_all(drive.video)
    damaged = _damage(drive.video, tmp_path / "damaged.mp4")
    raw = _decode_all(damaged)  # what the decoder makes of it, unchecked
    assert len(raw) == len(clean)

    def same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
        return a is not None and b is not None and bool(np.array_equal(a, b))

    wrong = [k for k, im in enumerate(raw) if im is not None and not same(im, clean[k])]
    undecodable = [k for k, im in enumerate(raw) if im is None]
    assert undecodable, "the damage makes frames undecodable"
    assert wrong, "and decodes others into what is not the scene (the test's premise)"
    with caplog.at_level(logging.WARNING, logger="roadpreview.sources.video"):
        source = VideoFileSource(damaged)
        frames = list(source)
    assert [f.index for f in frames] == list(range(len(clean)))  # read to the end
    # every image delivered is the scene: exactly the clean decode of that frame
    assert all(same(f.image, clean[f.index]) for f in frames if f.image is not None)
    dropped = [f.index for f in frames if f.image is None]
    assert dropped == list(range(dropped[0], dropped[-1] + 1))  # one stretch
    assert set(undecodable) | set(wrong) <= set(dropped)
    # recovery: good frames again at most one frame after the decoder's first true frame
    first_true = min(k for k in range(undecodable[-1], len(raw)) if same(raw[k], clean[k]))
    assert dropped[-1] <= first_true
    assert source.problems == {
        "undecodable_frame": len(undecodable),
        "corrupt_frame": len(dropped) - len(undecodable),
    }
    assert source.errors == len(dropped)
    assert f"{damaged}: frame {dropped[0]} " in caplog.text
    assert f"good again from frame {dropped[-1] + 1}" in caplog.text
    assert len(caplog.records) == 2  # one line when it starts, one when it ends


@pytest.mark.slow
def test_replay_of_a_damaged_video_has_no_false_alert(drive: Any, tmp_path: Path) -> None:
    """Before: the stream ended after 10 undecodable frames (the rest of the drive lost),
    and with fewer undecodable frames the decoder's garbage reached the vision."""
    folder = tmp_path / "rec"
    shutil.copytree(drive.folder, folder)
    _damage(drive.video, folder / "video.mp4")
    ref = replay(ReplayInputs.from_recording(drive.folder), keep_results=True)
    got = replay(ReplayInputs.from_recording(folder), keep_results=True)
    assert ref.results is not None
    assert got.results is not None
    assert got.frames == ref.frames == drive.info["n_frames"]
    failed = [k for k, r in enumerate(got.results) if r.vision_reason and not r.lead_found]
    lost = [
        k
        for k, (a, b) in enumerate(zip(ref.results, got.results, strict=True))
        if a.lead_found and not b.lead_found
    ]
    assert lost
    assert set(lost) <= set(failed)  # the frames dropped are vision failures, said so
    assert len(lost) <= got.decode_failures <= len(failed)
    # before the damage the run is the clean run, frame for frame
    first = lost[0]
    np.testing.assert_array_equal(
        [r.y_c for r in got.results[:first]], [r.y_c for r in ref.results[:first]]
    )
    # no false alert: the alerts are the clean run's (this short drive has none to lose)
    assert [(a.t_s, a.side) for a in got.alerts] == [(a.t_s, a.side) for a in ref.alerts]
