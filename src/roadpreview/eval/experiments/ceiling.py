"""The data set's ceiling: a detector on the *true* compensated trajectory (perfect
tracking, pitch and heave), what no method can beat; and s(t) of any series as the
windowed-std detector computes it."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from roadpreview.anomaly import TrajectorySample, WindowedStdDetector, make_detector
from roadpreview.anomaly.config import AnomalyConfig, DetectorConfig
from roadpreview.eval.clips import Scores
from roadpreview.eval.experiments.base import Array

#: the ceiling's camera heave: its height less its centred running mean over this span (the
#: road's hills and the ride height are not heave); the detrended s removes what is left
CEILING_HEAVE_SPAN_S = 3.0


def windowed_std(t: Array, y: Array, config: DetectorConfig | None = None) -> Array:
    """s(t) of the series ``y`` (paper eq. 1) exactly as the product's `WindowedStdDetector`
    with ``config`` computes it (its window ``window_s``, ``detrend`` and the minimum
    samples, valid share and span it needs before it gives an s); NaN values of ``y`` are
    frames without a lead. NaN where the detector has no s."""
    samples = [
        TrajectorySample(t=ti, y_c=yi, valid=math.isfinite(yi))
        for ti, yi in zip(
            np.asarray(t, dtype=np.float64).tolist(), np.asarray(y).tolist(), strict=True
        )
    ]
    return WindowedStdDetector(config).run(samples).s


def true_compensated_y(truth: Mapping[str, Array], f_px: float) -> tuple[Array, Array, Array]:
    """Frame times, the *true* compensated row y_c (px) and the true lead distance (m): the
    rendered row of the lead's rear centre (``lead_rear_px``) less the camera's true pitch,
    f tan(phi), and heave, f dz / d (dz: the camera height less its centred
    `CEILING_HEAVE_SPAN_S` mean)."""
    t = np.asarray(truth["frame_t_s"], dtype=np.float64)
    y = np.asarray(truth["lead_rear_px"], dtype=np.float64)[:, 1]
    z = np.asarray(truth["cam_z_m"], dtype=np.float64)
    d = np.asarray(truth["lead_distance_m"], dtype=np.float64)
    k = max(1, round(CEILING_HEAVE_SPAN_S / float(np.median(np.diff(t)))) | 1)
    mean = np.convolve(np.pad(z, (k // 2, k // 2), mode="edge"), np.ones(k) / k, mode="valid")
    with np.errstate(invalid="ignore", divide="ignore"):
        yc = y - f_px * np.tan(np.asarray(truth["cam_pitch_rad"])) - f_px * (z - mean) / d
    return t, yc, d


def ceiling_s(
    truth: Mapping[str, Array], f_px: float, config: DetectorConfig | None = None
) -> Array:
    """s(t) of the true compensated trajectory (`true_compensated_y`) by the windowed-std
    detector with ``config``: the std ceiling per frame."""
    t, yc, _ = true_compensated_y(truth, f_px)
    return windowed_std(t, yc, config)


def true_trajectory(truth: Mapping[str, Array], f_px: float) -> list[TrajectorySample]:
    """The *true* compensated trajectory as detector input: the rendered row of the lead's
    rear centre less the camera's true pitch and heave (`true_compensated_y`), with the true
    distance and ego speed; no halves (the truth has none)."""
    t, yc, d = true_compensated_y(truth, f_px)
    v = np.asarray(truth["ego_speed_m_s"], dtype=np.float64)
    return [
        TrajectorySample(
            t=float(t[i]),
            y_c=float(yc[i]),
            lead_distance_m=float(d[i]),
            ego_speed_mps=float(v[i]),
            valid=bool(np.isfinite(yc[i])),
            focal_px=f_px,
        )
        for i in range(t.size)
    ]


def ceiling_scores(
    truth: Mapping[str, Array], f_px: float, anomaly: AnomalyConfig, detector: str
) -> Scores:
    """``detector`` (with ``anomaly``'s settings) over the true compensated trajectory: the
    windowed std by `ceiling_s`, any other through `true_trajectory`."""
    if detector == "std":
        return Scores(
            np.asarray(truth["frame_t_s"], dtype=np.float64), ceiling_s(truth, f_px, anomaly.std)
        )
    det = make_detector(replace(anomaly, detector=detector), f_px)
    ts, ss = [], []
    for sample in true_trajectory(truth, f_px):  # a streaming detector: one push a frame
        det.push(sample)
        fr = det.frame
        ts.append(fr.t_score if fr else math.nan)
        ss.append(fr.score if fr else math.nan)
    return Scores(np.asarray(ts, dtype=np.float64), np.asarray(ss, dtype=np.float64))
