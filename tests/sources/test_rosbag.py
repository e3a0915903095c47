"""ROS bags without ROS: message conversion, topic choice, and a bag replayed end to end
(rosbag2 sqlite3 folder with raw images, MCAP file with JPEG images)."""

from __future__ import annotations

import csv
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import cv2
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.canbus.imu_csv import read_imu_csv
from roadpreview.cli.main import main
from roadpreview.errors import InputDataError
from roadpreview.sources.rosbag import choose_topics, image_of, imu_of, is_bag, speed_of
from roadpreview.types import FusionMode

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
#: the time a message is logged after its header stamp (the stamps must be used, not this)
LOG_DELAY_S = 0.012
OFFSET_TOL_S = 0.003  #: camera-IMU offset found by the estimator
SPEED_TOL_MPS = 0.3  #: speed through the pipeline vs truth


# --- conversion ---------------------------------------------------------------------------------


def _raw(image: np.ndarray, encoding: str, pad: int = 0) -> Any:
    h, w = image.shape[:2]
    rows = image.reshape(h, -1)
    step = rows.shape[1] + pad
    data = np.zeros((h, step), np.uint8)
    data[:, : rows.shape[1]] = rows
    return SimpleNamespace(
        height=h, width=w, encoding=encoding, step=step, data=data.ravel(), is_bigendian=0
    )


def test_raw_images_become_bgr() -> None:
    bgr = np.zeros((4, 5, 3), np.uint8)
    bgr[..., 2] = 200  # red
    rgb = bgr[..., ::-1].copy()
    for msg in (_raw(bgr, "bgr8"), _raw(rgb, "rgb8", pad=3)):
        got = image_of(msg, "sensor_msgs/msg/Image")
        assert got is not None
        assert got.shape == (4, 5, 3)
        assert (got[..., 2] == 200).all()
        assert (got[..., :2] == 0).all()
    grey = image_of(_raw(np.full((4, 5), 77, np.uint8), "mono8"), "sensor_msgs/msg/Image")
    assert grey is not None
    assert grey.shape == (4, 5, 3)
    assert (grey == 77).all()
    assert image_of(_raw(np.zeros((4, 5), np.uint16), "mono16"), "sensor_msgs/msg/Image") is None


def test_compressed_images_and_garbage() -> None:
    img = np.zeros((8, 8, 3), np.uint8)
    img[:, :, 1] = 150
    ok, png = cv2.imencode(".png", img)
    assert ok
    msg = SimpleNamespace(format="png", data=png.ravel())
    got = image_of(msg, "sensor_msgs/msg/CompressedImage")
    assert got is not None
    assert np.array_equal(got, img)
    junk = SimpleNamespace(format="jpeg", data=np.arange(50, dtype=np.uint8))
    assert image_of(junk, "sensor_msgs/msg/CompressedImage") is None


def test_imu_and_speed_conventions() -> None:
    v = SimpleNamespace
    # REP-103 body axes = ISO 8855; the nose rising is a negative rate about y (left)
    imu = v(angular_velocity=v(x=0.1, y=-0.2, z=0.3), linear_acceleration=v(x=1.0, y=0.0, z=9.81))
    s = imu_of(imu, 5.0, "/imu")
    assert s.pitch_rate_rad_s == pytest.approx(0.2)
    assert s.rates_rad_s == pytest.approx((0.1, 0.2, 0.3))
    assert s.accel_m_s2 == pytest.approx((1.0, 0.0, 9.81))
    twist = v(twist=v(linear=v(x=3.0, y=4.0, z=0.0)))
    assert speed_of(twist, "geometry_msgs/msg/TwistStamped", 1.0, "/t").speed_mps == 5.0
    odom = v(twist=twist)
    assert speed_of(odom, "nav_msgs/msg/Odometry", 1.0, "/o").speed_mps == 5.0


