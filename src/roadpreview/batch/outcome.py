"""What one drive of a batch gave: `DriveOutcome`, a plain record that travels from the
worker to the client (pickled) and into ``batch.json`` (JSON), then into the fleet
tables and report."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Literal

Status = Literal["done", "skipped", "failed"]

#: the fusion modes' names, in the tables' column order
MODES = ("FUSED", "VISUAL_ONLY", "IMU_ONLY", "DEGRADED")


@dataclass
class DriveOutcome:
    """One drive's result. ``status``: ``done`` (replayed now), ``skipped`` (outputs
    complete and nothing changed: the figures are the earlier run's) or ``failed``
    (``message`` says why, in one line). NaN: not known (no speed input: no distance)."""

    drive: str  #: the drive's id (its sub-folder's name)
    status: Status
    message: str = ""  #: the error of a failed drive; the unusable inputs of a done one
    folder: str = ""  #: its output sub-folder
    frames: int = 0
    duration_s: float = math.nan  #: drive time covered, first to last frame, s
    distance_km: float = math.nan  #: distance driven (ego speed integrated), km
    replay_s: float = math.nan  #: wall time of the replay's run loop, s
    task_s: float = math.nan  #: wall time of the whole task on its worker (this run), s
    fps: float = math.nan  #: frames per second of wall time
    alerts: int = 0
    #: share of the drive's time in each fusion mode (`MODES`), 0..1
    modes: dict[str, float] = field(default_factory=dict)
    road_class: str | None = None  #: ISO 8608 class at the end (ego's, else lead's)
    decode_failures: int = 0  #: video frames that could not be decoded
    input_errors: int = 0  #: CAN/IMU samples lost
    unusable_inputs: int = 0  #: inputs that gave nothing (the drive ran without them)
    #: with truth: ``expected``, ``hits``, ``false_alarms``, ``minutes``
    truth: dict[str, float] | None = None
    worker: str = ""  #: the worker that ran it (its address)
    #: the drive's alerts as in its alerts.jsonl (one dict per alert)
    alert_rows: list[dict[str, Any]] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.status != "failed"

    @property
    def alerts_per_km(self) -> float:
        d = self.distance_km
        return self.alerts / d if d > 0 else math.nan

    @property
    def alerts_per_hour(self) -> float:
        h = self.duration_s / 3600.0
        return self.alerts / h if h > 0 else math.nan

    def to_json(self) -> dict[str, Any]:
        """A JSON-safe mapping (NaN -> None)."""
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in asdict(self).items()
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> DriveOutcome:
        known = {f.name for f in fields(cls)}
        kw = {k: v for k, v in data.items() if k in known}
        for f in fields(cls):
            if f.type == "float" and kw.get(f.name) is None and f.name in kw:
                kw[f.name] = math.nan
        return cls(**kw)


__all__ = ["MODES", "DriveOutcome", "Status"]
