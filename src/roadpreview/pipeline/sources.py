"""Time-stamped input streams for replay: video frames and CAN frames, merged lazily.

Each source is an iterator of ``(t, kind, payload)`` on the CAN log's clock;
`merge_streams` interleaves them by time with ``heapq.merge``, so memory stays
bounded whatever the length of the recording.
"""

from __future__ import annotations

import csv
import heapq
import logging
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from roadpreview.canbus import read_can_log
from roadpreview.errors import InputDataError

log = logging.getLogger(__name__)

FRAME = 1  # CAN frames at the same instant go first (kind 0): the frame sees them
CAN = 0

Item = tuple[float, int, Any]


def frame_times(video: Path, frames_csv: Path | None, fps: float | None) -> Iterator[float] | None:
    """Frame time stamps (s from the start of the video): frames.csv if present, else None."""
    if frames_csv is None or not frames_csv.is_file():
        return None

    def rows() -> Iterator[float]:
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

    return rows()


class VideoSource:
    """Frames of a video file with their times on the log clock (``start_s`` + frame time).

    A frame that cannot be decoded is reported as ``None`` (the pipeline logs it
    and counts the frame as "no target"); the stream ends when the file does.
    """

    def __init__(
        self, path: str | Path, *, start_s: float = 0.0, frames_csv: str | Path | None = None
    ) -> None:
        self.path = Path(path)
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
        self.decode_failures = 0

    def __iter__(self) -> Iterator[Item]:
        cap = cv2.VideoCapture(str(self.path))
        times = frame_times(self.path, self.frames_csv, self.fps)
        i = 0
        misses = 0
        try:
            while True:
                ok, frame = cap.read()
                t_rel = next(times, None) if times is not None else i / self.fps
                if t_rel is None:
                    break
                if not ok:
                    # a corrupt frame inside the file: report it, try the next ones
                    if i >= self.n_frames - 1 or misses > 10:
                        break
                    misses += 1
                    self.decode_failures += 1
                    log.warning("%s: frame %d cannot be decoded; skipped", self.path, i)
                    yield (self.start_s + t_rel, FRAME, None)
                    i += 1
                    continue
                misses = 0
                yield (self.start_s + t_rel, FRAME, frame)
                i += 1
        finally:
            cap.release()


class CanSource:
    """Frames of one CAN log (any python-can format), garbled ones logged and skipped."""

    def __init__(self, path: str | Path, *, offset_s: float = 0.0) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputDataError(f"{self.path}: CAN log not found")
        self.offset_s = offset_s

    def __iter__(self) -> Iterator[Item]:
        last = -np.inf
        for msg in read_can_log(self.path):
            t = msg.timestamp + self.offset_s
            if t < last:
                log.warning(
                    "%s: time stamp goes back %.3f s at %.6f; kept in order",
                    self.path,
                    last - t,
                    msg.timestamp,
                )
                t = last
            last = t
            yield (t, CAN, msg)


def first_timestamp(path: str | Path) -> float:
    """Time stamp of the first frame of a CAN log."""
    for msg in read_can_log(path):
        return float(msg.timestamp)
    raise InputDataError(f"{path}: the CAN log holds no frame")


def merge_streams(sources: Iterable[Iterable[Item]]) -> Iterator[Item]:
    """All items of all sources in time order (CAN before a frame at the same instant)."""
    return heapq.merge(*sources, key=lambda item: (item[0], item[1]))
