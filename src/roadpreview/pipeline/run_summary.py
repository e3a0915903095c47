"""What a run of the loop did (`RunSummary`), as the sinks and the apps read it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from roadpreview.pipeline.pipeline import FrameResult
from roadpreview.types import Alert, ConfirmationResult, FusionMode


class FrameTimes:
    """Distribution of the per-frame processing time in constant memory (0.25 ms bins up
    to 250 ms, the exact maximum)."""

    BIN_MS = 0.25
    BINS = 1000

    def __init__(self) -> None:
        self.counts = [0] * (self.BINS + 1)  # the last bin: beyond 250 ms
        self.n = 0
        self.max = math.nan

    def add(self, ms: float) -> None:
        self.counts[min(int(ms / self.BIN_MS), self.BINS)] += 1
        self.n += 1
        if self.n == 1 or ms > self.max:
            self.max = ms

    def quantile(self, q: float) -> float:
        """Upper edge of the bin holding the ``q`` quantile, ms (NaN without frames)."""
        if self.n == 0:
            return math.nan
        rank = q * self.n
        total = 0
        for i, c in enumerate(self.counts):  # 1001 bins, once at exit
            total += c
            if total >= rank and c:
                return min((i + 1) * self.BIN_MS, self.max)
        return self.max


@dataclass
class RunSummary:
    """What a run did."""

    frames: int = 0  #: camera frames pushed (watchdog frames not counted)
    samples: int = 0  #: IMU and speed samples pushed
    frames_out_of_order: int = 0  #: camera frames not after the previous one (skipped)
    frames_dropped: int = 0  #: frames skipped because a newer one was due (live runs)
    injected_frames: int = 0  #: image-less frames the watchdogs pushed
    alerts: list[Alert] = field(default_factory=list)  #: CONFIRMED alerts
    provisional: list[Alert] = field(default_factory=list)  #: PROVISIONAL alerts raised
    cancelled: list[Alert] = field(default_factory=list)  #: provisional alerts cancelled
    confirmations: list[ConfirmationResult] = field(default_factory=list)
    #: (time, mode, reason) at the first frame and at every change of the mode or of the
    #: gyro's state (none yet, recent, timed out: `fusion.mode_machine.gyro_state`), so
    #: that the reason (`fusion.mode_machine.mode_reason`) holds until the next entry
    mode_changes: list[tuple[float, FusionMode, str]] = field(default_factory=list)
    first_t: float = math.nan  #: time of the first frame
    last_t: float = math.nan  #: time of the last frame
    seconds: float = 0.0  #: wall time of the run
    interrupted: bool = False  #: stopped before the input ended
    error: str = ""  #: the exception that ended the run ('' if none)
    sink_errors: int = 0
    queue_drops: int = 0  #: samples lost because the live merge's queue was full
    source_errors: dict[str, int] = field(default_factory=dict)  #: samples lost, per source
    #: per source: reason -> count (``skipped_bad_line``, ``rejected_range``, ``resynced``,
    #: ``thread_died``, ...: the ``problems`` the source and its decoder expose, and the
    #: loop's restarts; `roadpreview.loop.source_problems`)
    source_problems: dict[str, dict[str, int]] = field(default_factory=dict)
    #: per source: exceptions out of its iterator (the loop restarted it, or gave up)
    thread_deaths: dict[str, int] = field(default_factory=dict)
    frame_ms: FrameTimes = field(default_factory=FrameTimes)  #: processing time per frame
    last: FrameResult | None = None  #: the last frame's result

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else math.nan


__all__ = ["FrameTimes", "RunSummary"]
