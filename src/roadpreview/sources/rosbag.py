"""ROS bags without ROS: a rosbag2 folder (sqlite3 or MCAP storage), a bare ``.mcap`` file
or a ROS 1 ``.bag``, read with ``rosbags`` (its ``AnyReader``).

Topics by type: the camera is a ``sensor_msgs/Image`` (bgr8, rgb8, mono8, bgra8, rgba8)
or ``sensor_msgs/CompressedImage`` (JPEG, PNG) topic; the IMU a ``sensor_msgs/Imu``
topic; the speed (optional) a ``geometry_msgs/TwistStamped``,
``TwistWithCovarianceStamped`` or ``nav_msgs/Odometry`` topic. `choose_topics` takes
the ones named, else the only one of each type, and names the candidates when a choice
is ambiguous or missing.

Conventions (assumed, not read from TF): the IMU is body-mounted in REP-103 axes (x
forward, y left, z up), which are ISO 8855's, with ``linear_acceleration`` the
specific force (gravity included, +9.81 m/s² on z at rest); the speed is the norm of
the twist's linear x and y in the body frame (m/s). Each message is stamped with its
``header.stamp`` (the sensor's time), or the time it was logged when the stamp is 0. A
message stamped before its predecessor on the same topic is dropped and counted.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Generator, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from roadpreview.canbus.samples import RATE_SIGNS
from roadpreview.errors import InputDataError, MissingDependencyError
from roadpreview.sources.video import as_image
from roadpreview.types import CameraFrame, Image, ImuSample, InputSample, SpeedSample

log = logging.getLogger(__name__)

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
IMU_TYPES = ("sensor_msgs/msg/Imu",)
SPEED_TYPES = (
    "geometry_msgs/msg/TwistStamped",
    "geometry_msgs/msg/TwistWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
)
#: suffixes of bag files (a rosbag2 folder is recognised by its metadata.yaml)
BAG_SUFFIXES = (".bag", ".mcap", ".db3")
#: raw image encodings read, and the OpenCV conversion to BGR (None: already BGR / grey)
_ENCODINGS: dict[str, tuple[int, int | None]] = {
    "bgr8": (3, None),
    "rgb8": (3, cv2.COLOR_RGB2BGR),
    "mono8": (1, None),
    "8uc1": (1, None),
    "8uc3": (3, None),
    "bgra8": (4, cv2.COLOR_BGRA2BGR),
    "rgba8": (4, cv2.COLOR_RGBA2BGR),
}


def is_bag(path: str | Path) -> bool:
    """True for a bag: a rosbag2 folder (metadata.yaml), a ``.mcap``, ``.db3`` or ``.bag``."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in BAG_SUFFIXES


def _reader_paths(path: Path) -> list[Path]:
    if not path.exists():
        raise InputDataError(f"{path}: bag not found")
    if path.suffix.lower() == ".db3":  # a rosbag2 sqlite3 file needs its folder's metadata
        if not (path.parent / "metadata.yaml").is_file():
            raise InputDataError(f"{path}: a .db3 bag needs its metadata.yaml beside it")
        return [path.parent]
    return [path]


# --- message conversion (no I/O) ------------------------------------------------------------------


def stamp_s(msg: Any, logged_ns: int) -> float:
    """The message's ``header.stamp`` in s, or the log time when the stamp is 0."""
    header = getattr(msg, "header", None)
    if header is not None:
        t = int(header.stamp.sec) + 1e-9 * int(header.stamp.nanosec)
        if t > 0.0:
            return t
    return 1e-9 * logged_ns


def image_of(msg: Any, msgtype: str) -> Image | None:
    """The BGR image of an Image or CompressedImage message; None when it cannot be read
    (unknown encoding, short data, undecodable JPEG/PNG)."""
    data = np.asarray(msg.data, dtype=np.uint8)
    if msgtype.endswith("CompressedImage"):
        if data.size == 0:
            return None
        return as_image(cv2.imdecode(data, cv2.IMREAD_COLOR))
    enc = _ENCODINGS.get(str(msg.encoding).lower())
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if enc is None or h <= 0 or w <= 0 or step < w * enc[0] or data.size < h * step:
        return None
    channels, code = enc
    rows = data[: h * step].reshape(h, step)[:, : w * channels]
    if channels == 1:
        return as_image(np.ascontiguousarray(rows))
    pixels = np.ascontiguousarray(rows.reshape(h, w, channels))
    return pixels if code is None else as_image(cv2.cvtColor(pixels, code))


