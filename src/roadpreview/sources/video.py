"""Camera sources: a video file, a camera device or stream, an image sequence.

One clock rule for a file, whoever reads it (replay, the daemon, the
evaluation): frame ``i`` is stamped ``start_s`` + the ``i``-th time of
``frames.csv`` (``frame,t_s``) when there is one, else ``start_s + i / fps``.
``frames.csv`` must have one row per frame (else `InputDataError` naming it and
both counts, before any frame is read); a bad row (`read_frame_times`) costs
that row's time only, interpolated from its neighbours, the other frames keep
theirs. A frame that cannot be decoded, or that decodes into something that is
not the scene (`roadpreview.vision.frame_check`: its content jumps as no ego
motion can; a damaged stream's frames until it is good again), is yielded with
``image=None`` (the pipeline counts it as a vision failure) and counted in
``errors`` and ``problems``; the file is read to its last frame (without a
frame count: until 10 undecodable frames in a row). A device or stream is
stamped ``time.time()`` when the frame is read, and reopened after a failure.
"""

from __future__ import annotations

import bisect
import csv
import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.errors import ConfigError, InputDataError
from roadpreview.types import CameraFrame, Image
from roadpreview.vision.frame_check import JUMP_GREY, FrameIntegrity, Verdict, thumbnail

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


def increasing_rows(t: NDArray[np.float64]) -> NDArray[np.bool_]:
    """The rows of ``t`` that belong to its longest strictly increasing run of finite
    values (rows need not be adjacent): the time stamps that agree with each other.
    A stamp that jumps ahead or back, or is NaN, is left out; the rest keep theirs."""
    ok = np.isfinite(t)
    idx = np.flatnonzero(ok)
    if idx.size < 2 or bool(np.all(np.diff(t[idx]) > 0)):
        return ok
    # patience sorting: tails[k] = row ending the best run of length k + 1
    tails: list[int] = []
    tail_t: list[float] = []
    prev = np.full(t.size, -1)
    for i in idx.tolist():
        ti = float(t[i])
        k = bisect.bisect_left(tail_t, ti)
        if k > 0:
            prev[i] = tails[k - 1]
        if k == len(tails):
            tails.append(i)
            tail_t.append(ti)
        else:
            tails[k] = i
            tail_t[k] = ti
    keep = np.zeros(t.size, dtype=bool)
    i = tails[-1]
    while i >= 0:
        keep[i] = True
        i = int(prev[i])
    return keep


def fill_times(t: NDArray[np.float64], good: NDArray[np.bool_], dt: float) -> NDArray[np.float64]:
    """``t`` with the rows not ``good`` interpolated linearly (in the row index) from the
    good rows around them; before the first and after the last good row, extrapolated by
    the good rows' median interval (``dt`` if there is only one good row)."""
    idx = np.flatnonzero(good)
    rows = np.arange(t.size, dtype=np.float64)
    if idx.size >= 2:
        dt = float(np.median(np.diff(t[idx]) / np.diff(idx)))
    out = np.interp(rows, idx.astype(np.float64), t[idx])
    out[: idx[0]] = t[idx[0]] - dt * (idx[0] - rows[: idx[0]])
    out[idx[-1] + 1 :] = t[idx[-1]] + dt * (rows[idx[-1] + 1 :] - idx[-1])
    return out


@dataclass(frozen=True)
class FrameTimes:
    """The time stamps of a ``frames.csv`` (``frame,t_s``), one per row, s: a bad row (not
    two fields, a frame number that is not its row's, a time that is not a number or not
    finite, or out of order with the rows around it) gets a time interpolated from its
    neighbours; ``bad_rows`` says which (line number, why)."""

    path: Path
    t_s: NDArray[np.float64]
    bad_rows: tuple[tuple[int, str], ...]

    def __len__(self) -> int:
        return int(self.t_s.size)

    def log_bad_rows(self, limit: int = 10) -> None:
        """Warn about the bad rows: one line each for the first ``limit``, then one sum."""
        for line_no, why in self.bad_rows[:limit]:
            log.warning(
                "%s:%d: %s; the frame's time is interpolated from its neighbours",
                self.path,
                line_no,
                why,
            )
        if len(self.bad_rows) > limit:
            log.warning(
                "%s: %d bad rows in all (of %d), each frame's time interpolated",
                self.path,
                len(self.bad_rows),
                len(self),
            )


