"""roadpreview: predict road-surface anomalies by watching the vehicle ahead bounce.

Camera + IMU in, predictive-suspension alerts on CAN out. An implementation and
extension of Jahoda & Čech, "Predicting Road Surface Anomalies by Visual
Tracking of a Preceding Vehicle" (IEEE IV 2025).
"""

from roadpreview.errors import (
    ConfigError,
    InputDataError,
    MissingDependencyError,
    OperationError,
    RoadPreviewError,
)

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "InputDataError",
    "MissingDependencyError",
    "OperationError",
    "RoadPreviewError",
    "__version__",
]