def imu_of(msg: Any, t_s: float, source: str) -> ImuSample:
    """An Imu message as a sample: REP-103 body axes are ISO 8855's (module docstring)."""
    w, a = msg.angular_velocity, msg.linear_acceleration
    rates = np.array([w.x, w.y, w.z], dtype=np.float64) * RATE_SIGNS
    return ImuSample(
        t_s,
        (float(rates[0]), float(rates[1]), float(rates[2])),
        (float(a.x), float(a.y), float(a.z)),
        source,
    )


def speed_of(msg: Any, msgtype: str, t_s: float, source: str) -> SpeedSample:
    """The speed over ground of a twist or odometry message, m/s."""
    twist = (
        msg.twist.twist if msgtype.endswith(("Odometry", "WithCovarianceStamped")) else msg.twist
    )
    return SpeedSample(t_s, math.hypot(float(twist.linear.x), float(twist.linear.y)), source)


# --- topic choice (no I/O) -------------------------------------------------------------------


@dataclass(frozen=True)
class BagTopics:
    """The topics a replay reads from a bag (None: the bag has no such input)."""

    image: str
    imu: str | None
    speed: str | None


def _choose(
    topics: dict[str, str], types: Sequence[str], wanted: str | None, what: str, where: str
) -> str | None:
    if wanted:
        if wanted not in topics:
            listing = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items()))
            raise InputDataError(f"{where}: no topic {wanted!r}; the bag has {listing}")
        if topics[wanted] not in types:
            raise InputDataError(
                f"{where}: topic {wanted!r} is a {topics[wanted]}, not a {what}"
                f" ({', '.join(types)})"
            )
        return wanted
    candidates = sorted(t for t, m in topics.items() if m in types)
    if len(candidates) > 1:
        flag = {"camera": "--image-topic", "IMU": "--imu-topic"}.get(what, "--speed-topic")
        raise InputDataError(
            f"{where}: several {what} topics ({', '.join(candidates)}); choose one with {flag}"
        )
    return candidates[0] if candidates else None


def choose_topics(
    topics: dict[str, str],
    *,
    image: str | None = None,
    imu: str | None = None,
    speed: str | None = None,
    where: str = "bag",
) -> BagTopics:
    """The image, IMU and speed topics of a bag (``topics``: name -> message type)."""
    image_topic = _choose(topics, IMAGE_TYPES, image, "camera", where)
    if image_topic is None:
        listing = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "no topic"
        raise InputDataError(
            f"{where}: no camera topic (sensor_msgs/Image or CompressedImage); the bag has"
            f" {listing}"
        )
    return BagTopics(
        image_topic,
        _choose(topics, IMU_TYPES, imu, "IMU", where),
        _choose(topics, SPEED_TYPES, speed, "speed", where),
    )


# --- the bag and its sources -------------------------------------------------------------------


def _any_reader(paths: list[Path]) -> Any:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise MissingDependencyError(
            "reading ROS bags needs rosbags; install it with: pip install rosbags"
        ) from None
    return AnyReader(paths, default_typestore=get_typestore(Stores.ROS2_HUMBLE))