def test_topics_by_type_and_the_errors_name_the_candidates() -> None:
    topics = {
        "/cam": "sensor_msgs/msg/Image",
        "/imu/a": "sensor_msgs/msg/Imu",
        "/imu/b": "sensor_msgs/msg/Imu",
        "/odom": "nav_msgs/msg/Odometry",
    }
    with pytest.raises(InputDataError, match=r"several IMU topics \(/imu/a, /imu/b\).*--imu-topic"):
        choose_topics(topics)
    got = choose_topics(topics, imu="/imu/b")
    assert (got.image, got.imu, got.speed) == ("/cam", "/imu/b", "/odom")
    with pytest.raises(InputDataError, match=r"'/odom' is a nav_msgs/msg/Odometry, not a camera"):
        choose_topics(topics, image="/odom", imu="/imu/a")
    with pytest.raises(InputDataError, match=r"no topic '/nope'.*/cam \(sensor_msgs"):
        choose_topics(topics, imu="/nope")
    with pytest.raises(InputDataError, match="no camera topic"):
        choose_topics({"/imu/a": "sensor_msgs/msg/Imu"})


# --- bags replayed end to end ---------------------------------------------------------------------


def _stamp(t: float) -> Any:
    sec = int(t)
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9)),
        frame_id="base_link",
    )


def _vec(x: float, y: float, z: float) -> Any:
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def _write_bag(
    drive: Any,
    path: Path,
    *,
    storage: StoragePlugin,
    compressed: bool,
    speed_type: str,
    decoy_imu: bool = False,
) -> None:
    """The drive as a robot would record it: camera, IMU (the phone's stamps) and speed,
    stamped on Unix time, each logged LOG_DELAY_S after its stamp."""
    t0 = float(drive.info["can_t0_unix_s"])
    with drive.frames_csv.open() as fh:
        frame_t = [float(r["t_s"]) for r in csv.DictReader(fh)]
    messages: list[tuple[float, str, Any, str]] = []
    cap = cv2.VideoCapture(str(drive.video))
    for t in frame_t:
        ok, bgr = cap.read()
        assert ok
        if compressed:
            _, jpg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 95])
            msg = T["sensor_msgs/msg/CompressedImage"](
                header=_stamp(t0 + t), format="jpeg", data=jpg.ravel()
            )
            messages.append((t0 + t, "/camera/compressed", msg, msg.__msgtype__))
        else:
            h, w = bgr.shape[:2]
            msg = T["sensor_msgs/msg/Image"](
                header=_stamp(t0 + t),
                height=h,
                width=w,
                encoding="rgb8",
                is_bigendian=0,
                step=3 * w,
                data=np.ascontiguousarray(bgr[..., ::-1]).ravel(),
            )
            messages.append((t0 + t, "/camera/image_raw", msg, msg.__msgtype__))
    cap.release()
    imu = read_imu_csv(drive.imu_csv)
    zeros = np.zeros(9)
    quat = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    for t, g, a in zip(imu.t_s, imu.gyro_rad_s, imu.accel_m_s2, strict=True):
        msg = T["sensor_msgs/msg/Imu"](
            header=_stamp(t0 + t),
            orientation=quat,
            orientation_covariance=zeros,
            angular_velocity=_vec(*g),
            angular_velocity_covariance=zeros,
            linear_acceleration=_vec(*a),
            linear_acceleration_covariance=zeros,
        )
        messages.append((t0 + t, "/imu/data", msg, msg.__msgtype__))
        if decoy_imu:  # a second IMU that stands still: must not be taken silently
            still = T["sensor_msgs/msg/Imu"](
                header=_stamp(t0 + t),
                orientation=quat,
                orientation_covariance=zeros,
                angular_velocity=_vec(0.0, 0.0, 0.0),
                angular_velocity_covariance=zeros,
                linear_acceleration=_vec(0.0, 0.0, 9.81),
                linear_acceleration_covariance=zeros,
            )
            messages.append((t0 + t, "/imu/still", still, still.__msgtype__))
    for t, v in zip(drive.truth["speed_t_stamp_s"], drive.truth["speed_true_m_s"], strict=True):
        twist = T["geometry_msgs/msg/Twist"](
            linear=_vec(float(v), 0.0, 0.0), angular=_vec(0.0, 0.0, 0.0)
        )
        if speed_type == "odometry":
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0), orientation=quat
                ),
                covariance=np.zeros(36),
            )
            msg = T["nav_msgs/msg/Odometry"](
                header=_stamp(t0 + float(t)),
                child_frame_id="base_link",
                pose=pose,
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=twist, covariance=np.zeros(36)
                ),
            )
            messages.append((t0 + float(t), "/odom", msg, msg.__msgtype__))
        else:
            msg = T["geometry_msgs/msg/TwistStamped"](header=_stamp(t0 + float(t)), twist=twist)
            messages.append((t0 + float(t), "/vehicle/twist", msg, msg.__msgtype__))
    messages.sort(key=lambda m: m[0])
    with Writer(path, version=9, storage_plugin=storage) as writer:
        connections: dict[str, Any] = {}
        for t, topic, msg, msgtype in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=TS)
            writer.write(
                connections[topic], round((t + LOG_DELAY_S) * 1e9), TS.serialize_cdr(msg, msgtype)
            )


