"""Camera sources: a video file, a camera device or stream, an image sequence.

One clock rule for a file, whoever reads it (replay, the daemon, the
evaluation): frame ``i`` is stamped ``start_s`` + the ``i``-th time of
``frames.csv`` (``frame,t_s``) when there is one, else ``start_s + i / fps``.
A frame that cannot be decoded is yielded with ``image=None`` (the pipeline
counts it as a vision failure) and counted in ``errors``; the stream ends with
the file (or after 10 undecodable frames in a row). A device or stream is
stamped ``time.time()`` when the frame is read, and reopened after a failure.
"""

from __future__ import annotations

import csv
import logging
import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from roadpreview.errors import InputDataError
from roadpreview.types import CameraFrame, Image

log = logging.getLogger(__name__)

#: undecodable frames in a row after which a file is taken as ended
MAX_MISSES = 10


def as_image(array: object) -> Image | None:
    """``array`` as a BGR image if it is one (H x W x 3 uint8; a grey H x W uint8 is
    converted), else None."""
    if not isinstance(array, np.ndarray) or array.dtype != np.uint8:
        return None
    if array.ndim == 2:
        return cv2.cvtColor(array, cv2.COLOR_GRAY2BGR)  # type: ignore[return-value]
    if array.ndim == 3 and array.shape[2] == 3:
        return array
    return None


