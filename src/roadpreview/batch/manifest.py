"""Which drives a batch replays: a folder of recordings, or a manifest that lists them.

**A folder** (`discover`). Each entry is one drive, its id the entry's name:

* a sub-folder that is a roadpreview recording (``scenario.toml``, ``camera.toml``, ...);
* a ROS bag (a rosbag2 sub-folder, or a ``.mcap`` / ``.db3`` / ``.bag`` file);
* a video (``.mp4 .mkv .avi .mov``) with its companions by name: ``<stem>.blf`` (and the
  other CAN log suffixes but ``.csv``; a CAN CSV goes in a manifest), ``<stem>.imu.csv``,
  ``<stem>.frames.csv``.

A bag or a video needs a camera calibration: ``<stem>.camera.toml``, else ``camera.toml``
in the folder, else the batch's ``--camera``.

**A manifest** (`read_manifest`): a CSV with a header row, or a TOML file with an optional
``[defaults]`` table and one ``[[drive]]`` table per drive. The keys (`FIELDS`) are those
of ``roadpreview replay``: ``input`` (required), ``drive`` (its id; default the input's
name), ``camera``, ``can`` (a list in TOML; ``;``-separated in CSV), ``imu_csv``,
``frames_csv``, ``video_start_s``, ``can_offset_s``, ``imu_offset_s``, ``image_topic``,
``imu_topic``, ``speed_topic``, ``start_s``, ``end_s``, and the per-drive overrides of
the pipeline: ``config`` (a TOML file replacing the batch's ``--config``), ``dbc``,
``mapping``. Relative paths are relative to the manifest's folder. An unknown key, a
missing input or a repeated id is an error naming the manifest and the row.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roadpreview._tomlio import load_toml
from roadpreview.errors import ConfigError

if TYPE_CHECKING:
    from roadpreview.apps.replay import ReplayInputs
    from roadpreview.pipeline.config import PipelineConfig

VIDEO_SUFFIXES = (".mp4", ".mkv", ".avi", ".mov")
BAG_SUFFIXES = (".mcap", ".db3", ".bag")
#: CAN log suffixes found next to a video by its stem (a CAN ``.csv`` only via a manifest)
CAN_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".mf4", ".db", ".asc.gz", ".log.gz", ".trc.gz")
_PATHS = ("input", "camera", "imu_csv", "frames_csv", "config", "dbc")
_FLOATS = ("video_start_s", "can_offset_s", "imu_offset_s", "start_s", "end_s")


@dataclass(frozen=True)
class DriveSpec:
    """One drive of a batch: what to read and how (module docstring)."""

    drive: str  #: its id: the output sub-folder's name, the tables' ``drive`` column
    input: Path  #: recording folder, video or bag
    camera: Path | None = None
    can: tuple[Path, ...] = ()
    imu_csv: Path | None = None
    frames_csv: Path | None = None
    video_start_s: float | None = None
    can_offset_s: float | None = None
    imu_offset_s: float | None = None
    image_topic: str | None = None
    imu_topic: str | None = None
    speed_topic: str | None = None
    start_s: float | None = None  #: replay from this time (s from frame 0)
    end_s: float | None = None  #: replay up to this time
    config: Path | None = None  #: this drive's pipeline configuration (else the batch's)
    dbc: Path | None = None
    mapping: str | None = None
    where: str = field(default="", compare=False)  #: where it was listed (for errors)

    def replay_inputs(self, *, truth: bool = False) -> ReplayInputs:
        """The drive as `roadpreview.apps.replay.replay` takes it."""
        from roadpreview.apps.replay import drive_inputs

        return drive_inputs(
            self.input,
            camera=self.camera,
            can_logs=list(self.can),
            imu_csv=self.imu_csv,
            frames_csv=self.frames_csv,
            video_start_s=self.video_start_s,
            can_offset_s=self.can_offset_s,
            imu_offset_s=self.imu_offset_s,
            image_topic=self.image_topic,
            imu_topic=self.imu_topic,
            speed_topic=self.speed_topic,
            truth=truth,
        )

    def pipeline_config(self, base: PipelineConfig) -> PipelineConfig:
        """``base`` (the batch's), or this drive's ``config`` file, with its DBC/mapping."""
        from roadpreview.pipeline.config import PipelineConfig

        cfg = PipelineConfig.load(self.config) if self.config is not None else base
        if self.dbc is not None:
            cfg = replace(cfg, can=replace(cfg.can, dbc=str(self.dbc)))
        if self.mapping is not None:
            cfg = replace(cfg, can=replace(cfg.can, mapping=str(self.mapping)))
        return cfg

    def files(self) -> list[Path]:
        """The files named by the spec (besides what a recording folder holds)."""
        named = [self.camera, *self.can, self.imu_csv, self.frames_csv, self.config, self.dbc]
        if self.mapping is not None and Path(self.mapping).is_file():
            named.append(Path(self.mapping))
        return [p for p in named if p is not None]

    @property
    def is_recording(self) -> bool:
        """The input is a roadpreview recording folder (it has true events)."""
        return self.input.is_dir() and _is_recording(self.input)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in fields(self):
            if f.name == "where":
                continue
            v = getattr(self, f.name)
            if isinstance(v, Path):
                v = str(v)
            elif isinstance(v, tuple):
                v = [str(x) for x in v]
            out[f.name] = v
        return out


FIELDS = tuple(f.name for f in fields(DriveSpec) if f.name != "where")


def safe_id(name: str) -> str:
    """A drive id usable as a folder name: letters, digits, ``._-``; others -> ``_``."""
    out = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._")
    return out or "drive"


# -- a folder -----------------------------------------------------------------------------
def _is_recording(folder: Path) -> bool:
    from roadpreview.sources.recording import REQUIRED

    return all((folder / n).is_file() for n in REQUIRED)


def _stem(path: Path) -> str:
    return path.name[: -len(path.suffix)] if path.suffix else path.name


def _camera_for(path: Path, default: Path | None) -> Path | None:
    own = path.parent / f"{_stem(path)}.camera.toml"
    if own.is_file():
        return own
    shared = path.parent / "camera.toml"
    return shared if shared.is_file() else default


def discover(folder: Path, *, camera: Path | None = None) -> list[DriveSpec]:
    """The drives in ``folder`` (module docstring), sorted by id; ``camera``: the
    calibration of videos and bags that have none of their own."""
    from roadpreview.sources.rosbag import is_bag

    folder = Path(folder)
    if not folder.is_dir():
        raise ConfigError(f"{folder}: not a folder of recordings or a manifest")
    specs: list[DriveSpec] = []
    for entry in sorted(folder.iterdir()):
        if entry.name.startswith("."):
            continue
        where = str(entry)
        if entry.is_dir():
            if _is_recording(entry):
                specs.append(DriveSpec(safe_id(entry.name), entry, where=where))
            elif is_bag(entry):
                specs.append(
                    DriveSpec(safe_id(entry.name), entry, _camera_for(entry, camera), where=where)
                )
            continue
        suffix = entry.suffix.lower()
        if suffix in BAG_SUFFIXES and is_bag(entry):
            specs.append(
                DriveSpec(safe_id(_stem(entry)), entry, _camera_for(entry, camera), where=where)
            )
        elif suffix in VIDEO_SUFFIXES:
            stem = _stem(entry)
            logs = tuple(p for s in CAN_SUFFIXES if (p := entry.parent / f"{stem}{s}").is_file())
            imu = entry.parent / f"{stem}.imu.csv"
            frames = entry.parent / f"{stem}.frames.csv"
            specs.append(
                DriveSpec(
                    safe_id(stem),
                    entry,
                    _camera_for(entry, camera),
                    can=logs,
                    imu_csv=imu if imu.is_file() else None,
                    frames_csv=frames if frames.is_file() else None,
                    where=where,
                )
            )
    if not specs:
        raise ConfigError(
            f"{folder}: no recording folder, video ({', '.join(VIDEO_SUFFIXES)}) or bag in it"
        )
    return _unique(specs, str(folder))


# -- a manifest ---------------------------------------------------------------------------
def read_manifest(path: Path, *, camera: Path | None = None) -> list[DriveSpec]:
    """The drives a CSV or TOML manifest lists (module docstring), in its order."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        rows = _csv_rows(path)
    elif path.suffix.lower() == ".toml":
        rows = _toml_rows(path)
    else:
        raise ConfigError(f"{path}: a manifest is a .csv or .toml file")
    if not rows:
        raise ConfigError(f"{path}: lists no drive")
    specs = [_spec(row, path, where, camera) for where, row in rows]
    return _unique(specs, str(path))


def load_drives(source: Path, *, camera: Path | None = None) -> list[DriveSpec]:
    """A folder (`discover`) or a manifest file (`read_manifest`)."""
    source = Path(source)
    if not source.exists():
        raise ConfigError(f"{source}: no such folder or manifest")
    if source.is_dir():
        return discover(source, camera=camera)
    return read_manifest(source, camera=camera)


def _csv_rows(path: Path) -> list[tuple[str, dict[str, Any]]]:
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            names = reader.fieldnames or []
            rows = [(f"{path}: row {i}", row) for i, row in enumerate(reader, start=2)]
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ConfigError(f"{path}: not a readable CSV manifest ({exc})") from None
    unknown = [n for n in names if n not in FIELDS]
    if unknown:
        raise ConfigError(f"{path}: unknown column(s) {unknown}; known: {', '.join(FIELDS)}")
    out = []
    for where, row in rows:
        clean = {k: v.strip() for k, v in row.items() if k is not None and v and v.strip()}
        if "can" in clean:
            clean["can"] = [c.strip() for c in clean["can"].split(";") if c.strip()]
        out.append((where, clean))
    return out


def _toml_rows(path: Path) -> list[tuple[str, dict[str, Any]]]:
    data = load_toml(path)
    extra = set(data) - {"defaults", "drive"}
    if extra:
        raise ConfigError(f"{path}: unknown table(s) {sorted(extra)}; use [defaults], [[drive]]")
    defaults = data.get("defaults", {})
    drives = data.get("drive", [])
    if not isinstance(defaults, dict) or not isinstance(drives, list):
        raise ConfigError(f"{path}: [defaults] must be a table and [[drive]] an array of tables")
    return [(f"{path}: [[drive]] {i}", {**defaults, **d}) for i, d in enumerate(drives, start=1)]


def _spec(row: dict[str, Any], manifest: Path, where: str, camera: Path | None) -> DriveSpec:
    unknown = [k for k in row if k not in FIELDS]
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; known: {', '.join(FIELDS)}")
    if "input" not in row:
        raise ConfigError(f"{where}: no input")
    base = manifest.parent
    kw: dict[str, Any] = {}
    for key, value in row.items():
        if key in _PATHS:
            kw[key] = _path(value, base, where, key)
        elif key == "can":
            logs = [value] if isinstance(value, str) else value
            kw[key] = tuple(_path(v, base, where, key) for v in logs)
        elif key in _FLOATS:
            try:
                kw[key] = float(value)
            except (TypeError, ValueError):
                raise ConfigError(f"{where}: {key} {value!r} is not a number (s)") from None
            if not math.isfinite(kw[key]):
                raise ConfigError(f"{where}: {key} must be finite")
        elif key == "mapping" and str(value).endswith(".toml"):  # a file, not a shipped name
            kw[key] = str(_path(value, base, where, key))
        else:
            kw[key] = str(value)
    if not kw["input"].exists():
        raise ConfigError(f"{where}: input {kw['input']} does not exist")
    drive = safe_id(str(kw.pop("drive", _stem(kw["input"]))))
    if "camera" not in kw and camera is not None:
        kw["camera"] = camera
    return DriveSpec(drive, where=where, **kw)


def _path(value: Any, base: Path, where: str, key: str) -> Path:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{where}: {key} must be a path")
    p = Path(value).expanduser()
    return p if p.is_absolute() else base / p


def _unique(specs: list[DriveSpec], source: str) -> list[DriveSpec]:
    seen: dict[str, str] = {}
    for s in specs:
        if s.drive in seen:
            raise ConfigError(
                f"{source}: drive id {s.drive!r} twice ({seen[s.drive]} and {s.where}); "
                "give each a distinct 'drive'"
            )
        seen[s.drive] = s.where
    return specs


__all__ = [
    "FIELDS",
    "DriveSpec",
    "discover",
    "load_drives",
    "read_manifest",
    "safe_id",
]
