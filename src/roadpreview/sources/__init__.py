"""Sources: where typed, time-stamped samples (`roadpreview.types`) come from.

Every source is an iterable of samples in time-stamp order, with a ``name`` for
messages, an ``errors`` count of the samples it lost (undecodable frames,
garbled CAN frames, bad rows) and ``close``. A source is *live* when its
samples arrive by themselves (a camera device, a CAN bus): the run loop reads
it in a thread of its own. A file source is read lazily, in the loop's thread.

* `video`: a video file (one clock rule: ``frames.csv`` if given, else frame
  index / fps, plus the start time), a camera device or stream, an image sequence;
* `can`: a CAN log (any format python-can reads) or a live bus, decoded *in the
  source* through the DBC and the input mapping into `ImuSample` / `SpeedSample`;
* `imu_csv`: a phone-style IMU CSV;
* `clockguard`: `ClockGuard`, one source's clock checked sample by sample (stray stamps
  dropped alone, clock steps detected, logged once and taken off);
* `recording`: the recording folder format (video, frames.csv, CAN log, camera,
  truth) that the simulator writes and replay reads.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import Protocol, runtime_checkable

from roadpreview.types import CameraFrame, InputSample, Sample


@runtime_checkable
class Source(Protocol):
    """An iterable of samples in time-stamp order (module docstring)."""

    #: what the source reads (a path, a device, a bus channel), for messages
    name: str
    #: True: samples arrive by themselves and the loop reads the source in a thread
    live: bool

    @property
    def errors(self) -> int:
        """Samples lost so far (logged where they were lost)."""
        ...

    def __iter__(self) -> Iterator[Sample]: ...

    def close(self) -> None:
        """Stop reading and release the device or file (idempotent)."""
        ...


def merge_key(sample: Sample, frame_hold_s: float = 0.0) -> tuple[float, int]:
    """Time order, and IMU/speed samples before a frame stamped at the same instant; a
    camera frame ordered ``frame_hold_s`` after its stamp (the samples stamped up to then
    go first: the run loop's hold, `roadpreview.loop.hold_frames`)."""
    if isinstance(sample, CameraFrame):
        return (sample.t_s + frame_hold_s, 1)
    return (sample.t_s, 0)


def shifted(sample: InputSample, offset_s: float) -> InputSample:
    """``sample`` moved by ``offset_s`` onto the pipeline's clock (itself when 0)."""
    return sample if offset_s == 0.0 else replace(sample, t_s=sample.t_s + offset_s)


def merge_sources(sources: Iterable[Iterable[Sample]]) -> Iterator[Sample]:
    """All samples of file sources in time order, lazily (one pending sample per source)."""
    return heapq.merge(*sources, key=merge_key)


__all__ = ["Source", "merge_key", "merge_sources", "shifted"]
