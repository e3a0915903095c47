"""CAN log files: one set of frames through every format python-can reads; damaged files; a
real log."""

from __future__ import annotations

import gzip
import logging
import shutil
from collections import defaultdict
from pathlib import Path

import can
import numpy as np
import pytest
from can.io.blf import BLFWriter

from roadpreview.canbus.logio import CanLogReader, read_can_log, write_can_log
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.sim.canlog import write_drive_can
from roadpreview.sim.imu import ImuConfig, simulate_imu

T0 = 1735689600.0  # 2025-01-01T00:00:00Z
#: timestamp resolution of each format as python-can writes it
RESOLUTION = {".blf": 1e-9, ".asc": 1e-6, ".log": 1e-6, ".asc.gz": 1e-6, ".log.gz": 1e-6,
              ".trc": 2e-6, ".trc.gz": 2e-6, ".csv": 0.0, ".csv.gz": 0.0,  # TRC: ms + day count
              ".mf4": 0.0, ".db": 0.0}
ALL_SUFFIXES = [".blf", ".asc", ".log", ".trc", ".csv", ".mf4", ".db",
                ".asc.gz", ".log.gz", ".trc.gz", ".csv.gz"]
#: formats without a channel column
NO_CHANNEL = (".csv", ".csv.gz", ".db")


def _frames(n: int = 400, seed: int = 0) -> list[can.Message]:
    """Varied frames on channel 0: standard and extended IDs, DLC 0..8, irregular times."""
    rng = np.random.default_rng(seed)
    t = T0 + 12.3456789 + np.cumsum(rng.uniform(1e-5, 4e-3, n))
    out = []
    for k in range(n):
        ext = k % 7 == 3
        dlc = 8 if k % 5 else int(rng.integers(0, 9))
        out.append(can.Message(
            timestamp=float(t[k]),
            arbitration_id=int(rng.integers(0, 0x1FFFFFFF if ext else 0x7FF)),
            is_extended_id=ext,
            dlc=dlc,
            data=bytes(rng.integers(0, 256, dlc, dtype=np.uint8)),
            channel=0,
        ))
    return out


def _assert_same(got: list[can.Message], want: list[can.Message], tol: float) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert (g.arbitration_id, g.is_extended_id, bytes(g.data)) == (
            w.arbitration_id, w.is_extended_id, bytes(w.data))
        assert g.timestamp == pytest.approx(w.timestamp, abs=tol)


@pytest.mark.parametrize("suffix", ALL_SUFFIXES)
def test_round_trip_through_each_format(tmp_path: Path, suffix: str) -> None:
    frames = _frames()
    path = tmp_path / f"drive{suffix}"
    assert write_can_log(path, frames) == len(frames)
    reader = CanLogReader(path, errors="raise")
    got = list(reader)
    _assert_same(got, frames, RESOLUTION[suffix] + 5e-7)  # + float64 spacing at 1.7e9 s
    assert reader.problems == []
    # CSV and SQLite have no channel column
    assert {m.channel for m in got} == ({None} if suffix in NO_CHANNEL else {0})
    if not suffix.endswith(".gz"):
        # python-can's own LogReader sees the same (ASC: ask for absolute times)
        with can.LogReader(path, relative_timestamp=False) as plain_reader:
            plain = list(plain_reader)
        _assert_same(plain, frames, RESOLUTION[suffix] + 5e-7)


def test_channel_numbering_in_each_format(tmp_path: Path) -> None:
    frames = _frames(5)
    write_can_log(tmp_path / "a.asc", frames)
    write_can_log(tmp_path / "a.log", frames)
    asc, log = (tmp_path / "a.asc").read_text(), (tmp_path / "a.log").read_text()
    assert " 1  " in asc.splitlines()[5]  # ASC numbers channels from 1
    assert log.splitlines()[0].split()[1] == "can0"


