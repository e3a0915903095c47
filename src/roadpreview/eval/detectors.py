"""Every detector over a method's stored trajectory: scores, events, alerts and confirmations.

The traces hold what each method's pipeline gave its detector per frame (the
`TrajectorySample` stream, `roadpreview.eval.runner`); here a detector of the
registry (`roadpreview.anomaly.DETECTORS`) runs over it exactly as inside
`Pipeline.push_vision`: restarted where the tracker changed target, events
turned into alerts by the `AlertBuilder`, alerts checked by the `EgoConfirmer`.
So detectors are compared on identical inputs, and a detector's settings can
change without recomputing a single vision pass.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from roadpreview.anomaly import DETECTORS, AlertBuilder, AnomalyConfig, make_detector
from roadpreview.anomaly.base import AnomalyEvent
from roadpreview.anomaly.confirm import EgoConfirmer
from roadpreview.anomaly.roughness import RoadRoughness
from roadpreview.eval.runner import Trace
from roadpreview.types import Alert, ConfirmationResult

Array = NDArray[np.float64]

#: the threshold field of each detector's table (the knob the operating points turn)
THRESHOLD_FIELDS: dict[str, str] = {"two-axle": "threshold_z", "std": "threshold_px"}


def at_threshold(anomaly: AnomalyConfig, detector: str, threshold: float) -> AnomalyConfig:
    """``anomaly`` with ``detector``'s threshold (its `THRESHOLD_FIELDS` entry) set to
    ``threshold``: an operating point."""
    field_name = DETECTORS[detector][2]
    table = replace(getattr(anomaly, field_name), **{THRESHOLD_FIELDS[detector]: threshold})
    return replace(anomaly, **{field_name: table})


@dataclass(frozen=True)
class DetectorTrace:
    """One detector's output over one trace (recording clock)."""

    detector: str
    t: Array  #: frame times, s
    score: Array  #: the detector's statistic per frame (NaN: undefined)
    t_score: Array  #: the time each score describes, s
    threshold: Array  #: the threshold on the score per frame
    s: Array  #: the windowed std per frame (the std detector; NaN otherwise), px
    height_m: Array  #: the fitted road input per frame (two-axle; NaN otherwise), m
    events: list[AnomalyEvent] = field(default_factory=list)  #: suppressed ones included
    alerts: list[Alert] = field(default_factory=list)  #: CONFIRMED alerts
    provisional: list[Alert] = field(default_factory=list)  #: PROVISIONAL alerts raised
    cancelled: list[Alert] = field(default_factory=list)  #: provisional alerts cancelled
    confirmations: list[ConfirmationResult] = field(default_factory=list)
    #: the road's ISO 8608 class estimate at the end of the run (None: unknown)
    road_class: str | None = None
    seconds: float = math.nan  #: CPU time of the run, s


def run_detector(
    trace: Trace, anomaly: AnomalyConfig, detector: str | None = None
) -> DetectorTrace:
    """``detector`` (default: ``anomaly.detector``) over ``trace``'s trajectory."""
    cfg = anomaly if detector is None else replace(anomaly, detector=detector)
    name = cfg.detector
    focal = trace.focal_px if math.isfinite(trace.focal_px) else None
    det = make_detector(cfg, focal)
    signal = cfg.std.signal
    if signal.focal_px is None and focal is not None:
        signal = replace(signal, focal_px=focal)
    builder = AlertBuilder(cfg.alert, signal=signal)
    confirmer = EgoConfirmer(cfg.confirm)
    roughness = RoadRoughness(cfg.roughness, cfg.two_axle.vehicle)
    samples = trace.samples()
    changed = trace["target_changed"]
    n = len(samples)
    cols = np.full((6, n), np.nan)
    events: list[AnomalyEvent] = []
    alerts: list[Alert] = []
    provisional: list[Alert] = []
    cancelled: list[Alert] = []
    confirmations: list[ConfirmationResult] = []
    c0 = time.process_time()
    for i, sample in enumerate(samples):
        new = det.restart() if changed[i] else []
        new += det.push(sample)
        f = det.frame
        if f is not None:
            cols[:, i] = (f.score, f.t_score, f.threshold, f.s, f.height_m, 0.0)
        events += new
        batch = builder.take(new)
        alerts += batch.confirmed
        provisional += batch.provisional
        cancelled += batch.cancelled
        for a in batch.confirmed:
            confirmer.add(a.alert_id, a.t_s, a.distance_m, a.side)
        confirmations += confirmer.push(sample.t, sample.ego_speed_mps, sample.ego_accel_peak_mps2)
        roughness.push(
            sample.t,
            ego_speed_mps=sample.ego_speed_mps,
            ego_accel_rms_mps2=sample.ego_accel_rms_mps2,
            ego_accel_samples=1,
            lead_y_c_px=sample.y_c,
            lead_distance_m=sample.lead_distance_m,
            focal_px=sample.focal_px,
            lead_valid=sample.valid,
        )
    tail = det.flush()
    events += tail
    batch = builder.take(tail)
    alerts += batch.confirmed
    provisional += batch.provisional
    cancelled += batch.cancelled
    return DetectorTrace(
        detector=name,
        t=trace.t,
        score=cols[0],
        t_score=cols[1],
        threshold=cols[2],
        s=cols[3],
        height_m=cols[4],
        events=events,
        alerts=alerts,
        provisional=provisional,
        cancelled=cancelled,
        confirmations=confirmations,
        road_class=roughness.state.iso_class,
        seconds=time.process_time() - c0,
    )


__all__ = ["DetectorTrace", "run_detector"]
