"""A calibrated mount (a mapping's ``[mount]``) is applied to an IMU CSV replay, as it is to
the CAN decoder: chip axes -> car axes, stamps onto the camera's clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from roadpreview.canbus.samples import ImuMeasurements, ImuMount
from roadpreview.sim.canlog import write_imu_csv
from roadpreview.sources.imu_csv import ImuCsvSource
from roadpreview.types import ImuSample


def test_the_mount_turns_the_chip_axes_into_the_car_axes(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    n = 200
    t = np.arange(n) / 100.0
    body_gyro = rng.normal(0.0, 0.05, (n, 3))  # ISO 8855 body rates, rad/s
    body_acc = rng.normal(0.0, 0.5, (n, 3)) + np.array([0.0, 0.0, 9.81])
    R = Rotation.from_euler("ZYX", [90.0, 5.0, 0.0], degrees=True).as_matrix()  # body <- chip
    chip = ImuMeasurements(t + 0.060, body_gyro @ R, body_acc @ R)  # v_chip = R^T v_body
    path = tmp_path / "phone.csv"
    write_imu_csv(path, chip)

    mount = ImuMount(rotation=R, time_offset_s=0.060)
    got = [s for s in ImuCsvSource(path, mount=mount) if isinstance(s, ImuSample)]
    raw = [s for s in ImuCsvSource(path) if isinstance(s, ImuSample)]
    assert len(got) == n
    # roadpreview's pitch rate is nose-up positive = -omega_y (ISO)
    pitch = np.array([s.rates_rad_s[1] for s in got])
    np.testing.assert_allclose(pitch, -body_gyro[:, 1], atol=1e-5)  # CSV precision
    np.testing.assert_allclose([s.t_s for s in got], t, atol=1e-6)
    acc = np.array([s.accel_m_s2 for s in got])
    np.testing.assert_allclose(acc, body_acc, atol=1e-4)
    # without the mount the chip's axis is read as pitch: unrelated to the true pitch rate
    raw_pitch = np.array([s.rates_rad_s[1] for s in raw])
    assert abs(np.corrcoef(raw_pitch, -body_gyro[:, 1])[0, 1]) < 0.3
