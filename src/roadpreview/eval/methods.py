"""The methods the evaluation compares: one table row each, a pitch estimator and a fusion
back end on top of the same vision front end and the same detector.

Adding a method is one line in `METHODS`; `method_config` derives its
`PipelineConfig` from the user's (or the default) configuration by replacing
only the strategy fields, so everything else (vision, detector, alerts) stays
identical across methods.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from numpy.typing import ArrayLike

from roadpreview.errors import ConfigError
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pitch.base import PitchEstimate, PitchEstimator


@dataclass(frozen=True)
class MethodSpec:
    """One compared method (a row of Table I)."""

    estimator: str  #: `roadpreview.pitch.ESTIMATORS` name
    backend: str  #: `roadpreview.fusion.BACKENDS` name
    label: str  #: name in tables and plots
    compensated: bool = True  #: False: y_c = y (the uncompensated baseline)
    #: estimator options; None: the base configuration's when its estimator is the same
    pitch_options: Mapping[str, Any] | None = None
    #: back-end options; None: the base configuration's when its back end is the same
    fusion_options: Mapping[str, Any] | None = None
    #: the camera heave term of the compensation (``[heave] enabled``): None keeps the base
    #: configuration's; the paper's methods run without it (eq. 4 only, no accelerometer)
    heave: bool | None = None
    #: std (rad) given to the estimator's successful results that carry none (NaN): the
    #: essential-matrix baseline reports no uncertainty and the visual-only chain refuses a
    #: NaN std, so without this the baseline would never compensate (see `NanStdFallback`)
    nan_std_rad: float | None = None
    color: str = field(default="C0", compare=False)  #: matplotlib colour of its curves


#: name -> method, in the order of the tables; the paper's rows first, ours last
METHODS: dict[str, MethodSpec] = {
    "uncompensated": MethodSpec(
        "none", "none", "uncompensated", compensated=False, heave=False, color="C7"
    ),
    "essential": MethodSpec(
        "essential",
        "visual-only",
        "essential matrix (RANSAC)",
        heave=False,
        nan_std_rad=math.radians(0.05),
        color="C1",
    ),
    "visual": MethodSpec(
        "robust", "visual-only", "ours visual (robust LM)", heave=False, color="C0"
    ),
    "imu-only": MethodSpec(
        "none", "imu-only", "IMU only (integrated gyro)", heave=False, color="C4"
    ),
    # the gyro alone with the bias and time offset the Kalman fusion estimates (new)
    "imu-estimated": MethodSpec(
        "robust",
        "imu-estimated",
        "IMU with the fusion's bias and offset",
        heave=False,
        color="C5",
    ),
    "fused-kalman": MethodSpec("robust", "kalman", "ours fused (Kalman)", color="C3"),
    "fused-fg": MethodSpec("robust", "factor-graph", "ours fused (factor graph)", color="C2"),
}

#: the method whose pipeline runs the vision front end (its pitch is the vision's horizon)
REFERENCE_METHOD = "fused-kalman"


def _options(
    own: Mapping[str, Any] | None, same_component: bool, base: Mapping[str, Any]
) -> dict[str, Any]:
    """A component's options for a method: its ``own`` when it has some, else the base
    configuration's when the base names the same component, else none."""
    if own is not None:
        return dict(own)
    if same_component:
        return dict(base)
    return {}


def method_config(base: PipelineConfig, spec: MethodSpec) -> PipelineConfig:
    """``base`` with the method's estimator and back end (and their options)."""
    pitch_options = _options(
        spec.pitch_options, spec.estimator == base.pitch.estimator, base.pitch.options
    )
    fusion_options = _options(
        spec.fusion_options, spec.backend == base.fusion.backend, base.fusion.options
    )
    cfg = replace(
        base,
        pitch=replace(base.pitch, estimator=spec.estimator, options=pitch_options),
        fusion=replace(base.fusion, backend=spec.backend, options=fusion_options),
    )
    heave = getattr(cfg, "heave", None)  # the heave term is newer than some configurations
    if spec.heave is not None and heave is not None and heave.enabled != spec.heave:
        cfg = replace(cfg, heave=replace(heave, enabled=spec.heave))
    return cfg


def select_methods(names: list[str] | None = None) -> dict[str, MethodSpec]:
    """The named methods (all of `METHODS` when None), in the table's order."""
    if names is None:
        return dict(METHODS)
    unknown = [n for n in names if n not in METHODS]
    if unknown:
        raise ConfigError(f"methods: unknown {unknown}; choose from {list(METHODS)}")
    return {n: METHODS[n] for n in METHODS if n in names}


class NanStdFallback:
    """A pitch estimator whose successful results get ``std`` when theirs is NaN.

    The evaluation's adapter for `MethodSpec.nan_std_rad` (given to the method's
    `Pipeline` as its ``pitch`` estimator); everything else passes through unchanged.
    """

    def __init__(self, inner: PitchEstimator, std: float) -> None:
        self.inner = inner
        self.std = std
        self.name = getattr(inner, "name", "")

    def reset(self) -> None:
        self.inner.reset()

    def estimate(self, x_ref: ArrayLike, x_cur: ArrayLike) -> PitchEstimate:
        est = self.inner.estimate(x_ref, x_cur)
        if est and not math.isfinite(est.std):
            est = replace(est, std=self.std)
        return est
