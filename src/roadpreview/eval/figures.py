"""The evaluation's figures: one function per experiment, drawing its result (the frozen
dataclasses of `roadpreview.eval.experiments`) into a PNG and returning the file's name.

Plotting only: every number comes from the result. matplotlib is imported on use, through
its object-oriented interface (a `Figure` written to a file: no pyplot state, no GUI
back end).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roadpreview.eval.experiments import (
    DetectionRange,
    EgoBump,
    FprVsRotation,
    LeadTime,
    SignalVsDistance,
    Table1,
    TextureLoss,
)
from roadpreview.eval.experiments.detection_range import RANGE_MAX_FPR
from roadpreview.eval.methods import METHODS, MethodSpec

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: methods whose range curves are drawn (E5 range), with their marker
RANGE_METHODS = {"fused-kalman": "o", "uncompensated": "x"}


def _figure(figsize: tuple[float, float], *, constrained: bool = False) -> Figure:
    """A new figure, not registered with pyplot (nothing to close)."""
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained" if constrained else None)


def _save(fig: Figure, path: Path) -> str:
    """Write ``fig`` to ``path`` (folders created), return the file's name."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return path.name


def _spec(method: str) -> MethodSpec:
    return METHODS[method]


def plot_signal_vs_distance(res: SignalVsDistance, path: Path) -> str:
    """E1: s at the crossings vs distance per method, the background's p99 and the fit."""
    methods = list(res.methods)
    cols = 3
    rows = math.ceil(len(methods) / cols)
    fig = _figure((4.2 * cols, 3.4 * rows), constrained=True)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, m in zip(axes.ravel(), methods, strict=False):
        r = res.methods[m]
        d = np.asarray(r.d, dtype=np.float64)
        s = np.asarray(r.s, dtype=np.float64)
        ax.plot(d, s, "o", color=_spec(m).color, label="crossings")
        known = [row for row in r.per_gap if math.isfinite(row.distance_m)]
        ax.plot(
            [row.distance_m for row in known],
            [row.background_p99 for row in known],
            "k--",
            lw=1,
            label="background p99",
        )
        if math.isfinite(r.alpha) and d.size:
            dd = np.linspace(max(d.min() * 0.8, 1.0), d.max() * 1.1, 100)
            r2 = r.r2 if math.isfinite(r.r2) else 0.0
            ax.plot(
                dd,
                r.alpha * res.focal_px * res.delta_m / dd + r.beta,
                "-",
                color="0.3",
                lw=1,
                label=f"α={r.alpha:.2f} β={r.beta:.2f} R²={r2:.2f}",
            )
        ax.set_title(_spec(m).label, fontsize=9)
        ax.set_xlabel("lead distance (m)")
        ax.set_ylabel("s (px)")
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(methods) :]:
        ax.axis("off")
    fig.suptitle("E1: s at the lead's bump crossings vs distance (controlled)")
    return _save(fig, path)


def plot_ego_bump(res: EgoBump, path: Path) -> str:
    """E2: the compensated methods' pitch against the truth, every method's y_c."""
    te = res.ego_crossing_s
    fig = _figure((8, 6.5))
    a1, a2 = fig.subplots(2, 1, sharex=True)
    a1.plot(res.truth_t - te, np.degrees(res.truth_phi_rad), "k-", lw=2.2, label="truth")
    for m, c in res.curves.items():
        spec = _spec(m)
        if spec.compensated:
            a1.plot(c.t - te, np.degrees(c.phi_rad), color=spec.color, lw=1.2, label=spec.label)
        a2.plot(c.t - te, c.y_c_px, color=spec.color, lw=1.2, label=spec.label)
    a1.axvline(0, color="0.6", lw=0.8)
    a2.axvline(0, color="0.6", lw=0.8)
    a1.set_ylabel("camera pitch (deg)")
    a1.legend(fontsize=7, ncol=2)
    a2.set_ylabel("y_c - mean of first s (px)")
    a2.set_xlabel("time from the ego's front axle over the bump (s)")
    a2.legend(fontsize=7, ncol=2)
    fig.suptitle(f"E2: the ego crosses a 6 cm bump (controlled, gap {res.gap_m:g} m)")
    return _save(fig, path)


def plot_fpr_vs_rotation(res: FprVsRotation, path: Path) -> str:
    """E3: FPR per rotation bin, at each method's threshold and at the common one."""
    fig = _figure((11, 4.4), constrained=True)
    axes = fig.subplots(1, 2, sharey=True)
    panels = (
        ("fpr", "each method's F-max threshold"),
        ("fpr_at_default", f"common threshold {res.default_threshold_px:g} px"),
    )
    for ax, (key, title) in zip(axes, panels, strict=True):
        for m, r in res.methods.items():
            spec = _spec(m)
            values = r.fpr if key == "fpr" else r.fpr_at_default
            pts = [
                (c, v)
                for c, v in zip(res.bin_centers_deg_s, values, strict=True)
                if math.isfinite(c) and math.isfinite(v)
            ]
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                marker="o",
                color=spec.color,
                label=spec.label,
                ls="--" if not spec.compensated else "-",
            )
        ax.set_xlabel("ego rotation: mean |true pitch rate| in the window (deg/s)")
        ax.set_title(title, fontsize=9)
        ax.set_ylim(-0.02, 1.02)
    axes[0].set_ylabel("false-positive rate")
    axes[0].legend(fontsize=7)
    fig.suptitle("E3: FPR of background windows vs ego rotation (wild set)")
    return _save(fig, path)


