"""What a replay did (`ReplayResult`): the run loop's `RunSummary` plus the replay's own
findings. `replay` returns it, `summary` writes it to ``summary.json``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from roadpreview.pipeline.pipeline import FrameResult
from roadpreview.pipeline.run_summary import RunSummary
from roadpreview.pipeline.truthmatch import MatchReport
from roadpreview.types import Alert, ConfirmationResult, FusionMode, RoadState


@dataclass
class ReplayResult:
    """What a replay did (`RunSummary` plus the replay's own findings)."""

    run: RunSummary
    video_start_s: float
    out: Path | None
    match: MatchReport | None = None
    results: list[FrameResult] | None = None
    video_name: str = ""  #: the video source's name (its errors are decode failures)
    clock_notes: list[str] = field(default_factory=list)  #: how the inputs were put on one clock
    #: inputs that gave nothing: ``{"path": ..., "reason": ...}`` (`replay`)
    unusable_inputs: list[dict[str, str]] = field(default_factory=list)

    @property
    def frames(self) -> int:
        return self.run.frames

    @property
    def alerts(self) -> list[Alert]:
        return self.run.alerts

    @property
    def confirmations(self) -> list[ConfirmationResult]:
        return self.run.confirmations

    @property
    def mode_changes(self) -> list[tuple[float, FusionMode, str]]:
        return self.run.mode_changes

    @property
    def seconds(self) -> float:
        return self.run.seconds

    @property
    def fps(self) -> float:
        return self.run.fps

    @property
    def interrupted(self) -> bool:
        return self.run.interrupted

    @property
    def road(self) -> RoadState:
        """The road class at the end."""
        return self.run.last.road if self.run.last is not None else RoadState()

    @property
    def decode_failures(self) -> int:
        """Video frames that could not be decoded."""
        return self.run.source_errors.get(self.video_name, 0)

    @property
    def input_errors(self) -> int:
        """Samples the CAN and IMU sources lost."""
        errors = self.run.source_errors
        return sum(n for name, n in errors.items() if name != self.video_name)
