"""Road-anomaly detection: windowed std of the compensated lead trajectory, NMS, alerts."""

from roadpreview.anomaly.alert import Alert, AlertBuilder
from roadpreview.anomaly.base import (
    AnomalyEvent,
    Detector,
    DetectorFrame,
    Side,
    SuppressionReason,
    TrajectorySample,
)
from roadpreview.anomaly.config import (
    AlertConfig,
    AnomalyConfig,
    DetectorConfig,
    SignalModel,
    noise_threshold_px,
)
from roadpreview.anomaly.nms import PeakPicker
from roadpreview.anomaly.running import WindowedMoments
from roadpreview.anomaly.windowed_std import DetectorRun, WindowedStdDetector, classify_side

__all__ = [
    "Alert",
    "AlertBuilder",
    "AlertConfig",
    "AnomalyConfig",
    "AnomalyEvent",
    "Detector",
    "DetectorConfig",
    "DetectorFrame",
    "DetectorRun",
    "PeakPicker",
    "Side",
    "SignalModel",
    "SuppressionReason",
    "TrajectorySample",
    "WindowedMoments",
    "WindowedStdDetector",
    "classify_side",
    "noise_threshold_px",
]
