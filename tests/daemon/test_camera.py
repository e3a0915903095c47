"""Camera settings and backends: width/height/fps requested, read back and logged (a video
file stands in for a device: it refuses every setting, honestly reported); V4L2 for device
nodes; GStreamer pipelines only with an OpenCV that has GStreamer."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import cv2
import pytest

from roadpreview.apps import daemon as daemon_module
from roadpreview.apps.daemon import Daemon, DaemonOptions
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.pipeline import PipelineConfig
from roadpreview.sources.video import CameraDeviceSource, VideoFileSource, open_camera

HAS_GSTREAMER = CameraDeviceSource.gstreamer_available()


@pytest.mark.skipif(HAS_GSTREAMER, reason="this OpenCV has GStreamer")
@pytest.mark.parametrize(
    "source", ["gst:videotestsrc ! appsink", "v4l2src ! videoconvert ! appsink"]
)
def test_a_pipeline_without_gstreamer_is_a_one_line_error(source: str) -> None:
    with pytest.raises(ConfigError) as info:
        open_camera(source)
    message = str(info.value)
    assert "\n" not in message
    assert source in message
    assert "this OpenCV build has no GStreamer" in message
    assert "/dev/videoN (V4L2)" in message  # what to do instead


def test_backends_by_source(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(
        cv2, "getBuildInformation", lambda: "  Video I/O:\n    GStreamer:   YES (1.22.0)\n"
    )
    assert CameraDeviceSource.gstreamer_available()
    gst = open_camera("gst: v4l2src device=/dev/video2 ! videoconvert ! appsink")
    assert isinstance(gst, CameraDeviceSource)
    assert (gst.kind, gst.backend) == ("gstreamer", cv2.CAP_GSTREAMER)
    assert gst.pipeline == "v4l2src device=/dev/video2 ! videoconvert ! appsink"
    bare = CameraDeviceSource("videotestsrc ! appsink")
    assert (bare.kind, bare.pipeline) == ("gstreamer", "videotestsrc ! appsink")
    node = CameraDeviceSource("/dev/video0")
    assert (node.kind, node.backend, node.pipeline) == ("device", cv2.CAP_V4L2, None)
    assert (CameraDeviceSource("0").kind, CameraDeviceSource("0").backend) == (
        "device",
        cv2.CAP_ANY,
    )
    url = CameraDeviceSource("rtsp://10.0.0.2/stream")
    assert (url.kind, url.backend) == ("stream", cv2.CAP_ANY)
    monkeypatch.setattr(cv2, "getBuildInformation", lambda: "  Video I/O:\n    GStreamer:   NO\n")
    assert not CameraDeviceSource.gstreamer_available()


def test_settings_are_requested_read_back_and_refusals_warned(
    small_drive: Any, caplog: pytest.LogCaptureFixture
) -> None:
    # what OpenCV does with CAP_PROP_* on a video file: set() returns False and the file's own
    # size and rate are read back, exactly what a camera refusing a mode looks like
    cam = CameraDeviceSource(str(small_drive.video), width=640, height=480, fps=15.0)
    with caplog.at_level(logging.INFO, logger="roadpreview.sources.video"):
        assert cam.open()
    assert cam.size == (320, 180)
    assert cam.fps == pytest.approx(float(small_drive.info["fps"]))
    opened = [r.getMessage() for r in caplog.records if "camera_opened" in r.getMessage()]
    assert len(opened) == 1
    assert "width=320 height=180" in opened[0]
    refused = [r.getMessage() for r in caplog.records if "camera_setting_refused" in r.getMessage()]
    assert len(refused) == 3
    assert "setting=width requested=640 actual=320" in refused[0]
    assert "setting=height requested=480 actual=180" in refused[1]
    assert "setting=fps requested=15" in refused[2]
    cam.close()


def test_settings_the_camera_gives_are_not_warned(
    small_drive: Any, caplog: pytest.LogCaptureFixture
) -> None:
    fps = float(small_drive.info["fps"])
    cam = CameraDeviceSource(str(small_drive.video), width=320, height=180, fps=fps)
    with caplog.at_level(logging.INFO, logger="roadpreview.sources.video"):
        assert cam.open()
    assert not [r for r in caplog.records if "camera_setting_refused" in r.getMessage()]
    cam.close()


def _first_frames(cam: CameraDeviceSource, n: int) -> list[Any]:
    frames = []
    for frame in cam:
        frames.append(frame)
        if len(frames) == n:
            cam.close()
    return frames


def test_frames_of_another_size_than_the_calibration_come_without_image(
    small_drive: Any, caplog: pytest.LogCaptureFixture
) -> None:
    good = _first_frames(CameraDeviceSource(str(small_drive.video), expected_size=(320, 180)), 3)
    assert all(f.image is not None and f.image.shape == (180, 320, 3) for f in good)
    cam = CameraDeviceSource(str(small_drive.video), expected_size=(640, 360))
    with caplog.at_level(logging.ERROR, logger="roadpreview.sources.video"):
        bad = _first_frames(cam, 3)
    assert [f.image for f in bad] == [None, None, None]
    assert [f.index for f in bad] == [0, 1, 2]
    assert cam.size_mismatches == cam.errors == 3
    errors = [r.getMessage() for r in caplog.records]
    assert len(errors) == 1  # once per open, not per frame
    assert "frames are 320x180 but the calibration is for 640x360" in errors[0]


def test_daemon_refuses_a_camera_whose_size_is_not_the_calibrations(
    small_drive: Any,
    monkeypatch: pytest.MonkeyPatch,
    virtual_config: Callable[..., PipelineConfig],
) -> None:
    cfg = virtual_config()
    wrong = small_drive.camera.scaled(640, 360)
    # a video file through the device path stands in for a camera (no /dev/video here)
    monkeypatch.setattr(
        daemon_module,
        "open_camera",
        lambda source, **kw: CameraDeviceSource(source, expected_size=kw["expected_size"]),
    )
    with pytest.raises(ConfigError) as info:
        Daemon(wrong, cfg, DaemonOptions(camera_source=str(small_drive.video)))
    assert "gives 320x180 frames but the calibration is for 640x360" in str(info.value)
    assert "camera_width/camera_height" in str(info.value)


def test_daemon_refuses_a_video_file_whose_size_is_not_the_calibrations(
    small_drive: Any, virtual_config: Callable[..., PipelineConfig]
) -> None:
    assert isinstance(open_camera(str(small_drive.video)), VideoFileSource)
    wrong = small_drive.camera.scaled(640, 360)
    options = DaemonOptions(camera_source=str(small_drive.video))
    with pytest.raises(InputDataError, match=r"frames are 320x180 but the camera calibration"):
        Daemon(wrong, virtual_config(), options)