def plot_roc(res: Table1, path: Path) -> str:
    """E4 (Fig. 7): ROC curves of the windowed std's clip scores, entire and hard subsets."""
    fig = _figure((10, 4.6))
    axes = fig.subplots(1, 2)
    for ax, name in zip(axes, ("entire", "hard"), strict=True):
        for m, row in res.methods.items():
            roc = row.roc.get(name)
            if roc is None:
                continue
            spec = _spec(m)
            a = row.subsets[name].auc
            ax.plot(roc.fpr, roc.tpr, color=spec.color, label=f"{spec.label} ({a:.2f})")
        ax.plot([0, 1], [0, 1], ":", color="0.6")
        ax.set_title(f"{name} subset")
        ax.set_xlabel("false-positive rate")
        ax.set_ylabel("true-positive rate")
        ax.legend(fontsize=7, loc="lower right")
    fig.suptitle("E4: ROC of the clip score max s(t) (wild set)")
    return _save(fig, path)


def plot_texture_loss(res: TextureLoss, path: Path) -> str:
    """E5: the compensated methods' pitch error inside the low-texture segments."""
    fig = _figure((7, 3.8))
    ax = fig.subplots()
    names = [m for m in res.methods if _spec(m).compensated]
    vals = [res.methods[m].pitch_rms_hp_inside_deg for m in names]
    vals = [v if math.isfinite(v) else 0.0 for v in vals]
    ax.bar(range(len(names)), vals, color=[_spec(m).color for m in names])
    ax.set_xticks(range(len(names)), [_spec(m).label for m in names], rotation=20, fontsize=7)
    ax.set_ylabel("pitch error, high-passed by the detector window, RMS (deg)")
    ax.set_title("E5: pitch error inside fog / tunnel / night (texture-loss set)")
    return _save(fig, path)


def plot_range(res: DetectionRange, path: Path) -> str:
    """E5: recall vs distance per resolution for `RANGE_METHODS`."""
    fig = _figure((7, 4.2))
    ax = fig.subplots()
    styles = ["-", "--", ":", "-."]
    edges = np.asarray(res.bins_m, dtype=np.float64)
    mid = 0.5 * (edges[:-1] + edges[1:])
    for k, (size, r) in enumerate(res.sizes.items()):
        for m, marker in RANGE_METHODS.items():
            row = r.methods.get(m)
            if row is None:
                continue
            spec = _spec(m)
            ax.plot(
                mid,
                np.asarray(row.recall, dtype=np.float64),
                linestyle=styles[k % len(styles)],
                marker=marker,
                color=spec.color,
                label=f"{spec.label}, {size}",
            )
    ax.axhline(0.5, color="0.6", lw=0.8)
    ax.set_xlabel("lead distance at the crossing (m)")
    ax.set_ylabel(f"recall at FPR <= {RANGE_MAX_FPR:.0%}")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=7)
    ax.set_title("E5: detection range per resolution (wild drives)")
    return _save(fig, path)


def plot_lead_time(res: LeadTime, path: Path) -> str:
    """E5: histogram of the alerts' lead times per method."""
    fig = _figure((7, 3.8))
    ax = fig.subplots()
    shown = [m for m, r in res.methods.items() if r.lead_times_s]
    if shown:
        ax.hist(
            [list(res.methods[m].lead_times_s) for m in shown],
            bins=12,
            color=[_spec(m).color for m in shown],
            label=[_spec(m).label for m in shown],
        )
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel("lead time: ego reaches the anomaly minus alert emitted (s)")
    ax.set_ylabel("alerts")
    ax.legend(fontsize=7)
    ax.set_title("E5: alert lead time (wild set, default detector)")
    return _save(fig, path)


def plot_reliability(calibration: Mapping[str, Any], path: Path) -> str:
    """E6: reliability diagram of the alerts' confidence (`product.calibration`'s result)."""
    fig = _figure((4.8, 4.4))
    ax = fig.subplots()
    for name, style in (("wild_cross_fitted", "o-"), ("generalization_shipped", "s--")):
        r = calibration.get(name)
        if not r or not r["bins"]:
            continue
        conf = [b["confidence"] for b in r["bins"]]
        freq = [b["frequency"] for b in r["bins"]]
        ece = r["ece"]
        ax.plot(conf, freq, style, label=f"{name.replace('_', ' ')} (ECE {ece:.2f}, n={r['n']})")
    ax.plot([0, 1], [0, 1], ":", color="0.5")
    ax.set_xlabel("alert confidence")
    ax.set_ylabel("share of alerts that were real")
    ax.set_title("E6: confidence reliability")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    return _save(fig, path)
