"""Another car's CAN log: refused plainly by roadpreview's DBC ("0 of N frames matched"),
decoded with --dbc / --mapping."""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path
from typing import Any

import can
import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus import load_database, read_can_log
from roadpreview.canbus.logio import write_can_log
from roadpreview.cli._pipeline_args import add_pipeline_arguments, pipeline_config
from roadpreview.cli.main import main
from roadpreview.sources.can import CanLogSource, make_decoder
from roadpreview.types import FusionMode, ImuSample, SpeedSample

FILES = Path(__file__).resolve().parents[1] / "files"
DBC = FILES / "other_car.dbc"
MAPPING = FILES / "other_car_mapping.toml"
DEG = math.pi / 180.0


def _other_car_log(drive: Any, path: Path) -> list[ImuSample | SpeedSample]:
    """The drive's IMU and speed as the other car sends them; returns the samples."""
    db = load_database(DBC, strict=False)
    rates, accel, speed = (
        db.get_message_by_name(n) for n in ("CHASSIS_RATES", "CHASSIS_ACCEL", "WHEEL_SPEED")
    )
    samples = list(CanLogSource(drive.can_log(), make_decoder()))
    frames = []
    for s in samples:
        if isinstance(s, SpeedSample):
            msg, values = speed, {"VehSpeed": s.speed_mps * 3.6}
        elif s.has_rates:
            roll, pitch_up, yaw = (r / DEG for r in s.rates_rad_s)
            msg, values = rates, {"RollRateX": roll, "PitchRateY": -pitch_up, "YawRateZ": yaw}
        else:
            msg, values = accel, dict(zip(("AccX", "AccY", "AccZ"), s.accel_m_s2, strict=True))
        frames.append(
            can.Message(
                timestamp=s.t_s,
                arbitration_id=msg.frame_id,
                is_extended_id=False,
                data=msg.encode(values),
                channel=0,
            )
        )
    write_can_log(path, frames)
    return samples


def test_mapping_and_dbc_flags_reach_the_configuration() -> None:
    p = argparse.ArgumentParser()
    add_pipeline_arguments(p)
    config = pipeline_config(p.parse_args(["--dbc", str(DBC), "--mapping", str(MAPPING)]))
    assert (config.can.dbc, config.can.mapping) == (str(DBC), str(MAPPING))
    assert pipeline_config(p.parse_args([])).can.mapping == "roadpreview"


def test_decoded_with_its_own_dbc_and_mapping(drive: Any, tmp_path: Path) -> None:
    log = tmp_path / "other.blf"
    original = _other_car_log(drive, log)
    # the mapping names the DBC beside it: --mapping alone is enough
    decoded = list(CanLogSource(log, make_decoder("", str(MAPPING))))
    assert len(decoded) == len(original)
    for got, want in zip(decoded, original, strict=True):
        assert type(got) is type(want)
        assert got.t_s == pytest.approx(want.t_s, abs=1e-6)
        if isinstance(got, ImuSample) and isinstance(want, ImuSample):
            if want.has_rates:  # 0.01 deg/s steps; the pitch rate keeps its sign (nose up +)
                assert got.rates_rad_s == pytest.approx(want.rates_rad_s, abs=0.006 * DEG)
            else:  # 0.001 m/s² steps
                assert got.accel_m_s2 == pytest.approx(want.accel_m_s2, abs=6e-4)
        elif isinstance(got, SpeedSample) and isinstance(want, SpeedSample):
            assert got.speed_mps == pytest.approx(want.speed_mps, abs=0.006 / 3.6)


def test_another_cars_log_is_named_then_replayed_with_the_flags(
    drive: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    log = tmp_path / "other.blf"
    _other_car_log(drive, log)
    n = sum(1 for _ in read_can_log(log))
    # with roadpreview's DBC: said plainly, vision only
    result = replay(
        ReplayInputs(video=drive.video, camera=drive.camera, can_logs=[log]), max_frames=20
    )
    assert f"{log}: 0 of {n} frames matched the DBC/mapping" in caplog.text
    assert "--dbc and --mapping" in caplog.text
    assert result.mode_changes[-1][1] is FusionMode.VISUAL_ONLY
    # with the flags: IMU and speed decoded, the fusion runs on the gyro
    out = tmp_path / "out"
    code = main(
        [
            "replay",
            str(drive.video),
            "--camera",
            str(drive.folder / "camera.toml"),
            "--can",
            str(log),
            "--dbc",
            str(DBC),
            "--mapping",
            str(MAPPING),
            "--out",
            str(out),
        ]
    )
    assert code == 0
    with (out / "frames.csv").open() as fh:
        last = list(csv.DictReader(fh))[-1]
    assert last["mode"] == "FUSED"
    lag = float(drive.info["imu_time_offset_s"])
    first = min(m.timestamp for m in read_can_log(log)) - float(drive.info["can_t0_unix_s"])
    assert float(last["imu_time_offset_s"]) == pytest.approx(lag - first, abs=0.003)
    assert caplog.text.count("frames matched") == 1  # only the run without the flags