def frame_times(frames_csv: Path) -> Iterator[float]:
    """The time stamps of ``frames.csv`` (``frame,t_s``), s; bad rows logged and skipped."""
    with frames_csv.open(newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header != ["frame", "t_s"]:
            raise InputDataError(f"{frames_csv}: header must be 'frame,t_s', got {header}")
        for line_no, row in enumerate(reader, start=2):
            try:
                yield float(row[1])
            except (IndexError, ValueError):
                log.warning("%s:%d: bad time stamp %r skipped", frames_csv, line_no, row)


class VideoFileSource:
    """The frames of a video file on the pipeline's clock (module docstring)."""

    live = False

    def __init__(
        self, path: str | Path, *, start_s: float = 0.0, frames_csv: str | Path | None = None
    ) -> None:
        self.path = Path(path)
        self.name = str(self.path)
        if not self.path.is_file():
            raise InputDataError(f"{self.path}: video not found")
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise InputDataError(f"{self.path}: cannot open the video (unknown format or codec)")
        self.fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
        self.n_frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.size = (
            int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
            int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
        )
        cap.release()
        self.start_s = start_s
        self.frames_csv = Path(frames_csv) if frames_csv else None
        if self.frames_csv is not None and not self.frames_csv.is_file():
            raise InputDataError(f"{self.frames_csv}: frame time stamps not found")
        self.decode_failures = 0  #: frames that could not be decoded
        self._closed = False

    @property
    def errors(self) -> int:
        return self.decode_failures

    def check_size(self, size: tuple[int, int]) -> None:
        """Raise if the frames are not ``size`` (width, height): the calibration's."""
        if self.size != size:
            raise InputDataError(
                f"{self.path}: frames are {self.size[0]}x{self.size[1]} but the camera "
                f"calibration is for {size[0]}x{size[1]}"
            )

    def __iter__(self) -> Iterator[CameraFrame]:
        cap = cv2.VideoCapture(str(self.path))
        times = frame_times(self.frames_csv) if self.frames_csv is not None else None
        i = 0
        misses = 0
        try:
            while not self._closed:
                ok, image = cap.read()
                t_rel = next(times, None) if times is not None else i / self.fps
                if t_rel is None:
                    break
                if not ok:
                    # a corrupt frame inside the file: report it, try the next ones
                    if i >= self.n_frames - 1 or misses > MAX_MISSES:
                        break
                    misses += 1
                    self.decode_failures += 1
                    log.warning("%s: frame %d cannot be decoded; skipped", self.path, i)
                    yield CameraFrame(self.start_s + t_rel, None, i)
                    i += 1
                    continue
                misses = 0
                yield CameraFrame(self.start_s + t_rel, as_image(image), i)
                i += 1
        finally:
            cap.release()

    def close(self) -> None:
        self._closed = True


class CameraDeviceSource:
    """A camera device (an index or ``/dev/video*``) or a stream URL, stamped with
    ``time.time()`` when read; reopened ``reopen_s`` after a failure. Live."""

    live = True

    def __init__(self, source: str, *, reopen_s: float = 1.0) -> None:
        self.name = source
        self.source = source
        self.reopen_s = reopen_s
        self.read_failures = 0  #: reads that failed (each ends an open)
        self.opens = 0  #: successful opens
        self._stop = threading.Event()

    @property
    def errors(self) -> int:
        return self.read_failures

    def _open(self) -> cv2.VideoCapture | None:
        target: int | str = int(self.source) if self.source.isdigit() else self.source
        cap = cv2.VideoCapture(target)
        if not cap.isOpened():
            cap.release()
            log.error("camera %s: cannot open", self.source)
            return None
        self.opens += 1
        log.info("camera %s: opened", self.source)
        return cap

    def __iter__(self) -> Iterator[CameraFrame]:
        i = 0
        while not self._stop.is_set():
            cap = self._open()
            if cap is None:
                self._stop.wait(self.reopen_s)
                continue
            try:
                while not self._stop.is_set():
                    ok, image = cap.read()
                    now = time.time()
                    if not ok or image is None:
                        self.read_failures += 1
                        log.error("camera %s: frame %d cannot be read; reopening", self.source, i)
                        break
                    yield CameraFrame(now, as_image(image), i)
                    i += 1
            finally:
                cap.release()
            self._stop.wait(self.reopen_s)

    def close(self) -> None:
        self._stop.set()


#: image files an `ImageSequenceSource` reads, by suffix
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


class ImageSequenceSource:
    """A folder of images, in name order, at ``fps`` (or the times of a ``frames.csv``
    beside them); an unreadable image is yielded without image and counted."""

    live = False

    def __init__(
        self,
        folder: str | Path,
        *,
        fps: float = 10.0,
        start_s: float = 0.0,
        frames_csv: str | Path | None = None,
    ) -> None:
        self.folder = Path(folder)
        self.name = str(self.folder)
        if not self.folder.is_dir():
            raise InputDataError(f"{self.folder}: image folder not found")
        self.files = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.files:
            raise InputDataError(f"{self.folder}: no images ({', '.join(IMAGE_SUFFIXES)})")
        if not fps > 0:
            raise InputDataError(f"{self.folder}: fps must be positive, got {fps}")
        self.fps = fps
        self.start_s = start_s
        csv_path = Path(frames_csv) if frames_csv else self.folder / "frames.csv"
        self.frames_csv = csv_path if csv_path.is_file() else None
        first = cv2.imread(str(self.files[0]), cv2.IMREAD_COLOR)
        self.size = (0, 0) if first is None else (int(first.shape[1]), int(first.shape[0]))
        self.decode_failures = 0
        self._closed = False

    @property
    def errors(self) -> int:
        return self.decode_failures

    def __iter__(self) -> Iterator[CameraFrame]:
        times = frame_times(self.frames_csv) if self.frames_csv is not None else None
        for i, path in enumerate(self.files):
            if self._closed:
                return
            t_rel = next(times, None) if times is not None else i / self.fps
            if t_rel is None or not math.isfinite(t_rel):
                return
            image = as_image(cv2.imread(str(path), cv2.IMREAD_COLOR))
            if image is None:
                self.decode_failures += 1
                log.warning("%s: cannot be read as an image; skipped", path)
                image = None
            yield CameraFrame(self.start_s + t_rel, image, i)

    def close(self) -> None:
        self._closed = True


def camera_kind(source: str) -> str:
    """``device`` (digits or a device node), ``stream`` (an URL), ``images`` (a folder) or
    ``file``."""
    if source.isdigit():
        return "device"
    if "://" in source:
        return "stream"
    path = Path(source)
    if path.is_file():
        return "file"
    if path.is_dir():
        return "images"
    if path.exists():
        return "device"  # /dev/video0
    raise InputDataError(f"camera {source!r}: no such file or device")


def open_camera(
    source: str,
    *,
    start_s: float | None = None,
    frames_csv: str | Path | None = None,
    reopen_s: float = 1.0,
    fps: float = 10.0,
) -> VideoFileSource | CameraDeviceSource | ImageSequenceSource:
    """The camera source for ``source`` (`camera_kind`). A file or an image folder starts
    at ``start_s`` (default: now, so that it lines up with a live bus), its frames timed
    by ``frames_csv`` when given."""
    kind = camera_kind(source)
    if kind in ("device", "stream"):
        return CameraDeviceSource(source, reopen_s=reopen_s)
    start = time.time() if start_s is None else start_s
    if kind == "images":
        return ImageSequenceSource(source, fps=fps, start_s=start, frames_csv=frames_csv)
    return VideoFileSource(source, start_s=start, frames_csv=frames_csv)


__all__ = [
    "CameraDeviceSource",
    "ImageSequenceSource",
    "VideoFileSource",
    "camera_kind",
    "frame_times",
    "open_camera",
]
