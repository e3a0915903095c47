"""The calibration's estimators on the real recordings in ../shared (skipped when absent)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from roadpreview.calib.drive import read_tracks
from roadpreview.calib.estimate import calibrate
from roadpreview.calib.rotation import rate_axis, rotation_from_rates
from roadpreview.calib.timing import estimate_time_offset, gyro_integral, mean_rates
from roadpreview.camera import CameraModel
from roadpreview.sources.video import ImageSequenceSource
from roadpreview.types import CameraFrame

pytestmark = pytest.mark.shared


def test_comma2k19_phone_gyro_pitch_axis_and_sign_agree_with_the_ins(comma_dir: Path) -> None:
    """The phone's gyro (axes forward, right, down) against the body rates of the INS
    orientation (quaternions w, x, y, z, ECEF, 20 Hz; the README's frames): the pitch rate
    is +gyro_y (a right-handed rotation about 'right' raises the nose)."""
    ft = np.load(comma_dir / "global_pose" / "frame_times")
    quat = np.load(comma_dir / "global_pose" / "frame_orientations")
    tg = np.load(comma_dir / "processed_log" / "IMU" / "gyro" / "t")
    gyro = np.load(comma_dir / "processed_log" / "IMU" / "gyro" / "value")
    att = Rotation.from_quat(quat[:, [1, 2, 3, 0]])
    rel = (att[:-1].inv() * att[1:]).as_rotvec()  # body rotation between frames, body axes
    ta, tb = ft[:-1], ft[1:]
    offset = estimate_time_offset(ta, tb, rel, tg, gyro)
    assert offset, offset.reason
    assert abs(offset.offset_s) < 0.05  # one boot clock for both; the INS filters a little
    v = rel / (tb - ta)[:, None]
    g = mean_rates(*gyro_integral(tg, gyro), ta + offset.offset_s, tb + offset.offset_s)
    axis = rate_axis(v[:, 1], g)  # the INS's pitch rate, nose up: about its 'right' axis
    assert axis, axis.reason
    assert (axis.axis, axis.sign) == (1, 1)
    assert axis.correlation > 0.95
    # the turns and bumps of the minute excite yaw and pitch: the phone lies as the INS says
    rot = rotation_from_rates(v, g)
    assert rot, rot.reason
    assert math.degrees(Rotation.from_matrix(rot.R).magnitude()) < 2.0


def test_kitti_focus_of_expansion_and_horizon_fit_a_level_camera(kitti_dir: Path) -> None:
    """KITTI's rectified left colour camera (fx = 721.5) is mounted level on the car, its
    optical axis along the direction of travel to within about a degree (KITTI's
    camera-velodyne calibration). 78 frames, moving for the first ~50: the direction of
    travel must lie within 1.5 deg of the optical axis in yaw and pitch (the horizon
    within fx tan 1.5 deg = 19 px of cy), and be known to better than 1 deg."""
    cam = CameraModel(width=1242, height=375, fx=721.5377, fy=721.5377, cx=609.5593, cy=172.8540)
    frames = ImageSequenceSource(kitti_dir / "frames", fps=10.0)
    tracks = read_tracks((s for s in frames if isinstance(s, CameraFrame)), cam)
    cal = calibrate(tracks, None, cam)
    f = cal.forward
    assert f, f.reason
    assert f.n_used >= 5
    assert abs(math.degrees(f.yaw_rad)) < 1.5
    assert abs(math.degrees(f.pitch_rad)) < 1.5
    assert math.degrees(f.yaw_std_rad) < 1.0
    assert math.degrees(f.pitch_std_rad) < 1.0
    assert abs(cal.foe_px[1] - cam.cy) < cam.fy * math.tan(math.radians(1.5))
    assert not cal.time_offset
    assert "no IMU" in cal.time_offset.reason
