"""``roadpreview calibrate`` on a simulated drive with a rotated, late IMU, and the product
replaying that drive with the calibration it wrote (slow: renders 16 s at 640x360)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from roadpreview.cli.main import main
from roadpreview.sources.can import make_decoder
from roadpreview.types import FusionMode, ImuSample

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def calibrated(
    make_recording: Callable[..., Recording], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Recording, Path, dict[str, Any]]:
    rec = make_recording("mounted-imu", duration_s=16.0)
    out = tmp_path_factory.mktemp("calibration")
    assert main(["calibrate", str(rec.folder), "--out", str(out)]) == 0
    return rec, out, json.loads((out / "calibration.json").read_text())


def test_axes_offset_and_forward_direction_of_the_rotated_late_imu(
    calibrated: tuple[Recording, Path, dict[str, Any]],
) -> None:
    rec, out, report = calibrated
    assert rec.info["imu_mount_ypr_deg"] == [90.0, 5.0, 0.0]
    # the chip is yawed 90 deg: its x points left, so the pitch rate (nose up) is -gyro_x
    assert (report["pitch_axis"]["axis"], report["pitch_axis"]["sign"]) == ("x", -1)
    offset_ms = report["time_offset"]["offset_ms"]
    assert abs(offset_ms - 1e3 * rec.info["imu_time_offset_s"]) < 5.0
    # the forward direction (focus of expansion) the recording was rendered with
    from roadpreview.camera import CameraModel

    t_est = CameraModel.load(out / "camera.toml").t
    err_deg = math.degrees(math.acos(min(1.0, float(t_est @ rec.camera.t))))
    assert err_deg < 0.5
    # the full mount rotation: pitch and roll are excited on this straight rough road
    mount = Rotation.from_euler("ZYX", rec.info["imu_mount_ypr_deg"], degrees=True)
    est = np.array(report["rotation"]["body_from_imu"])
    rot_err = math.degrees((Rotation.from_matrix(est) * mount.inv()).magnitude())
    assert rot_err < 3.0
    assert rot_err < 4 * report["rotation"]["std_deg"]
    assert report["forward"]["seconds_used"] > 5
    assert report["time_offset"]["seconds_used"] > 10


def _pitch_rate_correlation(rec: Recording, mapping: str) -> float:
    """Correlation of the decoded pitch rate with the camera's true pitch rate."""
    from roadpreview.sources.can import CanLogSource

    src = CanLogSource(rec.can_log(), make_decoder(mapping=mapping))
    imu = [s for s in src if isinstance(s, ImuSample) and not math.isnan(s.rates_rad_s[1])]
    t = np.array([s.t_s for s in imu]) - rec.t0_unix_s - rec.info["imu_time_offset_s"]
    if mapping != "roadpreview":
        t += rec.info["imu_time_offset_s"]  # the mount already took the offset off
    q = np.array([s.rates_rad_s[1] for s in imu])
    truth = np.interp(t, rec.truth["frame_t_s"], rec.truth["cam_pitch_rate_rad_s"])
    return float(np.corrcoef(q, truth)[0, 1])


def test_replay_with_the_calibration_fuses_and_without_it_the_pitch_axis_is_wrong(
    calibrated: tuple[Recording, Path, dict[str, Any]],
) -> None:
    from roadpreview.apps.replay import ReplayInputs, replay
    from roadpreview.pipeline.config import PipelineConfig

    rec, out, _ = calibrated
    mapping = str(out / "mapping.toml")
    assert _pitch_rate_correlation(rec, mapping) > 0.95
    assert abs(_pitch_rate_correlation(rec, "roadpreview")) < 0.3

    def fused_and_error(cfg: PipelineConfig) -> tuple[float, float]:
        res = replay(ReplayInputs.from_recording(rec.folder), cfg, keep_results=True)
        assert res.results is not None
        t = np.array([r.t for r in res.results]) - res.video_start_s
        fused = np.array([r.mode is FusionMode.FUSED for r in res.results])
        true = np.interp(t, rec.truth["frame_t_s"], rec.truth["cam_pitch_rad"])
        err = np.array([r.phi for r in res.results]) - (true - true[0])
        late = t > 4.0  # after the fusion's start-up
        # the worst 1 s spread of the pitch error (what the detector's window sees)
        spans = [np.std(err[i : i + 30]) for i in range(0, err.size - 30, 30) if late[i]]
        return float(fused[late].mean()), math.degrees(max(spans))

    base = PipelineConfig()
    with_cal = replace(base, can=replace(base.can, mapping=mapping))
    fused, err = fused_and_error(with_cal)
    assert fused > 0.9
    assert err < 0.1
    fused0, err0 = fused_and_error(base)
    assert fused0 < 0.6
    assert err0 > 3 * err
