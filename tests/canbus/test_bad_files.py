"""Broken input files from tests/files: errors name the file and the line, good frames survive."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from roadpreview.canbus import (
    IMU_CSV_COLUMNS,
    CanInputDecoder,
    CanLogReader,
    decode_log,
    imu_samples,
    load_database,
    load_mapping,
    read_can_log,
    read_imu_csv,
    split_samples,
)
from roadpreview.errors import ConfigError, InputDataError, RoadPreviewError

FILES = Path(__file__).resolve().parents[1] / "files"


def test_dbc_with_a_syntax_error_names_file_line_and_column() -> None:
    with pytest.raises(InputDataError, match=r"bad_syntax\.dbc:17:34: DBC syntax error") as err:
        load_database(FILES / "bad_syntax.dbc")
    assert "PitchRate" in str(err.value)
    assert isinstance(err.value, RoadPreviewError)  # one root for every error we raise
    with pytest.raises(InputDataError, match=r"bad_syntax\.dbc:17"):
        load_database(FILES / "bad_syntax.dbc", strict=False)  # syntax is syntax
    with pytest.raises(InputDataError, match="not found"):
        load_database(FILES / "nothing.dbc")


def test_truncated_blf_gives_the_complete_frames_then_names_the_file() -> None:
    reader = CanLogReader(FILES / "truncated.blf")
    frames = list(reader)
    full = list(CanLogReader(FILES / "imu_drive.blf", errors="raise"))
    assert 0 < len(frames) < len(full)
    assert [bytes(f.data) for f in frames] == [bytes(f.data) for f in full[: len(frames)]]
    [problem] = reader.problems
    assert problem.fatal
    assert "truncated BLF" in problem.reason
    assert "truncated.blf" in str(problem)
    with pytest.raises(InputDataError, match=r"truncated\.blf.*truncated BLF"):
        list(read_can_log(FILES / "truncated.blf", errors="raise"))


@pytest.mark.parametrize(
    ("name", "bad_lines"), [("garbled.log", [6, 21, 31]), ("garbled.asc", [13, 26, 41])]
)
def test_garbage_lines_are_named_and_skipped(
    name: str, bad_lines: list[int], caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="roadpreview.canbus.logio"):
        reader = CanLogReader(FILES / name)
        frames = list(reader)
    assert [p.line for p in reader.problems] == bad_lines
    for line in bad_lines:
        assert f"{name}:{line}:" in caplog.text
    # every frame of the clean log is there (the candump one also has 2 extra valid lines)
    clean = list(CanLogReader(FILES / name.replace("garbled", "imu_drive"), errors="raise"))
    assert len(frames) == len(clean) + (2 if name.endswith(".log") else 0)
    with pytest.raises(InputDataError, match=rf"{name}:{bad_lines[0]}:"):
        list(read_can_log(FILES / name, errors="raise"))


def test_decoding_a_garbled_log_end_to_end() -> None:
    dec = CanInputDecoder(load_database(), load_mapping("roadpreview"))
    imu, speed = split_samples(decode_log(FILES / "garbled.asc", dec))
    assert len([s for s in imu if s.has_rates]) == 20
    assert len(speed) == 10
    assert dec.stats.skipped == 0


def test_mapping_with_a_missing_signal_fails_before_any_frame() -> None:
    with pytest.raises(ConfigError, match=r"mapping_missing_signal\.toml.*'PitchRat'"):
        CanInputDecoder(load_database(), load_mapping(FILES / "mapping_missing_signal.toml"))


def test_imu_csv_reader_moved_to_canbus_and_converts_to_samples(tmp_path: Path) -> None:
    from roadpreview.canbus import imu_csv
    from roadpreview.sim import canlog

    assert canlog.read_imu_csv is imu_csv.read_imu_csv  # the simulator re-exports it
    assert canlog.IMU_CSV_COLUMNS == IMU_CSV_COLUMNS
    path = tmp_path / "phone.csv"
    path.write_text(
        "# a phone\n" + ",".join(IMU_CSV_COLUMNS) + "\n"
        "0.00,0.1,0.2,0.3,1.0,2.0,9.81\n"
        "0.01,0.1,oops,0.3,1.0,2.0,9.81\n"
        "0.02,0.1,-0.2,0.3,1.0,2.0,9.81\n"
    )
    meas = read_imu_csv(path)
    assert len(meas) == 2
    samples = imu_samples(meas, source="phone.csv")
    assert [s.pitch_rate_rad_s for s in samples] == pytest.approx([-0.2, 0.2])  # nose up = -ω_y
    assert samples[0].rates_rad_s[2] == pytest.approx(0.3)
    assert samples[0].accel_m_s2 == pytest.approx((1.0, 2.0, 9.81))
    assert samples[1].source == "phone.csv"
