"""Road-anomaly detection: the two-axle CFAR detector (the product's), the paper's windowed
std (the baseline), events and alerts."""

from __future__ import annotations

import importlib
from dataclasses import replace

from roadpreview.anomaly.alert import AlertBatch, AlertBuilder
from roadpreview.anomaly.base import (
    AnomalyEvent,
    Detector,
    DetectorFrame,
    EventKind,
    TrajectorySample,
)
from roadpreview.anomaly.config import (
    DETECTORS,
    AlertConfig,
    AnomalyConfig,
    DetectorConfig,
    SignalModel,
    TwoAxleConfig,
    noise_threshold_px,
)
from roadpreview.anomaly.nms import PeakPicker
from roadpreview.anomaly.running import WindowedMoments
from roadpreview.anomaly.windowed_std import DetectorRun, WindowedStdDetector, classify_side
from roadpreview.errors import ConfigError
from roadpreview.types import Alert, Side, SuppressionReason


def make_detector(config: AnomalyConfig, focal_px: float | None = None) -> Detector:
    """The detector ``config.detector`` names (`DETECTORS`), built from its table; the
    windowed std's signal model gets ``focal_px`` unless its table sets one."""
    try:
        module, cls_name, field_name = DETECTORS[config.detector]
    except KeyError:
        raise ConfigError(
            f"anomaly.detector = {config.detector!r}: unknown; choose one of {sorted(DETECTORS)}"
        ) from None
    table = getattr(config, field_name)
    if isinstance(table, DetectorConfig) and table.signal.focal_px is None and focal_px:
        table = replace(table, signal=replace(table.signal, focal_px=float(focal_px)))
    cls = getattr(importlib.import_module(module), cls_name)
    detector: Detector = cls(table)
    return detector


__all__ = [
    "DETECTORS",
    "Alert",
    "AlertBatch",
    "AlertBuilder",
    "AlertConfig",
    "AnomalyConfig",
    "AnomalyEvent",
    "Detector",
    "DetectorConfig",
    "DetectorFrame",
    "DetectorRun",
    "EventKind",
    "PeakPicker",
    "Side",
    "SignalModel",
    "SuppressionReason",
    "TrajectorySample",
    "TwoAxleConfig",
    "WindowedMoments",
    "WindowedStdDetector",
    "classify_side",
    "make_detector",
    "noise_threshold_px",
]