def _check_speed(drive: Any, results: list[Any]) -> None:
    t0 = float(drive.info["can_t0_unix_s"])
    t = np.array([r.t - t0 for r in results])
    v = np.array([np.nan if r.ego_speed_mps is None else r.ego_speed_mps for r in results])
    truth = np.interp(t, drive.truth["speed_t_stamp_s"], drive.truth["speed_true_m_s"])
    ok = np.isfinite(v)
    assert ok.sum() > 0.9 * len(v)
    assert np.max(np.abs(v[ok] - truth[ok])) < SPEED_TOL_MPS


def test_rosbag2_folder_with_raw_images_replays_from_the_command_line(
    drive: Any, tmp_path: Path
) -> None:
    bag = tmp_path / "drive_bag"
    _write_bag(drive, bag, storage=StoragePlugin.SQLITE3, compressed=False, speed_type="twist")
    assert is_bag(bag)
    out = tmp_path / "out"
    code = main(
        ["replay", str(bag), "--camera", str(drive.folder / "camera.toml"), "--out", str(out)]
    )
    assert code == 0
    with (out / "frames.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == drive.info["n_frames"]
    t0 = float(drive.info["can_t0_unix_s"])
    assert float(rows[0]["t_unix_s"]) == pytest.approx(t0, abs=1e-6)  # header stamp
    assert rows[-1]["mode"] == "FUSED"
    # images and IMU stamped by their headers: only the IMU's own lag is left
    assert float(rows[-1]["imu_time_offset_s"]) == pytest.approx(
        float(drive.info["imu_time_offset_s"]), abs=OFFSET_TOL_S
    )


def test_mcap_file_with_jpeg_images_and_two_imus(drive: Any, tmp_path: Path) -> None:
    folder = tmp_path / "mcap_bag"
    _write_bag(
        drive,
        folder,
        storage=StoragePlugin.MCAP,
        compressed=True,
        speed_type="odometry",
        decoy_imu=True,
    )
    mcap = next(folder.glob("*.mcap"))  # the bare file, as a recorder hands it over
    inputs = ReplayInputs(video=mcap, camera=drive.camera)
    with pytest.raises(InputDataError, match=r"/imu/data, /imu/still.*--imu-topic"):
        replay(inputs)
    inputs.imu_topic = "/imu/data"
    result = replay(inputs, keep_results=True)
    assert result.results is not None
    assert result.frames == drive.info["n_frames"]
    assert result.decode_failures == 0
    final = result.results[-1]
    assert final.mode is FusionMode.FUSED
    assert final.time_offset == pytest.approx(
        float(drive.info["imu_time_offset_s"]), abs=OFFSET_TOL_S
    )
    _check_speed(drive, result.results)
