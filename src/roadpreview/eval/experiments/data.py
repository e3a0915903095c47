"""`EvalData`: the processed recordings of one run (traces, truth, clips and detector runs),
loaded once and shared by every experiment."""

from __future__ import annotations

import json
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from roadpreview.anomaly import DETECTORS
from roadpreview.anomaly.config import AnomalyConfig
from roadpreview.eval.clips import ClipTable, Scores, draw_clips, score_table
from roadpreview.eval.detectors import DetectorTrace, at_threshold, run_detector
from roadpreview.eval.experiments.base import Array
from roadpreview.eval.methods import METHODS, MethodSpec
from roadpreview.eval.plan import EvalPlan
from roadpreview.eval.runner import MethodSet, RecordingJob, Trace, load_traces

#: truth arrays the experiments read
TRUTH_KEYS = (
    "frame_t_s",
    "cam_pitch_rad",
    "cam_pitch_rate_rad_s",
    "lead_distance_m",
    "lead_box_px",
    "lead_rear_px",
    "cam_z_m",
    "ego_speed_m_s",
)


@dataclass
class EvalData:
    """Processed recordings: traces, truth and clips, loaded once (and cached here)."""

    plan: EvalPlan
    methods: MethodSet
    jobs: dict[str, list[RecordingJob]]
    _traces: dict[str, dict[str, Trace]] = field(default_factory=dict)
    _truth: dict[str, dict[str, Array]] = field(default_factory=dict)
    _info: dict[str, dict[str, Any]] = field(default_factory=dict)
    _tables: dict[str, ClipTable] = field(default_factory=dict)
    _runs: dict[tuple[str, str, str], DetectorTrace] = field(default_factory=dict)

    @property
    def method_names(self) -> list[str]:
        return list(self.methods.configs)

    def spec(self, method: str) -> MethodSpec:
        return METHODS[method]

    @property
    def reference_anomaly(self) -> AnomalyConfig:
        """The detector settings of the reference method (the product's)."""
        return self.methods.configs[self.methods.reference].anomaly

    @property
    def detector_window_s(self) -> float:
        """The windowed-std detector's window T (``[anomaly.std] window_s``), s: how far
        back from a frame its s sees."""
        return self.reference_anomaly.std.window_s

    def traces(self, job: RecordingJob) -> dict[str, Trace]:
        if job.key not in self._traces:
            self._traces[job.key] = load_traces(job, self.methods)
        return self._traces[job.key]

    def truth(self, job: RecordingJob) -> dict[str, Array]:
        if job.key not in self._truth:
            with np.load(job.folder / "truth.npz") as npz:
                self._truth[job.key] = {k: np.asarray(npz[k]) for k in TRUTH_KEYS}
        return self._truth[job.key]

    @property
    def detectors(self) -> list[str]:
        """Every detector of the registry, the paper's first."""
        return ["std", *(d for d in DETECTORS if d != "std")]

    @property
    def product_detector(self) -> str:
        """The detector the product runs (the reference method's configuration)."""
        return self.reference_anomaly.detector

    def detection(
        self, job: RecordingJob, method: str, detector: str | None = None
    ) -> DetectorTrace:
        """``detector`` (default: the product's) over ``method``'s trace of ``job``."""
        name = detector or self.product_detector
        key = (job.key, method, name)
        if key not in self._runs:
            anomaly = self.methods.configs[method].anomaly
            self._runs[key] = run_detector(self.traces(job)[method], anomaly, name)
        return self._runs[key]

    def detection_at(
        self, job: RecordingJob, method: str, detector: str, threshold: float
    ) -> DetectorTrace:
        """``detector`` on ``method``'s trace of ``job`` with its threshold set to
        ``threshold`` (`at_threshold`): an operating point."""
        key = (job.key, method, f"{detector}@{threshold:g}")
        if key not in self._runs:
            anomaly = at_threshold(self.methods.configs[method].anomaly, detector, threshold)
            self._runs[key] = run_detector(self.traces(job)[method], anomaly, detector)
        return self._runs[key]

    def detection_with(
        self, job: RecordingJob, method: str, tag: str, anomaly: AnomalyConfig
    ) -> DetectorTrace:
        """The product's detector on ``method``'s trace of ``job`` with ``anomaly`` (a
        variant of its settings, cached under ``tag``)."""
        key = (job.key, method, tag)
        if key not in self._runs:
            self._runs[key] = run_detector(self.traces(job)[method], anomaly)
        return self._runs[key]

    def scores(self, job: RecordingJob, detector: str = "std") -> dict[str, Scores]:
        """Every method's per-frame score of ``detector`` on ``job`` (the paper's
        experiments use the windowed std, its s at the frame's time)."""
        out = {}
        for m in self.method_names:
            run = self.detection(job, m, detector)
            out[m] = Scores(run.t_score, run.score)
        return out

    def score_window(self, detector: str) -> tuple[float, float]:
        """The clip window of ``detector``'s scores (relative to the clip centre)."""
        return self.plan.score_windows.get(detector, self.plan.score_window_s)

    def info(self, job: RecordingJob) -> dict[str, Any]:
        """The recording's ``truth.json`` (events, conditions, duration)."""
        if job.key not in self._info:
            self._info[job.key] = json.loads((job.folder / "truth.json").read_text())
        return self._info[job.key]

    def focal_px(self, job: RecordingJob) -> float:
        return float(job.scenario.camera_model().fy)

    def clip_table(
        self,
        dataset: str,
        jobs: Sequence[RecordingJob] | None = None,
        detector: str = "std",
    ) -> ClipTable:
        """Clips of a data set (or of the given jobs) with every method's score of
        ``detector`` (the paper's windowed std by default)."""
        jobs = list(jobs if jobs is not None else self.jobs[dataset])
        key = dataset + "|" + detector + "|" + ",".join(j.key for j in jobs)
        if key not in self._tables:
            plan = self.plan
            clips = {
                j.key: draw_clips(
                    j.folder,
                    j.key,
                    (plan.seed, i, zlib.crc32(dataset.encode())),
                    window=plan.score_window_s,
                    clip_half_s=plan.clip_half_s,
                    clearance_s=plan.clearance_s,
                    ego_crossing_share=plan.ego_crossing_share,
                    clear_of_hits_only=plan.clear_of_hits_only,
                    background_spacing_s=plan.background_spacing_s,
                    detector_window_s=self.detector_window_s,
                )
                for i, j in enumerate(jobs)
            }
            self._tables[key] = score_table(
                clips,
                {j.key: self.scores(j, detector) for j in jobs},
                {j.key: self.truth(j) for j in jobs},
                self.score_window(detector),
                boxes_by_recording={j.key: self.traces(j)[self.methods.reference] for j in jobs},
                tracked_window=plan.score_window_s,
                detector_window_s=self.detector_window_s,
            )
        return self._tables[key]
