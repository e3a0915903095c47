"""What the evaluation simulates: data sets, sizes, seeds, resolutions and every analysis
parameter, for the full run and the ``--quick`` run used by the tests.

Every recording is a `RecordingJob` built from a preset with explicit seed,
duration and camera; the plan is written into the report, so a reader can
regenerate each drive with ``roadpreview simulate`` or `write_recording`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from roadpreview.errors import ConfigError
from roadpreview.eval.clips import SCORE_WINDOW_S
from roadpreview.eval.runner import RecordingJob
from roadpreview.sim.presets import (
    GENERALIZATION_DRIVES,
    controlled,
    generalization_drive,
    texture_loss,
    wild,
)
from roadpreview.sim.road import paper_speed_bump
from roadpreview.sim.scenario import ScenarioConfig

Size = tuple[int, int]

#: experiment ids, in report order
EXPERIMENTS = ("e1", "e2", "e3", "e4", "e5", "e6", "e7")

#: the ego's front axle at t = 0 and the lead's front axle ahead of it beyond the gap, m
#: (measured on the controlled preset: lead front = ego front + gap + 4.5 m)
_EGO_FRONT_M = 31.2
_LEAD_OFFSET_M = 4.5


@dataclass(frozen=True)
class EvalPlan:
    """Every parameter of one evaluation run (written into the report)."""

    name: str  #: "quick" or "full"
    #: base seed: wild drive i has seed + i, texture-loss seed + 1000 + i, generalization
    #: drive i (its place in the whole suite) seed + 2000 + i
    seed: int = 0
    # -- wild (Table I, E3, lead time) --
    wild_drives: int = 22
    wild_duration_s: float = 60.0
    wild_size: Size = (1280, 720)
    #: None: the preset's 30 anomalies/km; the quick run doubles it to get events in short drives
    wild_anomaly_density_per_km: float | None = None
    # -- texture loss (E5) --
    texture_drives: int = 3
    texture_duration_s: float = 60.0
    texture_size: Size = (1280, 720)
    # -- generalization (E4): drives whose parameters no detector is tuned on --
    #: names from `roadpreview.sim.presets.GENERALIZATION_DRIVES`; each drive fixes its own
    #: camera, duration and lead vehicle. Empty: no generalization data set
    generalization_drives: tuple[str, ...] = GENERALIZATION_DRIVES
    # -- controlled (E1, E2) --
    e1_gaps_m: tuple[float, ...] = (3, 5, 7, 10, 13, 16, 20, 25, 30, 35, 40)
    e1_size: Size = (1920, 1080)
    #: None: the preset's three bumps over ~31 s; else a shortened drive whose lead crosses
    #: a paper bump at each of these times (s)
    e1_short_crossings_s: tuple[float, ...] | None = None
    e1_short_duration_s: float = 9.0
    e2_gap_m: float = 10.0
    # -- detection range (E5) --
    range_sizes: tuple[Size, ...] = ((640, 360), (1280, 720), (1920, 1080))
    range_drives: int = 3  #: the first wild seeds, re-simulated at each size
    range_duration_s: float = 60.0
    distance_bins_m: tuple[float, ...] = (0, 10, 15, 20, 25, 30, 40)
    # -- clips and scores --
    score_window_s: tuple[float, float] = SCORE_WINDOW_S
    #: the clip window per detector, around the time its score describes (the windowed std:
    #: the frame, lagging the crossing by up to its 1 s window; the two-axle detector: the
    #: front axle's crossing it hypothesises, the same 1.4 s wide centred on it)
    score_windows: dict[str, tuple[float, float]] = field(
        default_factory=lambda: {"std": SCORE_WINDOW_S, "two-axle": (-0.7, 0.7)}
    )
    clip_half_s: float = 2.5  #: positives need this much recording on each side
    clearance_s: float = 2.0  #: background clips this far from any lead crossing
    background_spacing_s: float = 2.5  #: background clips at least this far apart
    ego_crossing_share: float = 0.5  #: share of background clips centred on ego crossings
    #: backgrounds keep the clearance from the anomalies the lead hits only (one it passes
    #: beside does not move it)
    clear_of_hits_only: bool = True
    # -- cross-validation --
    cv_k: int = 5
    cv_seed: int = 0
    #: the methods whose operating points (E6) sweep every detector's threshold grid, each
    #: threshold a run of the detector over every wild trace; None: every method
    operating_point_methods: tuple[str, ...] | None = None
    #: E6 sweeps every this many thresholds of each detector's grid (from its lowest)
    threshold_stride: int = 1
    # -- E7: the error budget's variants (`experiments.budget.variants` names; None: all) --
    budget_variants: tuple[str, ...] | None = None
    # -- E3 --
    e3_step_s: float = 0.5  #: background windows every this many seconds
    e3_bins: int = 6
    # -- E1 background: frames this far around any crossing (either car) are excluded, s --
    e1_exclude_s: tuple[float, float] = (-0.5, 2.5)
    e1_start_s: float = 1.5

    @classmethod
    def full(cls, seed: int = 0) -> EvalPlan:
        # E6's threshold sweeps (each threshold a detector run over every wild trace, 0.6-0.9
        # s a drive for the two-axle detector) for the product, the factor graph and the
        # paper's baselines: for all seven methods they would take about 20 min of CPU
        return cls(
            name="full",
            seed=seed,
            operating_point_methods=("fused-kalman", "fused-fg", "uncompensated", "essential"),
        )

    @classmethod
    def quick(cls, seed: int = 0) -> EvalPlan:
        return cls(
            name="quick",
            seed=seed,
            wild_drives=5,
            wild_duration_s=18.0,
            wild_size=(640, 360),
            wild_anomaly_density_per_km=60.0,
            texture_drives=1,
            texture_duration_s=14.0,
            texture_size=(640, 360),
            generalization_drives=(),
            e1_gaps_m=(5, 10, 20),
            e1_size=(640, 360),
            e1_short_crossings_s=(2.5, 5.0),
            e1_short_duration_s=7.5,
            range_sizes=((640, 360),),
            range_drives=5,
            range_duration_s=18.0,
            distance_bins_m=(0, 10, 20, 40),
            e3_bins=3,
            # the product and the paper's baseline (the sweep was 80 % of the quick run)
            operating_point_methods=("fused-kalman", "uncompensated"),
            threshold_stride=2,  # half the sweep (26 s of the 50 s of experiments)
            budget_variants=("product", "pitch only", "+ pitch + heave + distance + tracking"),
        )

    def validate(self) -> None:
        if self.wild_drives < self.cv_k:
            raise ConfigError(
                f"plan {self.name}: {self.wild_drives} wild drives < cv_k = {self.cv_k} "
                "(folds never split a recording)"
            )
        if self.threshold_stride < 1:
            raise ConfigError(f"plan {self.name}: threshold_stride {self.threshold_stride} < 1")
        if self.e2_gap_m not in self.e1_gaps_m:
            raise ConfigError(f"plan {self.name}: e2_gap_m {self.e2_gap_m} not in e1_gaps_m")
        unknown = [n for n in self.generalization_drives if n not in GENERALIZATION_DRIVES]
        if unknown:
            raise ConfigError(
                f"plan {self.name}: generalization_drives {unknown} unknown; choose from"
                f" {list(GENERALIZATION_DRIVES)}"
            )

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    # -- scenarios ------------------------------------------------------------------------------
    def wild_scenario(self, i: int, size: Size, duration_s: float) -> ScenarioConfig:
        cfg = wild(self.seed + i, duration_s=duration_s)
        if self.wild_anomaly_density_per_km is not None:
            road = replace(cfg.motion.road, anomaly_density_per_km=self.wild_anomaly_density_per_km)
            cfg = replace(cfg, motion=replace(cfg.motion, road=road))
        return _sized(cfg, size)

    def texture_scenario(self, i: int) -> ScenarioConfig:
        cfg = texture_loss(self.seed + 1000 + i, duration_s=self.texture_duration_s)
        return _sized(cfg, self.texture_size)

    def generalization_scenario(self, name: str) -> ScenarioConfig:
        """Suite drive ``name`` with seed + 2000 + its index in the whole suite (so a drive
        keeps its seed whichever drives a plan selects)."""
        seed = self.seed + 2000 + GENERALIZATION_DRIVES.index(name)
        return generalization_drive(name, seed)

    def controlled_scenario(self, gap_m: float) -> ScenarioConfig:
        cfg = controlled(self.seed, gap_m=float(gap_m))
        if self.e1_short_crossings_s is not None:
            v = cfg.motion.ego_speed_kmh / 3.6
            lead0 = _EGO_FRONT_M + gap_m + _LEAD_OFFSET_M
            # paper_speed_bump(x) has its apex 1 m after x
            bumps = [paper_speed_bump(lead0 + v * t - 1.0) for t in self.e1_short_crossings_s]
            road = replace(cfg.motion.road, anomalies=bumps)
            cfg = replace(
                cfg,
                motion=replace(cfg.motion, road=road, duration_s=self.e1_short_duration_s),
            )
        return _sized(cfg, self.e1_size)

    # -- jobs -----------------------------------------------------------------------------------
    def jobs(self, root: Path, experiments: tuple[str, ...]) -> dict[str, list[RecordingJob]]:
        """The recordings each data set needs for ``experiments`` (data set -> jobs)."""
        out: dict[str, list[RecordingJob]] = {}
        if {"e3", "e4", "e5", "e6", "e7"} & set(experiments):
            out["wild"] = [
                RecordingJob(
                    "wild",
                    f"drive_{self.seed + i:05d}",
                    self.wild_scenario(i, self.wild_size, self.wild_duration_s),
                    root,
                )
                for i in range(self.wild_drives)
            ]
        if "e5" in experiments:
            out["texture-loss"] = [
                RecordingJob(
                    "texture-loss",
                    f"drive_{self.seed + 1000 + i:05d}",
                    self.texture_scenario(i),
                    root,
                )
                for i in range(self.texture_drives)
            ]
            for size in self.range_sizes:
                if self._range_from_wild(size):
                    continue
                name = range_dataset(size)
                out[name] = [
                    RecordingJob(
                        name,
                        f"drive_{self.seed + i:05d}",
                        self.wild_scenario(i, size, self.range_duration_s),
                        root,
                    )
                    for i in range(self.range_drives)
                ]
        if {"e1", "e2"} & set(experiments):
            gaps = self.e1_gaps_m if "e1" in experiments else (self.e2_gap_m,)
            out["controlled"] = [
                RecordingJob("controlled", gap_name(g), self.controlled_scenario(g), root)
                for g in gaps
            ]
        if {"e6", "e7"} & set(experiments) and self.generalization_drives:
            out["generalization"] = [
                RecordingJob("generalization", name, self.generalization_scenario(name), root)
                for name in self.generalization_drives
            ]
        return out

    def _range_from_wild(self, size: Size) -> bool:
        """The wild set serves as this size's range set (same seeds, long enough)."""
        return (
            size == self.wild_size
            and self.range_drives <= self.wild_drives
            and self.range_duration_s == self.wild_duration_s
        )

    def range_jobs(self, jobs: dict[str, list[RecordingJob]], size: Size) -> list[RecordingJob]:
        if self._range_from_wild(size):
            return jobs["wild"][: self.range_drives]
        return jobs[range_dataset(size)]


def range_dataset(size: Size) -> str:
    return f"range-{size[0]}x{size[1]}"


def gap_name(gap_m: float) -> str:
    return f"gap_{float(gap_m):04.1f}m"


def _sized(cfg: ScenarioConfig, size: Size) -> ScenarioConfig:
    return replace(cfg, camera=replace(cfg.camera, width=size[0], height=size[1]))
