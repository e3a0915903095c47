"""Progress of a long run for a person: a bar on a terminal, a log line now and then in a
file or a pipe.

On a terminal (stderr is a TTY) a tqdm bar shows frames done / total, the rate and the
time left; otherwise a line is logged every ``every_s`` seconds (logger
``roadpreview.progress``, INFO, which the CLI shows unless ``-q``). The run loop calls the
object with (frames done, seconds since start).
"""

from __future__ import annotations

import importlib
import logging
import sys
import time
from typing import Any, TextIO

log = logging.getLogger("roadpreview.progress")


def format_duration(seconds: float) -> str:
    """``m:ss``, or ``h:mm:ss`` from an hour on."""
    s = max(0, round(seconds))
    return (
        f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"
    )


class Progress:
    """Frames processed against ``total`` (module docstring). ``enabled`` False: silent.
    ``stream``: where the bar goes (default stderr); ``tty`` overrides its detection."""

    def __init__(
        self,
        label: str = "replay",
        *,
        enabled: bool = True,
        every_s: float = 10.0,
        stream: TextIO | None = None,
        tty: bool | None = None,
    ) -> None:
        self.label = label
        self.enabled = enabled
        self.every_s = every_s
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.total: int | None = None
        self.frames = 0
        self._bar: Any = None  # a tqdm bar (tqdm ships no type stubs)
        self._next_log = 0.0
        self._t0 = time.monotonic()

    def start(self, total: int | None) -> None:
        """The run begins: ``total`` frames expected (None or 0: unknown)."""
        self.total = total or None
        self._t0 = time.monotonic()
        self._next_log = self._t0 + self.every_s
        if self.enabled and self.tty:
            tqdm = importlib.import_module("tqdm").tqdm
            self._bar = tqdm(
                total=self.total,
                desc=self.label,
                unit="frame",
                file=self.stream,
                dynamic_ncols=True,
                smoothing=0.1,
            )

    def __call__(self, frames: int, seconds: float) -> None:
        """``frames`` done after ``seconds`` of wall time."""
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(frames - self.frames)
        elif time.monotonic() >= self._next_log:
            self._next_log = time.monotonic() + self.every_s
            log.info("%s", self.line(frames, seconds))
        self.frames = frames

    def line(self, frames: int, seconds: float) -> str:
        """``replay: 300/1800 frames (16.7 %), 28.4 fps, 0:10 elapsed, 0:53 left``."""
        fps = frames / seconds if seconds > 0 else 0.0
        elapsed = format_duration(seconds)
        if self.total is None:
            return f"{self.label}: {frames} frames, {fps:.1f} fps, {elapsed} elapsed"
        left = format_duration((self.total - frames) / fps) if fps > 0 else "?"
        return (
            f"{self.label}: {frames}/{self.total} frames ({100 * frames / self.total:.1f} %), "
            f"{fps:.1f} fps, {elapsed} elapsed, {left} left"
        )

    def close(self, frames: int | None = None) -> None:
        """The run ended after ``frames`` (default: the last count seen); without a bar
        the last line is logged."""
        if frames is not None and self._bar is not None:
            self._bar.update(frames - self.frames)
        if frames is not None:
            self.frames = frames
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self.enabled and self._next_log:
            self._next_log = 0.0  # once
            log.info("%s (done)", self.line(self.frames, time.monotonic() - self._t0))