class RosBag:
    """A bag opened for its topic list; each source reads it again on its own."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.paths = _reader_paths(self.path)
        try:
            with _any_reader(self.paths) as reader:
                self.topics: dict[str, str] = {c.topic: c.msgtype for c in reader.connections}
                self.counts: dict[str, int] = {}
                for c in reader.connections:
                    self.counts[c.topic] = self.counts.get(c.topic, 0) + int(c.msgcount)
                self.duration_s = 1e-9 * int(reader.duration)
        except MissingDependencyError:
            raise
        except Exception as exc:  # rosbags raises its own types for each storage's damage
            raise InputDataError(f"{self.path}: not a readable bag ({exc})") from None

    def messages(self, topic: str) -> Generator[tuple[int, Any], None, None]:
        """(log time in ns, deserialised message) of one topic, in log order."""
        with _any_reader(self.paths) as reader:
            connections = [c for c in reader.connections if c.topic == topic]
            for con, logged_ns, raw in reader.messages(connections=connections):
                yield logged_ns, reader.deserialize(raw, con.msgtype)

    def first(self, topic: str) -> tuple[int, Any] | None:
        """(log time in ns, message) of the first message of ``topic``; None: no message."""
        messages = self.messages(topic)
        try:
            return next(messages, None)
        finally:
            messages.close()

    def first_stamp(self, topic: str) -> float:
        """The stamp of the first message of ``topic``, s."""
        first = self.first(topic)
        if first is None:
            raise InputDataError(f"{self.path}: topic {topic} holds no message")
        return stamp_s(first[1], first[0])


class _BagTopicSource:
    """One topic of a bag, in stamp order (backward stamps dropped and counted)."""

    live = False

    def __init__(self, bag: RosBag, topic: str, offset_s: float) -> None:
        if topic not in bag.topics:
            raise InputDataError(f"{bag.path}: no topic {topic!r}")
        self.bag = bag
        self.topic = topic
        self.msgtype = bag.topics[topic]
        self.name = f"{bag.path}:{topic}"
        self.offset_s = offset_s
        self.out_of_order = 0  #: messages stamped before their predecessor (dropped)
        self.unreadable = 0  #: messages that gave no sample
        self._closed = False

    @property
    def errors(self) -> int:
        return self.out_of_order + self.unreadable

    def _stamped(self) -> Iterator[tuple[float, Any]]:
        last = -math.inf
        for logged_ns, msg in self.bag.messages(self.topic):
            if self._closed:
                return
            t = stamp_s(msg, logged_ns)
            if t < last:
                self.out_of_order += 1
                log.warning("%s: stamp goes back %.3f s at %.6f; dropped", self.name, last - t, t)
                continue
            last = t
            yield t + self.offset_s, msg

    def close(self) -> None:
        self._closed = True


class BagCameraSource(_BagTopicSource):
    """The image topic of a bag as camera frames, stamped ``start_s`` + the stamp; an
    unreadable image is yielded without image and counted (as a video's)."""

    def __init__(self, bag: RosBag, topic: str, *, start_s: float = 0.0) -> None:
        super().__init__(bag, topic, start_s)
        if self.msgtype not in IMAGE_TYPES:
            raise InputDataError(f"{self.name}: a {self.msgtype}, not an image topic")
        self.n_frames = bag.counts.get(topic, 0)
        self.fps = (self.n_frames - 1) / bag.duration_s if bag.duration_s > 0 else 30.0
        first = bag.first(topic)
        image = image_of(first[1], self.msgtype) if first is not None else None
        self.size = (0, 0) if image is None else (int(image.shape[1]), int(image.shape[0]))

    @property
    def start_s(self) -> float:
        """Added to the stamps: where the bag's clock lands on the drive's."""
        return self.offset_s

    @start_s.setter
    def start_s(self, value: float) -> None:
        self.offset_s = value

    def check_size(self, size: tuple[int, int]) -> None:
        """Raise if the images are not ``size`` (width, height): the calibration's."""
        if self.size != size:
            raise InputDataError(
                f"{self.name}: images are {self.size[0]}x{self.size[1]} but the camera"
                f" calibration is for {size[0]}x{size[1]}"
            )

    def __iter__(self) -> Iterator[CameraFrame]:
        for i, (t, msg) in enumerate(self._stamped()):
            image = image_of(msg, self.msgtype)
            if image is None:
                self.unreadable += 1
                if self.unreadable == 1:
                    log.warning(
                        "%s: image %d (%s) cannot be read; such frames are counted",
                        self.name,
                        i,
                        getattr(msg, "encoding", getattr(msg, "format", "?")),
                    )
            yield CameraFrame(t, image, i)


class BagSampleSource(_BagTopicSource):
    """An IMU or speed topic of a bag as samples, stamped the stamp + ``offset_s``."""

    def __init__(self, bag: RosBag, topic: str, *, offset_s: float = 0.0) -> None:
        super().__init__(bag, topic, offset_s)
        if self.msgtype not in IMU_TYPES + SPEED_TYPES:
            raise InputDataError(f"{self.name}: a {self.msgtype}, not an IMU or speed topic")

    def __iter__(self) -> Iterator[InputSample]:
        imu = self.msgtype in IMU_TYPES
        for t, msg in self._stamped():
            if imu:
                yield imu_of(msg, t, self.topic)
            else:
                yield speed_of(msg, self.msgtype, t, self.topic)


__all__ = [
    "BAG_SUFFIXES",
    "BagCameraSource",
    "BagSampleSource",
    "BagTopics",
    "RosBag",
    "choose_topics",
    "image_of",
    "imu_of",
    "is_bag",
    "speed_of",
    "stamp_s",
]
