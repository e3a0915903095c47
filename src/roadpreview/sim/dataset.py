"""A labelled data set like the paper's SVAR: clips around lead-vehicle anomaly crossings
plus about as many background clips, from many simulated drives.

Each positive clip is centred on the apex time (the lead's front axle over the
anomaly) with ``clip_half_s`` of context on either side; a background clip is
centred on a time at least ``clearance_s`` away from any crossing of the lead.
The ``hard`` flag is the paper's: the ego crosses another anomaly while the
lead crosses this one. Optionally (the evaluation) a background clip is hard
too when the ego crosses an anomaly inside a given window around its centre,
and a share of the background clips is centred on the ego's own crossings
(the ego pitching with no lead event: what compensation is for). Drives are
generated in parallel processes and are deterministic by seed; the index is
``dataset.json``.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from roadpreview.errors import OperationError
from roadpreview.sim.presets import preset
from roadpreview.sim.recording import write_recording
from roadpreview.sim.scenario import CameraSpec, ScenarioConfig

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Clip:
    """One labelled time window of one recording."""

    recording: str  #: folder name relative to the data set root
    t_center_s: float  #: the apex (positives) or a background instant
    t_start_s: float
    t_end_s: float
    label: int  #: 1 = the lead crosses an anomaly at t_center_s, 0 = background
    hard: bool = False
    event_index: int | None = None
    kind: str = ""
    height_m: float = math.nan
    lead_distance_m: float = math.nan
    lead_side: str = ""


def drive_config(
    preset_name: str,
    seed: int,
    *,
    duration_s: float | None = None,
    width: int | None = None,
    height: int | None = None,
    fps: float | None = None,
) -> ScenarioConfig:
    """The preset's scenario for ``seed`` with optional overrides (duration, resolution, fps)."""
    cfg = preset(preset_name, seed)
    if duration_s is not None:
        cfg = replace(
            cfg,
            motion=replace(cfg.motion, duration_s=duration_s),
            conditions=[c for c in cfg.conditions if c.start_s < duration_s],
        )
    if width is not None or height is not None or fps is not None:
        cam = cfg.camera
        cfg = replace(
            cfg,
            camera=CameraSpec(
                width=width or cam.width,
                height=height or cam.height,
                vfov_deg=cam.vfov_deg,
                fps=fps or cam.fps,
                forward=cam.forward,
            ),
        )
    return cfg


def _write_one(args: tuple[ScenarioConfig, str]) -> tuple[str, int]:
    cfg, folder = args
    info = write_recording(cfg, folder)
    return folder, info.n_frames


def clips_of_recording(
    folder: Path,
    name: str,
    rng: np.random.Generator,
    *,
    clip_half_s: float = 5.0,
    clearance_s: float = 1.5,
    background_per_positive: float = 1.0,
    hard_window_s: tuple[float, float] | None = None,
    ego_crossing_share: float = 0.0,
    clear_of_hits_only: bool = False,
    background_spacing_s: float | None = None,
) -> list[Clip]:
    """Positive clips for each anomaly the lead crosses, and background clips.

    ``hard_window_s = (lo, hi)``: a background clip centred at t is ``hard`` when
    the ego's front axle crosses an anomaly it hits within [t + lo, t + hi] (by
    default background clips are never hard). ``ego_crossing_share``: that share
    of the background clips is centred on the ego's crossings (``kind`` =
    ``"ego-crossing"``) at least ``clearance_s`` from any crossing of the lead,
    the rest drawn at random as before (0: the random draw alone, unchanged).
    ``clear_of_hits_only``: background clips keep ``clearance_s`` only from the
    anomalies the lead hits (one it passes beside does not move it); by default
    from every anomaly the lead passes. ``background_spacing_s``: the least time
    between two background clips (default twice ``clearance_s``).
    """
    info = json.loads((folder / "truth.json").read_text())
    duration = float(info["duration_s"])
    lo, hi = clip_half_s, duration - clip_half_s
    clips: list[Clip] = []
    crossings = []
    for e in info["events"]:
        t = e.get("lead_front_t_s")
        if t is None:
            continue
        if e["lead_hits"] or not clear_of_hits_only:
            crossings.append(float(t))
        if e["lead_hits"] and lo <= t <= hi:
            clips.append(
                Clip(
                    recording=name,
                    t_center_s=t,
                    t_start_s=t - clip_half_s,
                    t_end_s=t + clip_half_s,
                    label=1,
                    hard=bool(e["hard"]),
                    event_index=int(e["index"]),
                    kind=e["kind"],
                    height_m=float(e["height_m"]),
                    lead_distance_m=float(e["lead_distance_m"] or math.nan),
                    lead_side=e["lead_side"],
                )
            )
    n_pos = sum(c.label for c in clips)
    n_bg = round(background_per_positive * max(n_pos, 1))
    spacing = 2.0 * clearance_s if background_spacing_s is None else background_spacing_s
    cross = np.asarray(crossings)
    ego_cross = np.asarray(
        [
            float(e["ego_front_t_s"])
            for e in info["events"]
            if e.get("ego_hits") and e.get("ego_front_t_s") is not None
        ]
    )
    chosen: list[float] = []
    from_ego: set[float] = set()
    n_ego = min(n_bg, round(ego_crossing_share * n_bg)) if ego_crossing_share > 0 else 0
    if n_ego:
        ego_ok = ego_cross[(ego_cross >= lo) & (ego_cross <= hi)]
        if cross.size and ego_ok.size:
            far = np.min(np.abs(ego_ok[:, None] - cross[None, :]), axis=1) >= clearance_s
            ego_ok = ego_ok[far]
        for t in rng.permutation(ego_ok):
            if all(abs(t - c) >= spacing for c in chosen):
                chosen.append(float(t))
                from_ego.add(float(t))
            if len(chosen) == n_ego:
                break
    candidates = rng.uniform(lo, hi, 50 * n_bg) if hi > lo else np.empty(0)
    if cross.size:
        far = np.min(np.abs(candidates[:, None] - cross[None, :]), axis=1) >= clearance_s
        candidates = candidates[far]
    if len(chosen) < n_bg:
        for t in candidates:  # a few dozen candidates; keep background clips apart
            if all(abs(t - c) >= spacing for c in chosen):
                chosen.append(float(t))
            if len(chosen) == n_bg:
                break

    def ego_crosses_near(t: float) -> bool:
        if hard_window_s is None or not ego_cross.size:
            return False
        return bool(
            np.any((ego_cross >= t + hard_window_s[0]) & (ego_cross <= t + hard_window_s[1]))
        )

    clips += [
        Clip(
            recording=name,
            t_center_s=t,
            t_start_s=t - clip_half_s,
            t_end_s=t + clip_half_s,
            label=0,
            hard=ego_crosses_near(t),
            kind="ego-crossing" if t in from_ego else "",
        )
        for t in sorted(chosen)
    ]
    return clips