def read_frame_times(frames_csv: Path, *, fps: float = 30.0) -> FrameTimes:
    """Read ``frames.csv`` (`FrameTimes`); ``fps`` extrapolates when only one row is good.

    Raises `InputDataError` for a wrong header or a table without two good rows."""
    with frames_csv.open(newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header != ["frame", "t_s"]:
            raise InputDataError(f"{frames_csv}: header must be 'frame,t_s', got {header}")
        times: list[float] = []
        why: dict[int, tuple[int, str]] = {}  # row -> (line number, reason)
        for line_no, row in enumerate(reader, start=2):
            if not row or not "".join(row).strip():
                continue  # a blank line is no row
            k = len(times)
            t = math.nan
            if len(row) != 2:
                why[k] = (line_no, f"{len(row)} fields, not 2 ({','.join(row)[:40]!r})")
            elif row[0].strip() != str(k):
                why[k] = (line_no, f"frame {row[0][:20]!r} in the row of frame {k}")
            else:
                try:
                    t = float(row[1])
                except ValueError:
                    why[k] = (line_no, f"t_s {row[1][:20]!r} is not a number")
                else:
                    if not math.isfinite(t):
                        why[k] = (line_no, f"t_s {row[1]!r} is not finite")
            times.append(t)
    t_s = np.array(times, dtype=np.float64)
    good = increasing_rows(t_s)
    line_of = {k: line_no for k, (line_no, _) in why.items()}
    for late in np.flatnonzero(np.isfinite(t_s) & ~good).tolist():
        why[late] = (line_of.get(late, late + 2), f"t_s {t_s[late]:.6f} is out of order")
    if int(good.sum()) < min(2, t_s.size) or t_s.size == 0:
        raise InputDataError(
            f"{frames_csv}: {int(good.sum())} usable time stamps in {t_s.size} rows"
        )
    bad = tuple(why[k] for k in sorted(why))
    filled = fill_times(t_s, good, 1.0 / fps) if bad else t_s
    return FrameTimes(frames_csv, filled, bad)


def frame_times(frames_csv: Path) -> Iterator[float]:
    """The time stamps of ``frames.csv``, s (`read_frame_times`: bad rows interpolated)."""
    yield from (float(t) for t in read_frame_times(frames_csv).t_s)


def _check_rows(table: FrameTimes, n_frames: int, what: str) -> None:
    """Refuse a frame table whose rows do not match the frames one to one."""
    if n_frames > 0 and len(table) != n_frames:
        raise InputDataError(
            f"{table.path}: {len(table)} time stamps for the {n_frames} frames of {what};"
            " frames.csv needs one row per frame"
        )


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
        self.frame_table: FrameTimes | None = None
        if self.frames_csv is not None:
            if not self.frames_csv.is_file():
                raise InputDataError(f"{self.frames_csv}: frame time stamps not found")
            self.frame_table = read_frame_times(self.frames_csv, fps=self.fps)
            _check_rows(self.frame_table, self.n_frames, f"the video {self.path}")
        self.decode_failures = 0  #: frames that could not be decoded
        self.corrupt_frames = 0  #: decoded frames dropped as not the scene (`frame_check`)
        self._closed = False

    @property
    def errors(self) -> int:
        """Frames yielded without image: undecodable or corrupt."""
        return self.decode_failures + self.corrupt_frames

    @property
    def problems(self) -> Counter[str]:
        """Problems by kind: ``undecodable_frame``, ``corrupt_frame``, ``bad_time_row``
        (a frames.csv row whose time was interpolated)."""
        counts: Counter[str] = Counter()
        counts["undecodable_frame"] = self.decode_failures
        counts["corrupt_frame"] = self.corrupt_frames
        if self.frame_table is not None:
            counts["bad_time_row"] = len(self.frame_table.bad_rows)
        return +counts  # the kinds that happened

    def check_size(self, size: tuple[int, int]) -> None:
        """Raise if the frames are not ``size`` (width, height): the calibration's."""
        if self.size != size:
            raise InputDataError(
                f"{self.path}: frames are {self.size[0]}x{self.size[1]} but the camera "
                f"calibration is for {size[0]}x{size[1]}"
            )

    def __iter__(self) -> Iterator[CameraFrame]:
        """The frames, each yielded once the next one is read: a frame decoded just
        before an undecodable one is dropped too (it is decoded only in part)."""
        table = self.frame_table
        if table is not None:
            table.log_bad_rows()
        self.decode_failures = self.corrupt_frames = 0
        report = _DamageReport(self.path)
        pending: tuple[CameraFrame, str] | None = None
        for frame, status in self._decoded(report):
            if pending is not None:
                held, held_status = pending
                if status == "undecodable" and held_status == "good":
                    held, held_status = CameraFrame(held.t_s, None, held.index), "partial"
                yield self._account(held, held_status, report)
            pending = (frame, status)
        if pending is not None:
            yield self._account(*pending, report)
        report.close()

    def _account(self, frame: CameraFrame, status: str, report: _DamageReport) -> CameraFrame:
        """Count and report ``frame`` as it leaves the source."""
        if status == "good":
            report.good(frame.index)
        elif status == "undecodable":
            self.decode_failures += 1
            report.bad(frame.index, "cannot be decoded")
        else:
            self.corrupt_frames += 1
            report.bad(frame.index, status)
        return frame

    def _decoded(self, report: _DamageReport) -> Iterator[tuple[CameraFrame, str]]:
        """Each frame with its status: ``good``, ``undecodable`` (no image) or why it is
        dropped (`FrameIntegrity`; no image)."""
        cap = cv2.VideoCapture(str(self.path))
        table = self.frame_table
        integrity = FrameIntegrity(max_untrusted=max(1, round(UNTRUSTED_S * self.fps)))
        i = misses = 0
        try:
            while not self._closed:
                ok, image = cap.read()
                if table is not None and i >= len(table):
                    if ok:
                        log.warning(
                            "%s: more frames than the %d rows of %s; the rest is not read",
                            self.path,
                            len(table),
                            table.path,
                        )
                    break
                t = self.start_s + (float(table.t_s[i]) if table is not None else i / self.fps)
                frame = as_image(image) if ok else None
                if frame is None:
                    known_end = self.n_frames > 0 and i >= self.n_frames - 1
                    if known_end or (self.n_frames <= 0 and misses >= MAX_MISSES):
                        break
                    misses += 1
                    integrity.undecodable()
                    yield CameraFrame(t, None, i), "undecodable"
                else:
                    misses = 0
                    verdict = integrity.check(thumbnail(frame))
                    if verdict is Verdict.GOOD:
                        yield CameraFrame(t, frame, i), "good"
                    elif verdict is Verdict.CORRUPT:
                        why = f"is corrupt (content jumps {integrity.last_jump:.1f} grey levels,"
                        yield CameraFrame(t, None, i), f"{why} limit {JUMP_GREY:g})"
                    else:
                        yield CameraFrame(t, None, i), "is not trusted yet after damage"
                i += 1
        finally:
            cap.release()

    def close(self) -> None:
        self._closed = True


#: after damage, frames dropped at most while waiting for the picture to re-anchor, s
UNTRUSTED_S = 2.0


class _DamageReport:
    """The log lines of a video's damage: one when a stretch of frames without image
    begins (why), one when good frames resume (with the count); after
    `MAX_DAMAGE_REPORTS` stretches only counted, summed up at the end."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.stretches = 0
        self._bad_since: int | None = None
        self._bad = 0
        self._last = -1

    def bad(self, i: int, why: str) -> None:
        self._last = i
        if self._bad_since is None:
            self._bad_since = i
            self.stretches += 1
            if self.stretches <= MAX_DAMAGE_REPORTS:
                log.warning(
                    "%s: frame %d %s; frames without image until the video is good again",
                    self.path,
                    i,
                    why if why != "partial" else "is decoded only in part",
                )
        self._bad += 1

    def good(self, i: int) -> None:
        self._last = i
        if self._bad_since is None:
            return
        if self.stretches <= MAX_DAMAGE_REPORTS:
            log.warning(
                "%s: frames %d-%d (%d) undecodable or corrupt; good again from frame %d",
                self.path,
                self._bad_since,
                i - 1,
                self._bad,
                i,
            )
        self._bad_since, self._bad = None, 0

    def close(self) -> None:
        if self._bad_since is not None and self.stretches <= MAX_DAMAGE_REPORTS:
            log.warning(
                "%s: frames %d-%d (%d) undecodable or corrupt, to the end of the video",
                self.path,
                self._bad_since,
                self._last,
                self._bad,
            )
        if self.stretches > MAX_DAMAGE_REPORTS:
            log.warning(
                "%s: %d damaged stretches in all; the first %d were logged",
                self.path,
                self.stretches,
                MAX_DAMAGE_REPORTS,
            )


#: damaged stretches of one video logged one by one
MAX_DAMAGE_REPORTS = 10


class CameraDeviceSource:
    """A camera device (an index or ``/dev/video*``), a stream URL or a GStreamer pipeline,
    stamped with ``time.time()`` when read; reopened ``reopen_s`` after a failure. Live.

    Backends: ``/dev/videoN`` opens with V4L2; a source starting with ``gst:`` or holding
    `` ! `` is a GStreamer pipeline (ending in ``appsink``), opened with GStreamer only if
    this OpenCV build has it (`ConfigError` otherwise); anything else with OpenCV's
    default (an index: V4L2 on Linux; a URL: FFmpeg). After each open, a non-zero
    ``width``, ``height`` and ``fps`` are requested (``CAP_PROP_FRAME_WIDTH/HEIGHT/FPS``),
    read back and logged, with a warning for each one the camera refused. A frame whose
    size is not ``expected_size`` (the calibration's) is yielded without image and counted
    in ``size_mismatches``: the pipeline's geometry holds for one size only.
    """

    live = True

    def __init__(
        self,
        source: str,
        *,
        reopen_s: float = 1.0,
        width: int = 0,
        height: int = 0,
        fps: float = 0.0,
        expected_size: tuple[int, int] | None = None,
    ) -> None:
        self.name = source
        self.source = source
        self.reopen_s = reopen_s
        self.requested = {"width": width, "height": height, "fps": fps}  #: 0: the default
        self.expected_size = expected_size
        self.pipeline = self.gstreamer_pipeline(source)
        if self.pipeline is not None and not self.gstreamer_available():
            raise ConfigError(
                f"camera {source!r}: a GStreamer pipeline, but this OpenCV build has no "
                "GStreamer (cv2.getBuildInformation(): GStreamer NO; the opencv-python "
                "wheels never have it): use /dev/videoN (V4L2) or a stream URL (FFmpeg), "
                "or install an OpenCV built with GStreamer (e.g. the distribution's "
                "python3-opencv, venv with --system-site-packages)"
            )
        if self.pipeline is not None:
            self.kind, self.backend = "gstreamer", cv2.CAP_GSTREAMER
        elif source.startswith("/dev/video"):
            self.kind, self.backend = "device", cv2.CAP_V4L2
        else:
            self.kind = "device" if source.isdigit() else "stream"
            self.backend = cv2.CAP_ANY
        self.read_failures = 0  #: reads that failed (each ends an open)
        self.size_mismatches = 0  #: frames not of ``expected_size`` (yielded without image)
        self.opens = 0  #: successful opens
        #: what the camera gave at the last open: (width, height) and fps (0: not reported)
        self.size: tuple[int, int] = (0, 0)
        self.fps = 0.0
        self._cap: cv2.VideoCapture | None = None
        self._stop = threading.Event()

    @staticmethod
    def gstreamer_pipeline(source: str) -> str | None:
        """The pipeline of a ``gst:`` source or one holding `` ! ``, else None."""
        if source.startswith("gst:"):
            return source[4:].strip()
        return source if " ! " in source else None

    @staticmethod
    def gstreamer_available() -> bool:
        """Whether this OpenCV build can open GStreamer pipelines (its build information
        says ``GStreamer: YES``)."""
        for line in cv2.getBuildInformation().splitlines():
            key, _, value = line.strip().partition(":")
            if key.strip() == "GStreamer":
                return value.strip().upper().startswith("YES")
        return False

    @property
    def errors(self) -> int:
        return self.read_failures + self.size_mismatches

    def open(self) -> bool:
        """Open the camera now (else the first iteration does) and apply the settings;
        False (logged) when it cannot be opened."""
        if self._cap is None:
            self._cap = self._open()
        return self._cap is not None

    def _open(self) -> cv2.VideoCapture | None:
        target: int | str = self.source
        if self.pipeline is not None:
            target = self.pipeline
        elif self.source.isdigit():
            target = int(self.source)
        cap = cv2.VideoCapture(target, self.backend)
        if not cap.isOpened():
            cap.release()
            log.error("camera %s: cannot open", self.source)
            return None
        self.opens += 1
        self._apply_settings(cap)
        return cap

    def _apply_settings(self, cap: cv2.VideoCapture) -> None:
        """Request the non-zero settings, read everything back, log it; warn on refusals."""
        props = {
            "width": cv2.CAP_PROP_FRAME_WIDTH,
            "height": cv2.CAP_PROP_FRAME_HEIGHT,
            "fps": cv2.CAP_PROP_FPS,
        }
        for key, prop in props.items():
            if self.requested[key] > 0:
                cap.set(prop, float(self.requested[key]))
        got = {key: float(cap.get(prop)) for key, prop in props.items()}
        self.size = (int(got["width"]), int(got["height"]))
        self.fps = got["fps"]
        log.info(
            "event=camera_opened source=%r backend=%s width=%d height=%d fps=%g",
            self.source,
            cap.getBackendName(),
            self.size[0],
            self.size[1],
            self.fps,
        )
        for key, wanted in self.requested.items():
            if wanted > 0 and abs(got[key] - wanted) > 0.01 * wanted:
                log.warning(
                    "event=camera_setting_refused source=%r setting=%s requested=%g actual=%g",
                    self.source,
                    key,
                    wanted,
                    got[key],
                )

    def __iter__(self) -> Iterator[CameraFrame]:
        i = 0
        while not self._stop.is_set():
            cap, self._cap = self._cap or self._open(), None
            if cap is None:
                self._stop.wait(self.reopen_s)
                continue
            warned = False
            try:
                while not self._stop.is_set():
                    ok, image = cap.read()
                    now = time.time()
                    if not ok or image is None:
                        self.read_failures += 1
                        log.error("camera %s: frame %d cannot be read; reopening", self.source, i)
                        break
                    frame = as_image(image)
                    size = (int(image.shape[1]), int(image.shape[0]))
                    if self.expected_size is not None and size != self.expected_size:
                        self.size_mismatches += 1
                        frame = None
                        if not warned:
                            warned = True
                            log.error(
                                "camera %s: frames are %dx%d but the calibration is for %dx%d;"
                                " frames without image until the camera is fixed",
                                self.source,
                                *size,
                                *self.expected_size,
                            )
                    yield CameraFrame(now, frame, i)
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
        self.frame_table: FrameTimes | None = None
        if self.frames_csv is not None:
            self.frame_table = read_frame_times(self.frames_csv, fps=fps)
            _check_rows(self.frame_table, len(self.files), f"the images in {self.folder}")
        first = cv2.imread(str(self.files[0]), cv2.IMREAD_COLOR)
        self.size = (0, 0) if first is None else (int(first.shape[1]), int(first.shape[0]))
        self.decode_failures = 0
        self._closed = False

    @property
    def errors(self) -> int:
        return self.decode_failures

    def __iter__(self) -> Iterator[CameraFrame]:
        table = self.frame_table
        if table is not None:
            table.log_bad_rows()
        for i, path in enumerate(self.files):
            if self._closed:
                return
            t_rel = float(table.t_s[i]) if table is not None else i / self.fps
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
    device_width: int = 0,
    device_height: int = 0,
    device_fps: float = 0.0,
    expected_size: tuple[int, int] | None = None,
) -> VideoFileSource | CameraDeviceSource | ImageSequenceSource:
    """The camera source for ``source``: a GStreamer pipeline
    (`CameraDeviceSource.gstreamer_pipeline`) or a device or stream (`camera_kind`) is a
    `CameraDeviceSource` with the ``device_*`` settings (0: the camera's default) and
    ``expected_size``; a file or an image folder starts at ``start_s`` (default: now, so
    that it lines up with a live bus), its frames timed by ``frames_csv`` when given."""
    if CameraDeviceSource.gstreamer_pipeline(source) is not None or camera_kind(source) in (
        "device",
        "stream",
    ):
        return CameraDeviceSource(
            source,
            reopen_s=reopen_s,
            width=device_width,
            height=device_height,
            fps=device_fps,
            expected_size=expected_size,
        )
    start = time.time() if start_s is None else start_s
    if camera_kind(source) == "images":
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