def test_all_formats_agree_on_a_simulated_drive(tmp_path: Path) -> None:
    t = np.arange(0.0, 2.0005, 0.001)
    n = len(t)
    omega = np.column_stack([np.zeros(n), 0.2 * np.sin(7 * t), np.zeros(n)])
    imu = simulate_imu(t, omega, np.zeros((n, 3)), np.zeros((n, 3)), ImuConfig.automotive(),
                       np.random.default_rng(1))
    logs = {}
    for suffix in (".blf", ".asc", ".log"):
        write_drive_can(tmp_path / f"sim{suffix}", imu, None)
        logs[suffix] = list(read_can_log(tmp_path / f"sim{suffix}", errors="raise"))
    _assert_same(logs[".asc"], logs[".blf"], 1e-6)
    _assert_same(logs[".log"], logs[".blf"], 1e-6)
    assert len(logs[".blf"]) == 2 * len(imu)


# --- damaged files ----------------------------------------------------------------------------


def test_truncated_blf_keeps_frames_and_reports_the_file(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    frames = _frames(6000)
    path = tmp_path / "cut.blf"
    write_can_log(path, frames)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])
    with caplog.at_level(logging.WARNING, logger="roadpreview.canbus.logio"):
        reader = CanLogReader(path)
        got = list(reader)
    assert 0.3 * len(frames) < len(got) < len(frames)
    _assert_same(got, frames[: len(got)], 1e-9)
    assert len(reader.problems) == 1
    assert reader.problems[0].fatal
    assert "truncated" in caplog.text
    assert str(path) in caplog.text
    # errors="raise": the same frames first, then the error naming the file
    frames_then_error = read_can_log(path, errors="raise")
    seen = [next(frames_then_error) for _ in range(len(got))]
    _assert_same(seen, got, 0.0)
    with pytest.raises(InputDataError, match=r"cut\.blf.*truncated"):
        next(frames_then_error)


def test_blf_of_a_logger_that_was_never_closed(tmp_path: Path) -> None:
    frames = _frames(3000)
    writer = can.BLFWriter(tmp_path / "live.blf")
    for m in frames:
        writer.on_message_received(m)
    writer.file.flush()
    shutil.copy(tmp_path / "live.blf", tmp_path / "crash.blf")  # what a power cut leaves
    writer.stop()
    reader = CanLogReader(tmp_path / "crash.blf")
    got = list(reader)
    assert 0 < len(got) < len(frames)
    # the header (with the start date) is only written on close: times are relative
    start = int(frames[0].timestamp * 1000) / 1000
    for m in frames:
        m.timestamp -= start
    _assert_same(got, frames[: len(got)], 1e-6)
    assert len(reader.problems) == 1
    assert "never finalised" in reader.problems[0].reason
    assert "relative" in reader.problems[0].reason


def _insert(lines: list[str], at: dict[int, str]) -> list[str]:
    """Insert text lines so that each lands on the given 1-based line number."""
    out = list(lines)
    for line_no in sorted(at):
        out.insert(line_no - 1, at[line_no] + "\n")
    return out


@pytest.mark.parametrize(("suffix", "garbage"), [
    (".log", {40: "(1735689612.5) can0 12G#0011", 41: "complete nonsense",
              90: "(17356896xx.5) can0 123#00"}),
    (".asc", {40: " 0.500000 1  12G             Rx   d 8 00 00 00 00 00 00 00 00",
              41: " 0.500100 1  123             Rx   d 8 00 00 ZZ 00 00 00 00 00",
              60: "complete nonsense",  # not frame-like: ASC readers skip such events
              90: " 0.600000 1  123             Rx   d"}),
    (".trc", {40: "      7      5.000 DT  1     012G Rx -  8    00 00 00 00 00 00 00 00",
              41: "complete nonsense",
              90: "      9      6.000 DT"}),
    (".csv", {40: "1735689612.5,0x12G,0,0,0,8,AAAAAAAAAAA=",
              41: "complete nonsense",
              90: "1735689612.6,0x123,0,0,0,8"}),
])
def test_garbage_lines_are_skipped_and_frames_after_them_kept(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, suffix: str, garbage: dict[int, str]
) -> None:
    frames = _frames()
    clean = tmp_path / f"clean{suffix}"
    write_can_log(clean, frames)
    path = tmp_path / f"garbled{suffix}"
    path.write_text("".join(_insert(clean.read_text().splitlines(True), garbage)))
    with caplog.at_level(logging.WARNING, logger="roadpreview.canbus.logio"):
        reader = CanLogReader(path)
        got = list(reader)
    _assert_same(got, frames, 1e-6)  # nothing lost, nothing invented
    bad_lines = [p.line for p in reader.problems]
    expected = [40, 41, 90]
    assert bad_lines == expected
    for line_no in expected:
        assert f"{path}:{line_no}:" in caplog.text
    with pytest.raises(InputDataError, match=rf"garbled\{suffix}:40:"):
        list(read_can_log(path, errors="raise"))