def build_dataset(
    out: str | Path,
    *,
    preset_name: str = "wild",
    n_drives: int = 10,
    seed: int = 0,
    jobs: int = 2,
    duration_s: float | None = None,
    width: int | None = None,
    height: int | None = None,
    clip_half_s: float = 5.0,
    clearance_s: float = 1.5,
    progress: Callable[[int, int], None] | None = None,
) -> list[Clip]:
    """Generate ``n_drives`` drives of ``preset_name`` (seeds ``seed .. seed+n-1``) into
    ``out`` in parallel and write ``dataset.json``; existing complete drives are reused."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    todo: list[tuple[ScenarioConfig, str]] = []
    names = []
    for i in range(n_drives):
        name = f"drive_{seed + i:05d}"
        names.append(name)
        folder = out / name
        cfg = drive_config(preset_name, seed + i, duration_s=duration_s, width=width, height=height)
        if (folder / "truth.json").is_file() and _same_scenario(folder, cfg):
            continue
        todo.append((cfg, str(folder)))
    done = n_drives - len(todo)
    if progress:
        progress(done, n_drives)
    if todo and jobs <= 1:
        for item in todo:
            _write_one(item)
            done += 1
            if progress:
                progress(done, n_drives)
    elif todo:  # on the batch's engine: a local Dask cluster of `jobs` processes
        from roadpreview.batch.engine import TaskFailure, open_engine

        with open_engine(workers=jobs, dashboard=False) as engine:
            keys = [Path(folder).name for _, folder in todo]
            for item, result in engine.map(
                _write_one, todo, keys=keys, label="simulate", progress=False
            ):
                if isinstance(result, TaskFailure):
                    raise OperationError(f"{item[1]}: the simulation failed: {result.message}")
                done += 1
                if progress:
                    progress(done, n_drives)
    rng = np.random.default_rng([seed, 0xC11])
    clips: list[Clip] = []
    for name in names:
        clips += clips_of_recording(
            out / name, name, rng, clip_half_s=clip_half_s, clearance_s=clearance_s
        )
    index = {
        "preset": preset_name,
        "seed": seed,
        "n_drives": n_drives,
        "clip_half_s": clip_half_s,
        "clearance_s": clearance_s,
        "n_positive": sum(c.label for c in clips),
        "n_hard": sum(1 for c in clips if c.label and c.hard),
        "n_background": sum(1 for c in clips if not c.label),
        "clips": [_clip_json(c) for c in clips],
    }
    (out / "dataset.json").write_text(json.dumps(index, indent=1))
    return clips


def _clip_json(c: Clip) -> dict[str, Any]:
    d = asdict(c)
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def _same_scenario(folder: Path, cfg: ScenarioConfig) -> bool:
    try:
        return ScenarioConfig.load(folder / "scenario.toml") == cfg
    except Exception:  # a half-written or foreign folder is regenerated
        return False
