"""Pitch fusion: visual pitch + IMU gyro; back ends chosen by name, modes and fallback.

Back ends are chosen by name from `BACKENDS` (imported lazily)::

    fusion = make_fusion("kalman", gyro={"noise_density": 3e-4})
    fusion.push_gyro(t_imu, pitch_rate)
    fusion.push_visual(VisualPitch(t_key, t_frame, dphi, std, inlier_ratio, quality_ok))
    out = fusion.estimate(t_frame)          # FusedPitch: phi, std, mode, bias, time offset
"""

from __future__ import annotations

from roadpreview.fusion.base import (
    FusedPitch,
    PitchBackEnd,
    PitchFusion,
    RewindableBackEnd,
    VisualPitch,
)
from roadpreview.registry import build
from roadpreview.types import FusionMode

#: config name -> (module, class or factory taking the config, config class)
BACKENDS: dict[str, tuple[str, str, str | None]] = {
    "kalman": ("roadpreview.fusion.kalman", "kalman_fusion", "KalmanConfig"),
    "factor-graph": ("roadpreview.fusion.factor_graph", "factor_graph_fusion", "FactorGraphConfig"),
    "visual-only": ("roadpreview.fusion.baselines", "VisualOnlyPitch", "VisualOnlyConfig"),
    "imu-only": ("roadpreview.fusion.baselines", "ImuOnlyPitch", "ImuOnlyConfig"),
    "imu-estimated": (
        "roadpreview.fusion.gyro_estimated",
        "GyroWithEstimates",
        "KalmanConfig",
    ),
    "none": ("roadpreview.fusion.baselines", "ZeroPitchFusion", None),
}


def make_fusion(name: str, **options: object) -> PitchFusion:
    """Build the back end registered as ``name``; ``options`` fill its config dataclass
    (nested tables as dicts: ``gyro={"noise_density": ...}``)."""
    fusion: PitchFusion = build(
        BACKENDS,
        name,
        key="fusion.backend",
        where="fusion",
        options=options,
        config_module="roadpreview.fusion.config",
    )
    return fusion


__all__ = [
    "BACKENDS",
    "FusedPitch",
    "FusionMode",
    "PitchBackEnd",
    "PitchFusion",
    "RewindableBackEnd",
    "VisualPitch",
    "make_fusion",
]