def test_truncated_gzip_log_keeps_the_frames_before_the_cut(tmp_path: Path) -> None:
    frames = _frames(3000)
    path = tmp_path / "cut.log.gz"
    write_can_log(path, frames)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    reader = CanLogReader(path)
    got = list(reader)
    assert 0 < len(got) < len(frames)
    _assert_same(got, frames[: len(got)], 1e-6)
    assert reader.problems
    assert reader.problems[-1].fatal


#: frames held (at least in part) by one BLF container as python-can writes them: 128 KiB
#: of 48-byte CAN_MESSAGE2 objects (16 base header + 16 v1 header + 16 message), the first
#: and last straddling into the neighbouring containers
FRAMES_PER_CONTAINER = -(-BLFWriter.max_container_size // 48) + 1


def _lost(got: list[can.Message], frames: list[can.Message]) -> list[int]:
    """Indices of ``frames`` missing from ``got``; ``got`` must hold nothing else."""
    key = {(m.timestamp, m.arbitration_id, bytes(m.data)) for m in got}
    kept = [
        k for k, m in enumerate(frames) if (m.timestamp, m.arbitration_id, bytes(m.data)) in key
    ]
    assert len(kept) == len(got)  # nothing invented
    return sorted(set(range(len(frames))) - set(kept))


@pytest.mark.parametrize("mode", ["insert", "overwrite"])
def test_blf_resyncs_after_512_random_bytes(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, mode: str
) -> None:
    frames = _frames(9000)  # a little over 3 containers
    clean = tmp_path / "clean.blf"
    write_can_log(clean, frames)
    data = clean.read_bytes()
    middle = len(data) // 2
    junk = np.random.default_rng(7).integers(0, 256, 512, dtype=np.uint8).tobytes()
    path = tmp_path / "damaged.blf"
    path.write_bytes(data[:middle] + junk + data[middle + (512 if mode == "overwrite" else 0) :])
    with caplog.at_level(logging.WARNING, logger="roadpreview.canbus.logio"):
        reader = CanLogReader(path)
        got = list(reader)
    lost = _lost(got, frames)
    # what is lost: the frames of the damaged container only, one run in the middle
    assert 0 < len(lost) <= FRAMES_PER_CONTAINER
    assert lost == list(range(lost[0], lost[-1] + 1))
    assert lost[0] > 0.3 * len(frames)
    assert lost[-1] < 0.7 * len(frames)
    assert [m.timestamp for m in got] == [
        m.timestamp for k, m in enumerate(frames) if k not in lost
    ]
    assert reader.counts == {"resynced": 1}  # and no 'never finalised' for inserted bytes
    [problem] = reader.problems
    assert not problem.fatal
    assert problem.byte_offset is not None
    assert problem.byte_offset <= middle
    assert problem.resumed_at is not None
    assert problem.resumed_at > middle + 512
    assert reader.bytes_skipped == problem.resumed_at - problem.byte_offset
    assert f"{path} (byte {problem.byte_offset})" in caplog.text
    assert f"reading resumed at byte {problem.resumed_at}" in caplog.text
    with pytest.raises(InputDataError, match=r"damaged\.blf.*resumed"):
        list(read_can_log(path, errors="raise"))


def test_blf_with_damage_in_many_places_delivers_only_true_frames(tmp_path: Path) -> None:
    frames = _frames(15000)
    path = tmp_path / "rotten.blf"
    write_can_log(path, frames)
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(3)
    spots = sorted(rng.integers(200, len(data) - 200, 5))
    for at in spots:  # bit rot: 64 bytes overwritten at each spot
        data[at : at + 64] = rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    reader = CanLogReader(path)
    got = list(reader)
    lost = _lost(got, frames)  # no garbage frame, no duplicate
    assert [m.timestamp for m in got] == sorted(m.timestamp for m in got)
    assert 0 < len(lost) <= len(spots) * FRAMES_PER_CONTAINER
    assert 1 <= sum(reader.counts.values()) <= len(spots)
    assert set(reader.counts) <= {"resynced", "corrupt_data"}


def test_a_text_file_that_is_no_blf(tmp_path: Path) -> None:
    path = tmp_path / "fake.blf"
    path.write_text("this is not a BLF file at all, not even close to one" * 5)
    reader = CanLogReader(path)
    assert list(reader) == []
    assert reader.problems[0].fatal
    assert "fake.blf" in str(reader.problems[0])


# --- writer checks ------------------------------------------------------------------------------


def test_writer_refuses_frames_out_of_order_and_leaves_no_file(tmp_path: Path) -> None:
    frames = _frames(10)
    frames[5].timestamp = frames[3].timestamp
    path = tmp_path / "bad.asc"
    with pytest.raises(InputDataError, match="message 5"):
        write_can_log(path, frames)
    assert not path.exists()


def test_blf_needs_unix_times(tmp_path: Path) -> None:
    frames = [can.Message(timestamp=0.5 + k * 0.01, arbitration_id=0x130, data=bytes(8))
              for k in range(3)]
    with pytest.raises(InputDataError, match="Unix time"):
        write_can_log(tmp_path / "rel.blf", frames)
    write_can_log(tmp_path / "rel.log", frames)  # text formats store any time
    assert [m.timestamp for m in read_can_log(tmp_path / "rel.log")] == [0.5, 0.51, 0.52]


@pytest.mark.parametrize("name", ["x.txt", "x.blf.gz", "x", "x.mf4.gz", "x.db.gz"])
def test_unknown_suffixes(tmp_path: Path, name: str) -> None:
    with pytest.raises(ConfigError, match="unknown CAN log format"):
        write_can_log(tmp_path / name, _frames(2))
    (tmp_path / name).write_bytes(b"")
    with pytest.raises(InputDataError, match="unknown CAN log format"):
        read_can_log(tmp_path / name)


@pytest.mark.parametrize("suffix", [".mf4", ".db"])
def test_a_text_file_that_is_no_mf4_or_sqlite(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"notes{suffix}"
    path.write_text("this is no CAN log\n" * 50)
    reader = CanLogReader(path)
    assert list(reader) == []
    assert len(reader.problems) == 1
    assert reader.problems[0].fatal
    assert str(path) in str(reader.problems[0])
    with pytest.raises(InputDataError, match=rf"notes\{suffix}"):
        list(CanLogReader(path, errors="raise"))


def test_sqlite_keeps_every_frame_of_a_long_burst(tmp_path: Path) -> None:
    # python-can's writer thread batches 501 frames and stopped after the batch in hand
    frames = _frames(1600)
    write_can_log(tmp_path / "burst.db", frames)
    _assert_same(list(read_can_log(tmp_path / "burst.db")), frames, 0.0)


def test_sqlite_writer_replaces_an_existing_file(tmp_path: Path) -> None:
    # python-can appends to an existing table; a log written twice must hold one drive
    write_can_log(tmp_path / "a.db", _frames(5))
    write_can_log(tmp_path / "a.db", _frames(3, seed=1))
    _assert_same(list(read_can_log(tmp_path / "a.db")), _frames(3, seed=1), 0.0)


def test_missing_log(tmp_path: Path) -> None:
    with pytest.raises(InputDataError, match="not found"):
        read_can_log(tmp_path / "nothing.log")


# --- real data ----------------------------------------------------------------------------------


@pytest.mark.shared
def test_real_comma_candump_log(comma_dir: Path) -> None:
    path = comma_dir / "derived" / "raw_can.candump.log"
    reader = CanLogReader(path, errors="raise")
    last: dict[object, float] = defaultdict(lambda: -np.inf)
    count: dict[object, int] = defaultdict(int)
    for m in reader:
        assert m.timestamp >= last[m.channel], (m.channel, m.timestamp)
        last[m.channel] = m.timestamp
        count[m.channel] += 1
    assert sum(count.values()) == 135_468
    assert dict(count) == {0: 53_800, 1: 45_000, 128: 12_434, 129: 24_234}
    assert reader.problems == []


def test_gzip_text_is_really_gzip(tmp_path: Path) -> None:
    write_can_log(tmp_path / "a.log.gz", _frames(3))
    with gzip.open(tmp_path / "a.log.gz", "rt") as f:
        assert f.readline().startswith("(")
