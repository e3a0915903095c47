"""A time window over a source: only the samples stamped in ``[start_s, end_s]``
(``replay --start/--end`` cuts a long drive).

A source that can seek (a ``seek(t_s)`` method) is asked to jump to ``start_s``;
any other is read from its beginning and the samples before ``start_s`` are
dropped (a video's frames are then decoded and thrown away: slower, same result).
The window ends the source at the first sample after ``end_s``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator

from roadpreview.sources import Source
from roadpreview.types import Sample

log = logging.getLogger(__name__)


class WindowedSource:
    """``source`` limited to the samples stamped in ``[start_s, end_s]`` (module docstring)."""

    def __init__(self, source: Source, start_s: float = -math.inf, end_s: float = math.inf) -> None:
        if not start_s <= end_s:
            raise ValueError(f"window start {start_s} s is after its end {end_s} s")
        self.source = source
        self.start_s = start_s
        self.end_s = end_s
        self.name = source.name
        self.live = source.live
        self.skipped = 0  #: samples read and dropped before ``start_s``

    @property
    def errors(self) -> int:
        return self.source.errors

    def __iter__(self) -> Iterator[Sample]:
        seek = getattr(self.source, "seek", None)
        if callable(seek) and math.isfinite(self.start_s):
            seek(self.start_s)
        for sample in self.source:
            if sample.t_s < self.start_s:
                self.skipped += 1
                continue
            if sample.t_s > self.end_s:
                break
            yield sample
        if self.skipped:
            log.info("%s: %d samples before the window skipped", self.name, self.skipped)

    def close(self) -> None:
        self.source.close()
