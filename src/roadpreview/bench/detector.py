"""``roadpreview bench detector``: milliseconds per frame of each anomaly detector.

A synthetic trajectory (seeded): a lead 15 m ahead at 10 m/s whose rear face bounces on a
rough road (a 1.3 Hz body driven by white noise, 8 mm RMS) with 0.15 px of tracking noise
per half, a bump every 8 s, the compensation channel moving too; 30 and 60 fps. Every
detector of the registry (`roadpreview.anomaly.DETECTORS`) with its default settings runs
over the same samples; the median wall time over repeats per frame is reported, with the
events found (a check that the run did the work). Target: the product's detector costs
<= 0.2 ms per frame.

Issue 27's additions, on the same samples in the same run: the two-axle detector without
its provisional stage (``provisional = false``), and the road-profile preview
(`roadpreview.preview.ProfileEstimator`, a solve every 0.2 s); what the issue added per
frame is the provisional stage's difference plus the preview (target <= 0.3 ms).
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import partial

import numpy as np
from scipy import signal

from roadpreview.anomaly import DETECTORS, AnomalyConfig, TrajectorySample, make_detector
from roadpreview.anomaly.response import NominalVehicle, TemplateBank
from roadpreview.bench._timing import format_table, median_seconds
from roadpreview.preview import ProfileEstimator

TARGET_MS = 0.2
#: issue 27's budget for the provisional stage and the preview together, ms per frame
ADDED_TARGET_MS = 0.3


def synthetic_trajectory(duration_s: float, fps: float, seed: int) -> list[TrajectorySample]:
    """The module docstring's trajectory."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / fps)
    wn, zeta = 2 * math.pi * 1.3, 0.3
    # a resonant body: a second-order filter of white noise
    b, a = signal.bilinear([wn * wn], [1.0, 2 * zeta * wn, wn * wn], fs=fps)
    z = signal.lfilter(b, a, rng.standard_normal(t.size))
    z *= 0.008 / z.std()
    veh = NominalVehicle()
    bank = TemplateBank.build(veh, (0.15,))
    for t0 in np.arange(5.0, duration_s - 3.0, 8.0):
        z += 0.05 * bank.two_axle(t - t0, veh.wheelbase_m / 10.0, veh.rho)[0]
    f, d = 1000.0, 15.0
    y = 400.0 - f * z / d
    comp = 3.0 * np.sin(2 * math.pi * 0.7 * t)
    yl = y + rng.normal(0, 0.15, t.size)
    yr = y + rng.normal(0, 0.15, t.size)
    return [
        TrajectorySample(
            t=float(t[i]),
            y_c=float(0.5 * (yl[i] + yr[i])),
            y_c_left=float(yl[i]),
            y_c_right=float(yr[i]),
            lead_distance_m=d,
            lead_distance_std_m=0.5,
            ego_speed_mps=10.0,
            focal_px=f,
            compensation_px=float(comp[i]),
        )
        for i in range(t.size)
    ]


def _run_once(name: str, samples: list[TrajectorySample], *, provisional: bool = True) -> int:
    cfg = AnomalyConfig(detector=name)
    if not provisional:
        cfg = replace(cfg, two_axle=replace(cfg.two_axle, provisional=False))
    det = make_detector(cfg, 1000.0)
    events = 0
    for s in samples:
        events += len(det.push(s))
    return events + len(det.flush())


def _preview_once(samples: list[TrajectorySample]) -> int:
    est = ProfileEstimator(principal_row_px=400.0)
    return sum(est.push(s) is not None for s in samples)


def run(repeats: int | None = None, quick: bool = False, seed: int = 0) -> str:
    reps = repeats or (2 if quick else 7)
    duration = 30.0 if quick else 120.0
    rows = []
    for fps in (30.0, 60.0):
        samples = synthetic_trajectory(duration, fps, seed)
        for name in DETECTORS:
            sec = median_seconds(partial(_run_once, name, samples), reps)
            ms = 1000.0 * sec / len(samples)
            target = f"<= {TARGET_MS} ms" if name == AnomalyConfig().detector else ""
            rows.append(
                [
                    name,
                    f"{fps:.0f}",
                    f"{ms:.3f}",
                    f"{len(samples) / sec:,.0f}",
                    str(_run_once(name, samples)),
                    target,
                ]
            )
            if name == "two-axle":
                base = median_seconds(partial(_run_once, name, samples, provisional=False), reps)
                prev = median_seconds(partial(_preview_once, samples), reps)
                added = 1000.0 * (sec - base + prev) / len(samples)
                rows.append(
                    [
                        "two-axle without provisional",
                        f"{fps:.0f}",
                        f"{1000.0 * base / len(samples):.3f}",
                        f"{len(samples) / base:,.0f}",
                        str(_run_once(name, samples, provisional=False)),
                        "",
                    ]
                )
                rows.append(
                    [
                        "preview (RP_PREVIEW)",
                        f"{fps:.0f}",
                        f"{1000.0 * prev / len(samples):.3f}",
                        f"{len(samples) / prev:,.0f}",
                        f"{_preview_once(samples)} previews",
                        "",
                    ]
                )
                rows.append(
                    [
                        "issue 27 added (provisional + preview)",
                        f"{fps:.0f}",
                        f"{added:.3f}",
                        "",
                        "",
                        f"<= {ADDED_TARGET_MS} ms",
                    ]
                )
    head = ["detector", "fps", "ms / frame", "frames / s", "events", "target"]
    title = f"bench detector: {duration:.0f} s synthetic trajectory, 14-15 bumps, median of {reps}"
    return title + "\n" + format_table(head, rows)
