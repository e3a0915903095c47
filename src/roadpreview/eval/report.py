"""The evaluation report: the experiments' results with their figures (`run_experiments`,
the numbers of `roadpreview.eval.experiments` drawn by `roadpreview.eval.figures`), then
Markdown tables from ``results.json`` and the console summary (Table I and the headline
figures).

The report is regenerated whole by ``roadpreview evaluate --report PATH``; its
figures are copied next to it into ``eval/`` and linked relatively.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import shutil
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roadpreview.anomaly import DETECTORS
from roadpreview.eval import experiments as ex
from roadpreview.eval import figures
from roadpreview.eval.detectors import THRESHOLD_FIELDS
from roadpreview.eval.plan import EXPERIMENTS
from roadpreview.eval.product import e6_product

if TYPE_CHECKING:
    from roadpreview.eval.suite import EvalResults

#: subsets of Table I, in column order
TABLE1_SUBSETS = ("entire", "hard", "easy")
TRACKED_SUBSETS = ("tracked", "tracked-hard", "tracked-easy")
#: fewer hard positives than this: the hard subset is flagged as too small to be meaningful
MIN_HARD_POSITIVES = 15
#: detectors of the registry (`roadpreview.anomaly.DETECTORS`) as the report names them
DETECTOR_LABELS = {
    "std": "windowed std (the paper's eq. 1)",
    "two-axle": "two-axle matched filter against the road's background (CFAR)",
}


def _num(v: Any, fmt: str = ".2f") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, fmt)


def _pm(mean: Any, std: Any) -> str:
    if mean is None:
        return "–"
    return f"{mean:.2f} ± {std:.2f}" if std is not None else f"{mean:.2f}"


def _compact(x: Any) -> str:
    """A settings mapping on one line (JSON without spaces)."""
    return json.dumps(x, separators=(",", ":"), default=str)


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


#: Table I's last row: the true compensated trajectory (`experiments.ceiling_scores`)
CEILING_LABEL = "truth-compensated y (ceiling, not a method)"


def _label(d: Mapping[str, Any], m: str) -> str:
    if m == "ceiling":
        return CEILING_LABEL
    return str(d["methods"][m]["label"])


# -- the experiments and their figures ----------------------------------------------------------
def run_experiments(
    data: ex.EvalData,
    fig_dir: Path,
    experiments: Sequence[str] = EXPERIMENTS,
    *,
    default_threshold_px: float = 1.0,
) -> dict[str, Any]:
    """Each experiment of ``experiments`` on ``data``, its figure drawn into ``fig_dir``:
    ``results.json``'s ``results`` (the result's ``as_dict()`` with its figure's file
    name). ``default_threshold_px``: E3's common threshold (the configured one)."""
    res: dict[str, Any] = {}

    def with_figure(numbers: dict[str, Any], name: str) -> dict[str, Any]:
        return {**numbers, "figure": name}

    if "e4" in experiments:
        t1 = ex.table1(data)
        res["e4"] = with_figure(t1.as_dict(), figures.plot_roc(t1, fig_dir / "e4_roc.png"))
    thresholds = ex.thresholds_of(data) if {"e3", "e5"} & set(experiments) else {}
    if "e1" in experiments:
        e1 = ex.signal_vs_distance(data)
        path = fig_dir / "e1_signal_vs_distance.png"
        res["e1"] = with_figure(e1.as_dict(), figures.plot_signal_vs_distance(e1, path))
    if "e2" in experiments:
        e2 = ex.ego_bump(data)
        res["e2"] = with_figure(
            e2.as_dict(), figures.plot_ego_bump(e2, fig_dir / "e2_ego_bump.png")
        )
    if "e3" in experiments:
        e3 = ex.fpr_vs_rotation(data, thresholds, default_threshold_px)
        path = fig_dir / "e3_fpr_vs_rotation.png"
        res["e3"] = with_figure(e3.as_dict(), figures.plot_fpr_vs_rotation(e3, path))
    if "e5" in experiments:
        tl = ex.texture_loss(data, thresholds)
        rng = ex.detection_range(data)
        lt = ex.lead_time(data)
        res["e5"] = {
            "texture_loss": with_figure(
                tl.as_dict(), figures.plot_texture_loss(tl, fig_dir / "e5_texture_loss.png")
            ),
            "range": with_figure(rng.as_dict(), figures.plot_range(rng, fig_dir / "e5_range.png")),
            "lead_time": with_figure(
                lt.as_dict(), figures.plot_lead_time(lt, fig_dir / "e5_lead_time.png")
            ),
        }
    if "e6" in experiments:
        e6 = e6_product(data)
        if "calibration" in e6:
            e6["reliability_figure"] = figures.plot_reliability(
                e6["calibration"], fig_dir / "e6_reliability.png"
            )
        res["e6"] = e6
    return res


# -- Table I ------------------------------------------------------------------------------------
def _table1_cells(r: Mapping[str, Any], subsets: Sequence[str]) -> list[str]:
    """BA, F and AUC of each subset of one Table I row (``{"subsets": {...}}``)."""
    row: list[str] = []
    for sub in subsets:
        s = (r.get("subsets") or {}).get(sub)
        if s is None:
            row += ["–", "–", "–"]
            continue
        row += [_pm(s["ba_mean"], s["ba_std"]), _pm(s["f_mean"], s["f_std"]), _num(s["auc"])]
    return row


def table1_rows(d: Mapping[str, Any], subsets: Sequence[str] = TABLE1_SUBSETS) -> list[list[str]]:
    e4 = d["results"]["e4"]["methods"]
    rows = [[_label(d, m), *_table1_cells(r, subsets)] for m, r in e4.items()]
    ceiling = d["results"]["e4"].get("ceiling")
    if ceiling is not None:
        rows.append([CEILING_LABEL, *_table1_cells(ceiling, subsets)])
    return rows


def _table1_head(
    methods: Mapping[str, Any], subsets: Sequence[str], first: str = "method"
) -> list[str]:
    anym: Mapping[str, Any] = next(iter(methods.values()), {})
    head = [first]
    for sub in subsets:
        s = (anym.get("subsets") or {}).get(sub, {})
        n = f" ({s.get('n_pos', 0)}+/{s.get('n_neg', 0)}−)"
        head += [f"{sub} BA{n}", f"{sub} F", f"{sub} AUC"]
    return head


def table1_header(d: Mapping[str, Any], subsets: Sequence[str] = TABLE1_SUBSETS) -> list[str]:
    return _table1_head(d["results"]["e4"]["methods"], subsets)


def table1_text(d: Mapping[str, Any], subsets: Sequence[str] = TABLE1_SUBSETS) -> str:
    """Table I as aligned plain text (console)."""
    head = table1_header(d, subsets)
    rows = table1_rows(d, subsets)
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    out = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True))]
    out += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(out)


def headline(d: Mapping[str, Any]) -> str:
    """The headline figures in a few lines (console)."""
    res = d["results"]
    lines = []
    if "e4" in res:
        c = res["e4"]["counts"]
        lines.append(
            f"wild set: {c['positives']} positives ({c['hard_positives']} hard), "
            f"{c['backgrounds']} backgrounds ({c['hard_backgrounds']} hard), "
            f"{c['recordings']} recordings"
        )
        fk = res["e4"]["methods"].get("fused-kalman")
        if fk:
            lines.append(
                f"fused-kalman: F-max threshold {_num(fk['threshold_f_max_px'])} px on the whole "
                f"set (folds {', '.join(_num(v) for v in fk['fold_thresholds_px'])}); "
                "default 1.0 px"
            )
        for det, r in (res["e4"].get("detectors") or {}).items():
            fk = (r.get("methods") or {}).get("fused-kalman")
            if fk:
                sub = fk.get("subsets") or {}
                lines.append(
                    f"{det} detector, fused-kalman AUC: entire "
                    f"{_num((sub.get('entire') or {}).get('auc'))}, hard "
                    f"{_num((sub.get('hard') or {}).get('auc'))}"
                )
    if "e1" in res:
        for m in ("uncompensated", "fused-kalman"):
            r = res["e1"]["methods"].get(m)
            if r:
                lines.append(
                    f"E1 {m}: s(d) = {_num(r['alpha'])}·fδ/d + {_num(r['beta'])} "
                    f"(R² {_num(r['r2'])}), separates up to "
                    f"{_num(r['separation_distance_m'], '.1f')} m"
                )
    if "e5" in res:
        tl = res["e5"]["texture_loss"]["methods"]
        parts = [
            f"{m} {_num(tl[m]['pitch_rms_hp_inside_deg'], '.3f')}"
            for m in ("visual", "fused-kalman", "fused-fg")
            if m in tl
        ]
        lines.append("E5 pitch error in low texture (deg, 1 s high-pass RMS): " + ", ".join(parts))
        for size, r in res["e5"]["range"]["sizes"].items():
            fk = r["methods"].get("fused-kalman")
            if fk:
                more = "+" if fk["range_open"] else ""
                lines.append(
                    f"E5 range {size} (fused-kalman): {_num(fk['range_m'], '.0f')}{more} m"
                )
    lines.append(f"wall time {d['timing']['wall_s']:.0f} s")
    return "\n".join(lines)


# -- the Markdown report ------------------------------------------------------------------------
def write_report(results: EvalResults, path: str | Path, *, command: str = "") -> Path:
    """Write the Markdown report to ``path``; figures go to ``<path's folder>/eval/``."""
    path = Path(path)
    fig_dir = path.parent / "eval"
    fig_dir.mkdir(parents=True, exist_ok=True)
    for png in sorted(results.figures_dir.glob("*.png")):
        shutil.copy2(png, fig_dir / png.name)
    d = results.data
    text = render(d, fig_prefix="eval/", command=command)
    path.write_text(text)
    return path


def render(d: Mapping[str, Any], *, fig_prefix: str = "eval/", command: str = "") -> str:
    plan = d["plan"]
    res = d["results"]
    quick = plan["name"] == "quick"
    t = d["timing"]
    out: list[str] = []
    w = out.append
    w("# Evaluation report")
    w("")
    if quick:
        sizes = ", ".join(f"{w_}x{h_}" for w_, h_ in plan["range_sizes"])
        w(
            "> **QUICK CONFIGURATION.** These numbers come from the `--quick` run (a few short "
            f"drives at {plan['wild_size'][0]}x{plan['wild_size'][1]}, "
            f"{len(plan['e1_gaps_m'])} gaps, the detection range at {sizes} only): a smoke "
            "test of the whole evaluation that the test suite runs, not a measurement. The "
            "full configuration is regenerated with the first command below."
        )
        w("")
    w(
        "The same simulated recordings are run through every method; only the pitch estimator "
        "and the fusion back end differ (one vision pass per recording is shared by all "
        "methods, `roadpreview.eval.runner`). Generated by `roadpreview evaluate` "
        f"(roadpreview {d['version']}"
        + (f", commit {d['git_commit']}" if d.get("git_commit") else "")
        + (f", pipeline source {d['pipeline_source']}" if d.get("pipeline_source") else "")
        + f", Python {d['python']}) on "
        f"{_dt.date.today().isoformat()} in {t['wall_s'] / 60:.1f} min wall time with "
        f"{t['workers']} worker process(es)."
    )
    w("")
    w("## How to regenerate")
    w("")
    w("```sh")
    w("roadpreview evaluate --out runs/eval --report docs/evaluation.md        # full, < 1 h")
    w("roadpreview evaluate --quick --out runs/eval-quick --report docs/evaluation.md  # quick")
    w("```")
    if command:
        w("")
        w(f"This report: `{command}`.")
    w("")
    w(
        "Recordings and per-method traces are cached in the output folder (`data/`, "
        "`traces/`); a trace is recomputed when the method's configuration, the package "
        "version or the pipeline's source changes, a recording when its scenario or the "
        "simulator's source changes. All numbers are in `results.json` there."
    )
    w("")
    _methods_section(d, w)
    _data_section(d, w)
    if "e4" in res:
        _e4_section(d, w, fig_prefix)
    if "e1" in res:
        _e1_section(d, w, fig_prefix)
    if "e2" in res:
        _e2_section(d, w, fig_prefix)
    if "e3" in res:
        _e3_section(d, w, fig_prefix)
    if "e5" in res:
        _e5_section(d, w, fig_prefix)
    if "e6" in res:
        _e6_section(d, w, fig_prefix)
    _timing_section(d, w)
    return "\n".join(out) + "\n"


def _methods_section(d: Mapping[str, Any], w: Any) -> None:
    w("## Methods")
    w("")
    rows = []
    for m, r in d["methods"].items():
        opts = []
        if r["pitch"].get("options"):
            opts.append(f"pitch options {r['pitch']['options']}")
        if r["fusion"].get("options"):
            opts.append(f"fusion options {r['fusion']['options']}")
        if r["nan_std_rad"] is not None:
            opts.append(
                f"estimates without a std get {math.degrees(r['nan_std_rad']):.2f}° (see notes)"
            )
        heave = r.get("heave")
        rows.append(
            [
                f"`{m}`",
                r["label"],
                f"`{r['estimator']}`",
                f"`{r['backend']}`",
                "–" if heave is None else ("on" if heave else "off"),
                "; ".join(opts),
            ]
        )
    w(
        _md_table(
            ["name", "label", "pitch estimator", "fusion back end", "heave term", "notes"], rows
        )
    )
    w("")
    w(
        "Heave term: `[heave] enabled`, the camera's heave from the accelerometer subtracted "
        "as f Δz / d (docs/method.md). The paper's methods (and the IMU-only pitch) run "
        "without it, as eq. (4); ours fused use the product default."
    )
    w("")
    w(
        "Everything else is the default `PipelineConfig` (or the `--config` file): vision "
        "(motion finder), detector and alerts. The reference method `fused-kalman` runs the "
        "vision front end; its fused pitch is the vision's horizon for every method. "
        "Detector (`[anomaly.std]`):"
    )
    w("")
    det = d["detector"]
    flat = {k: v for k, v in det.items() if not isinstance(v, dict)}
    w(", ".join(f"`{k}` = {v}" for k, v in flat.items()))
    w("")
    w(
        "<details><summary>Every setting of each method's estimator and back end, and of the "
        "shared vision front end</summary>"
    )
    w("")
    for m, r in d["methods"].items():
        w(f"`{m}` pitch estimator `{r['estimator']}`: `{_compact(r.get('pitch_settings', {}))}`")
        w("")
        w(f"`{m}` fusion back end `{r['backend']}`: `{_compact(r.get('fusion_settings', {}))}`")
        w("")
    w(f"vision: `{_compact(d.get('vision', {}))}`")
    w("")
    if d.get("heave_settings") is not None:
        w(f"heave (when on): `{_compact(d['heave_settings'])}`")
        w("")
    w(f"alerts: `{_compact(d.get('alert', {}))}`")
    w("")
    w("</details>")
    w("")
    w(
        "Note on `essential`: `EssentialMatrixPitchEstimator` reports no standard deviation "
        "(NaN) and the `visual-only` chain refuses a measurement with a non-finite std, so in "
        "the product `--estimator essential` never compensates (it equals `uncompensated`). "
        "The evaluation wraps the estimator (`NanStdFallback`) to give its successful fits the "
        "std in the table; the std only affects `phi_std`, not the chained pitch."
    )
    w("")


def _data_section(d: Mapping[str, Any], w: Any) -> None:
    plan = d["plan"]
    w("## Data sets")
    w("")
    rows = []
    for name, ds in d["datasets"].items():
        seeds = ds["seeds"]
        seed_txt = f"{seeds[0]}–{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
        durs = sorted(set(ds["duration_s"]))
        rows.append(
            [
                name,
                str(len(ds["recordings"])),
                seed_txt,
                ", ".join(f"{v:g}" for v in durs) + " s",
                f"{ds['size'][0]}x{ds['size'][1]}" if ds["size"] else "–",
                str(ds["frames"]),
            ]
        )
    w(_md_table(["set", "recordings", "seeds", "duration", "resolution", "frames"], rows))
    w("")
    dens = plan["wild_anomaly_density_per_km"]
    w(
        "* `wild`: preset `wild` (rough ISO B-D road, random anomalies, speed 20-60 km/h, gap "
        "5-35 m, lead manoeuvres, oncoming traffic, smartphone-grade IMU with a 0-80 ms clock "
        f"offset), {plan['wild_duration_s']:g} s per drive"
        + (f", anomaly density raised to {dens:g}/km (preset: 30/km)" if dens else "")
        + f", seeds {plan['seed']} + i."
    )
    w(
        f"* `texture-loss`: preset `texture-loss` (a `wild` drive with fog, a tunnel and night, "
        f"each about a sixth of the drive), seeds {plan['seed']} + 1000 + i."
    )
    if plan["e1_short_crossings_s"]:
        w(
            "* `controlled`: preset `controlled` (smooth ISO A road, 20 km/h, fixed gap) shortened "
            f"to {plan['e1_short_duration_s']:g} s with paper bumps (6 cm, 2 m, 7°) placed so "
            f"that the lead crosses them at {plan['e1_short_crossings_s']} s; gaps "
            f"{', '.join(f'{g:g}' for g in plan['e1_gaps_m'])} m, seed {plan['seed']}."
        )
    else:
        w(
            "* `controlled`: preset `controlled` (three paper bumps, 6 cm, 2 m, 7°, smooth ISO A "
            f"road, 20 km/h), gaps {', '.join(f'{g:g}' for g in plan['e1_gaps_m'])} m, seed "
            f"{plan['seed']}."
        )
    w(
        "* `range-WxH`: the first wild seeds re-simulated at another resolution (the wild set "
        "itself serves its own resolution)."
    )
    w("")
    a, b = plan["score_window_s"]
    w("**Clips.** ")
    w(
        f"Positive clips are centred on the lead's front axle over an anomaly it hits; their "
        f"score is the maximum of s(t) over [t_c {a:+g} s, t_c {b:+g} s] (s is the std of y_c "
        "over the last second, so it rises from the crossing and stays up for about one second "
        "plus the lead's response). Background clips use the same window; they are at least "
        f"{plan['clearance_s']:g} s from any anomaly the lead hits"
        + (" (anomalies it passes beside do not count)" if plan["clear_of_hits_only"] else "")
        + f" and {plan['background_spacing_s']:g} s apart; "
        f"{plan['ego_crossing_share']:.0%} of them are centred on the ego's own crossings "
        "of an anomaly (drawn first), the rest at random. "
        f"Positives need {plan['clip_half_s']:g} s of recording on each side. A clip without "
        "any s in its window (no lead) scores 0. **Hard**: positives whose ego crosses another "
        "anomaly within 0.5 s of the lead's crossing (the simulator's truth `hard`, the "
        f"paper's definition), and backgrounds whose ego crosses an anomaly in [t {a - 1:+g} s, "
        f"t {b:+g} s] (the frames the score depends on). **Easy**: the rest. **Tracked**: "
        "clips where the lead's box overlaps the true box with IoU >= 0.5 in at least 80 % of "
        "those frames (the vision is shared, so the same clips for every method)."
    )
    w("")


def _e4_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e4 = d["results"]["e4"]
    plan = d["plan"]
    c = e4["counts"]
    w("## E4: the paper's Table I (wild set)")
    w("")
    w(
        f"{c['positives']} positive and {c['backgrounds']} background clips from "
        f"{c['recordings']} recordings at {e4['size'][0]}x{e4['size'][1]}; hard subset: "
        f"{c['hard_positives']} positives and {c['hard_backgrounds']} backgrounds "
        f"({c['ego_crossing_backgrounds']} backgrounds centred on ego crossings); "
        f"{c['tracked']} clips tracked; in {c['ego_same_anomaly_in_window']} positives the "
        "ego itself crosses the same anomaly inside the score window (short gap, high speed), "
        "which adds the ego's pitching to the uncompensated score of a true event. "
        "Balanced accuracy (BA) and F-score at the F-maximising "
        f"threshold chosen on the training folds of a {plan['cv_k']}-fold cross-validation "
        f"(folds grouped by recording, stratified, seed {plan['cv_seed']}), mean ± std over the "
        "folds; AUC of the subset's clips (no threshold)."
    )
    w("")
    if c["hard_positives"] < MIN_HARD_POSITIVES:
        w(
            f"**The hard subset has only {c['hard_positives']} positives (< {MIN_HARD_POSITIVES}): "
            "its numbers are too noisy to rank the methods.**"
        )
        w("")
    w(_md_table(table1_header(d), table1_rows(d)))
    w("")
    w("The same, on the tracked clips only (threshold still chosen on all training clips):")
    w("")
    w(_md_table(table1_header(d, TRACKED_SUBSETS), table1_rows(d, TRACKED_SUBSETS)))
    w("")
    if "ceiling" in e4:
        w(
            "The last row is no method: it scores the *true* compensated trajectory (the "
            "rendered row of the lead's rear centre less the camera's true pitch, f tan φ, and "
            "heave, f Δz / d; `experiments.ceiling_scores`) with the same detector window, clip "
            "windows and folds. It is what perfect tracking, pitch and heave would reach on "
            "this data set: the share of it a method attains is the method's; the rest is the "
            "data set (anomalies the lead's suspension swallows, a rough road's own bouncing)."
        )
        w("")
    bs = e4.get("by_signal")
    if bs is not None:
        w(
            f"**AUC by signal strength.** Positives binned by their expected signal f |δ| / d "
            f"(f = {bs['focal_px']:.0f} px, δ the anomaly's height, d the true lead distance at "
            f"the crossing), each bin against all {bs['n_neg']} backgrounds:"
        )
        w("")
        w(_by_signal_table(d, bs))
        w("")
    w(f"![ROC curves]({fp}{e4['figure']})")
    w("")
    w("**Threshold.** ")
    rows = []
    for m, r in e4["methods"].items():
        rows.append(
            [
                _label(d, m),
                _num(r["threshold_f_max_px"]),
                ", ".join(_num(v) for v in r["fold_thresholds_px"]),
                f"{_num(r['at_f_max']['tpr'])} / {_num(r['at_f_max']['fpr'])}",
                f"{_num(r['at_1px']['tpr'])} / {_num(r['at_1px']['fpr'])}",
                str(r["no_lead_clips"]),
            ]
        )
    w(
        _md_table(
            [
                "method",
                "F-max threshold, all clips (px)",
                "fold thresholds (px)",
                "TPR / FPR there",
                "TPR / FPR at 1.0 px (product default)",
                "clips without lead",
            ],
            rows,
        )
    )
    w("")
    fk = e4["methods"].get("fused-kalman")
    if fk and fk["threshold_f_max_px"] is not None:
        thr = fk["threshold_f_max_px"]
        w(
            f"For `fused-kalman` the F-maximising threshold on the whole set is {thr:.2f} px at "
            f"{e4['size'][0]}x{e4['size'][1]} against the product default "
            "`anomaly.std.threshold_px` = 1.0 px. Signals and the pitch residual scale with "
            "the focal length, so a pixel threshold holds for one resolution only. The F-score "
            "weighs misses and false alarms equally on a set with as many backgrounds as "
            "positives; a product that must keep false alarms rare (about one per minute, "
            "docs/pipeline.md) needs a higher threshold than the F-maximising one. "
            "The default is unchanged."
        )
        w("")
    if e4.get("detectors"):
        _e4_detectors(d, w)


def _by_signal_table(d: Mapping[str, Any], bs: Mapping[str, Any]) -> str:
    """AUC per bin of expected signal (`experiments.table1.auc_by_signal`), one column a method."""
    bins = bs.get("bins") or []
    names = list(bins[0]["auc"]) if bins else []
    head = ["f abs(δ) / d (px)", "positives", *[_label(d, m) for m in names]]
    rows = []
    for b in bins:
        hi = "∞" if b["hi_px"] is None else f"{b['hi_px']:g}"
        rows.append(
            [f"[{b['lo_px']:g}, {hi})", str(b["n_pos"])] + [_num(b["auc"].get(m)) for m in names]
        )
    return _md_table(head, rows)


def _detector_label(det: str) -> str:
    return DETECTOR_LABELS.get(det, det)


def _e4_detectors(d: Mapping[str, Any], w: Any) -> None:
    """Table I of every detector of the registry on the same clips, side by side."""
    e4 = d["results"]["e4"]
    others: Mapping[str, Any] = e4["detectors"]
    dets = {"std": e4, **others}
    product = (d.get("anomaly") or {}).get("detector")
    w("### Every detector side by side")
    w("")
    w(
        "Table I again with every detector of the registry scoring the same clips: a clip's "
        "score is the largest of the detector's own statistic over its score window (the "
        "windowed std s in px; the two-axle detector's z, the fitted road input over the "
        "road's background std), cross-validated with the same folds, each detector's "
        "threshold chosen on its own training folds. The ceiling rows run each detector on "
        "the true compensated trajectory. Detectors: "
        + "; ".join(f"`{det}` = {_detector_label(det)}" for det in dets)
        + "."
        + (f" The product runs `{product}`." if product else "")
    )
    w("")
    methods = list(e4["methods"])
    rows = []
    for m in methods:
        for det, r in dets.items():
            res = (r.get("methods") or {}).get(m)
            if res is not None:
                rows.append([f"{_label(d, m)} / {det}", *_table1_cells(res, TABLE1_SUBSETS)])
    for det, r in dets.items():
        if r.get("ceiling") is not None:
            rows.append([f"ceiling / {det}", *_table1_cells(r["ceiling"], TABLE1_SUBSETS)])
    w(_md_table(_table1_head(e4["methods"], TABLE1_SUBSETS, "method / detector"), rows))
    w("")
    w(
        "Clip counts in the header are those of the std detector's table; every detector "
        "scores the same clips. `ceiling` = " + CEILING_LABEL + "."
    )
    w("")
    for det, r in others.items():
        bs = r.get("by_signal")
        if not bs:
            continue
        w(
            f"**AUC by signal strength, `{det}` detector** (bins as above, each against all "
            f"{bs.get('n_neg', '–')} backgrounds):"
        )
        w("")
        w(_by_signal_table(d, bs))
        w("")


def _e1_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e1 = d["results"]["e1"]
    w("## E1: signal strength vs distance (paper Fig. 4)")
    w("")
    w(
        f"`controlled` drives at {e1['size'][0]}x{e1['size'][1]} "
        f"(f = {_num(e1['focal_px'], '.0f')} px). Positive: the clip score at each bump "
        "crossing of the lead; background: s at every "
        f"frame from {d['plan']['e1_start_s']:g} s on that is not within "
        f"[{d['plan']['e1_exclude_s'][0]:g}, {d['plan']['e1_exclude_s'][1]:+g}] s of a crossing "
        "of either car. Fit s(d) = α f δ / d + β by least squares over the crossings (δ = 0.06 m, "
        "d the true lead distance at the crossing). Separation distance: the largest distance up "
        "to which (from the shortest gap on, without a break) the median crossing score exceeds "
        "the 99th percentile of that drive's background s (of all drives pooled when a drive has "
        "fewer than 30 background frames). The paper reports about 20 m at 1080p."
    )
    w("")
    rows = []
    for m, r in e1["methods"].items():
        rows.append(
            [
                _label(d, m),
                _num(r["alpha"]),
                _num(r["beta"]),
                _num(r["r2"]),
                str(r["n_points"]),
                _num(r["background_p99_pooled"]),
                _num(r["separation_distance_m"], ".1f"),
            ]
        )
    w(
        _md_table(
            ["method", "α", "β (px)", "R²", "crossings", "background p99 (px)", "separation (m)"],
            rows,
        )
    )
    w("")
    fk = e1["methods"].get("fused-kalman")
    if fk:
        w("Per gap (`fused-kalman`):")
        w("")
        rows = [
            [
                f"{g['gap_m']:g}",
                _num(g["distance_m"], ".1f"),
                ", ".join(_num(v) for v in g["positive_s"]),
                _num(g["background_p99"]),
                "yes" if g["separated"] else "no",
            ]
            for g in fk["per_gap"]
        ]
        w(
            _md_table(
                ["gap (m)", "distance (m)", "crossing scores (px)", "background p99", "separated"],
                rows,
            )
        )
        w("")
    w(f"![E1]({fp}{e1['figure']})")
    w("")


def _e2_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e2 = d["results"]["e2"]
    w("## E2: pitch while the ego crosses a bump (paper Fig. 5)")
    w("")
    lo, hi = e2["window_s"]
    w(
        f"Recording `{e2['recording']}`, the ego's front axle over the bump at "
        f"{e2['ego_crossing_s']:.2f} s; window {lo:.2f}-{hi:.2f} s. The pipeline's pitch is "
        "relative to its first frame: each curve is shifted by its mean difference to the true "
        "camera pitch over the first second of the window. Columns: RMS and largest error in "
        "the window after that alignment; RMS of the 1 s high-pass error (error minus its "
        "trailing 1 s mean, what the detector window sees) over the whole drive; largest s in "
        "the window (the ego's own crossing, no lead event: ideally small)."
    )
    w("")
    rows = [
        [
            _label(d, m),
            _num(r["rms_error_window_deg"], ".3f"),
            _num(r["max_abs_error_window_deg"], ".3f"),
            _num(r["rms_error_hp_drive_deg"], ".3f"),
            _num(r["s_max_window_px"]),
        ]
        for m, r in e2["methods"].items()
    ]
    w(
        _md_table(
            [
                "method",
                "RMS error (deg)",
                "max error (deg)",
                "1 s high-pass RMS, drive (deg)",
                "max s (px)",
            ],
            rows,
        )
    )
    w("")
    w(f"![E2]({fp}{e2['figure']})")
    w("")


def _e3_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e3 = d["results"]["e3"]
    a, b = d["plan"]["score_window_s"]
    w("## E3: false positives vs ego rotation (paper Fig. 6)")
    w("")
    w(
        f"{e3['n_windows']} background windows of the wild set, one every {e3['step_s']:g} s "
        "wherever the score cannot see a lead crossing; each scored like a clip. Rotation "
        "intensity: the mean absolute true camera pitch rate (deg/s; equivalently the mean "
        f"absolute pitch change per frame x fps) over [t {a - 1:+g} s, t {b:+g} s]. Bins: "
        "equal-count quantiles. FPR at each method's F-maximising threshold on the wild clips "
        f"(first table) and at the common product default {e3['default_threshold_px']:g} px "
        "(second table)."
    )
    w("")
    centers = e3["bin_centers_deg_s"]
    bins = [
        f"{_num(c, '.2f')} deg/s (n={n})" for c, n in zip(centers, e3["bin_counts"], strict=True)
    ]
    rows = []
    for m, r in e3["methods"].items():
        rows.append([_label(d, m), _num(r["threshold_px"])] + [_num(v) for v in r["fpr"]])
    w(_md_table(["method", "threshold (px)", *bins], rows))
    w("")
    rows = [
        [_label(d, m), _num(r["fpr_all_at_default"])] + [_num(v) for v in r["fpr_at_default"]]
        for m, r in e3["methods"].items()
    ]
    w(_md_table(["method", "all windows", *bins], rows))
    w("")
    w(f"![E3]({fp}{e3['figure']})")
    w("")


def _e5_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e5 = d["results"]["e5"]
    tl = e5["texture_loss"]
    c = tl["counts"]
    w("## E5: beyond the paper")
    w("")
    w("### Texture loss (fog, tunnel, night)")
    w("")
    w(
        f"`texture-loss` set at {tl['size'][0]}x{tl['size'][1]}: {c['positives']} positive and "
        f"{c['backgrounds']} background clips, {tl['clips_inside']} of them centred inside a "
        "segment. AUC and BA (at the method's F-maximising threshold on the wild set) inside "
        "vs outside the segments; pitch error inside the segments: 1 s high-pass RMS, and the "
        "RMS after aligning on the second before each segment (drift while texture is lost)."
    )
    w("")
    rows = []
    for m, r in tl["methods"].items():
        ins, outs = r["inside"], r["outside"]
        rows.append(
            [
                _label(d, m),
                f"{_num(ins['auc'])} / {_num(ins['ba'])} ({ins['n_pos']}+/{ins['n_neg']}−)",
                f"{_num(outs['auc'])} / {_num(outs['ba'])} ({outs['n_pos']}+/{outs['n_neg']}−)",
                _num(r["pitch_rms_hp_inside_deg"], ".3f"),
                _num(r["pitch_rms_aligned_inside_deg"], ".3f"),
            ]
        )
    w(
        _md_table(
            [
                "method",
                "inside AUC / BA",
                "outside AUC / BA",
                "pitch error inside, 1 s HP RMS (deg)",
                "aligned RMS (deg)",
            ],
            rows,
        )
    )
    w("")
    w(f"![E5 texture]({fp}{tl['figure']})")
    w("")
    rg = e5["range"]
    bins = rg["bins_m"]
    w("### Detection range per resolution")
    w("")
    w(
        "Tracked clips only (the lead's box on the true one, as in Table I's tracked subsets: "
        "range is a question of resolution, not of the tracker's failures). "
        "Recall of the positive clips per bin of the true lead distance, at each method's "
        "threshold for a false-positive rate of at most 10 % on that resolution's own "
        "background clips (not cross-validated; FPR column: the rate reached). Range: "
        "the lower edge of the first bin whose recall is below 50 % (`≥ x`: never below 50 % "
        "up to the last edge)."
    )
    w("")
    bin_names = [f"{bins[i]:g}-{bins[i + 1]:g} m" for i in range(len(bins) - 1)]
    for size, r in rg["sizes"].items():
        w(
            f"**{size}** ({r['recordings']} recordings, {r['positives']} positives, "
            f"{r['backgrounds']} backgrounds tracked; {r.get('untracked_clips', 0)} clips "
            "untracked)"
        )
        w("")
        rows = []
        for m, x in r["methods"].items():
            rng_txt = ("≥ " if x["range_open"] else "") + _num(x["range_m"], ".0f") + " m"
            rows.append(
                [_label(d, m), _num(x["threshold_px"]), _num(x.get("fpr")), rng_txt]
                + [f"{_num(v)} ({n})" for v, n in zip(x["recall"], x["positives"], strict=True)]
            )
        w(_md_table(["method", "threshold (px)", "FPR", "range", *bin_names], rows))
        w("")
    w(f"![E5 range]({fp}{rg['figure']})")
    w("")
    lt = e5["lead_time"]
    w("### Alert lead time")
    w("")
    w(
        "The product's own alerts (default detector, `threshold_px` = 1.0 px, emitted at "
        "the onset of the excursion (`emit` = onset), suppression) on the wild set, "
        "matched to the lead's crossings as `roadpreview replay "
        "--truth` does (crossing within -0.6/+1.2 s of the alert's crossing time). Lead time = "
        "the ego's front axle over the anomaly minus the alert's emission. `uncompensated` "
        "runs in mode DEGRADED, whose events are suppressed by design, so it raises no alert; "
        "`imu-only` likewise when its mode is DEGRADED."
    )
    w("")
    rows = [
        [
            _label(d, m),
            f"{r['alerts_hits']}/{r['lead_crossings']}",
            _num(r["false_alarms_per_min"], ".1f"),
            _num(r["lead_time_median_s"]),
            _num(r["lead_time_p10_s"]),
            _num(r["lead_time_p90_s"]),
            str(r["late_alerts"]),
        ]
        for m, r in lt["methods"].items()
    ]
    w(
        _md_table(
            [
                "method",
                "detected",
                "false alarms / min",
                "lead time median (s)",
                "p10 (s)",
                "p90 (s)",
                "alerts after arrival",
            ],
            rows,
        )
    )
    w("")
    w(f"![E5 lead time]({fp}{lt['figure']})")
    w("")


# -- E6: the product ----------------------------------------------------------------------------
#: the outcome columns of the ego confirmation table, in this order (others follow)
CONFIRMATION_COLUMNS = ("CONFIRMED", "NOT_FELT", "UNKNOWN", "pending")
#: what each truth row of the ego confirmation table holds
CONFIRMATION_ROWS = {
    "felt": "real, the ego drives over it",
    "beside": "real, the ego passes beside it",
    "false": "false alarm",
}
#: the unit of each detector's threshold (`detectors.THRESHOLD_FIELDS`)
THRESHOLD_UNITS = {"std": "px", "two-axle": "background std"}


def _int(v: Any) -> str:
    return "–" if v is None else str(v)


def _hits(t: Mapping[str, Any] | None) -> str:
    """A tally's recall with its hits / expected."""
    if not t:
        return "–"
    return f"{_num(t.get('recall'))} ({_int(t.get('hits'))}/{_int(t.get('expected'))})"


def _fa(t: Mapping[str, Any] | None) -> str:
    """A tally's false alarms per minute with the count."""
    if not t:
        return "–"
    return f"{_num(t.get('fa_per_min'))} ({_int(t.get('false_alarms'))})"


def _unit(det: str) -> str:
    return THRESHOLD_UNITS.get(det, "")


def _e6_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e6 = d["results"]["e6"]
    det = e6.get("product_detector") or "–"
    ref = e6.get("reference_method") or "–"
    ref_label = _label(d, ref) if ref in d.get("methods", {}) else ref
    w("## E6: the product at its operating point")
    w("")
    w(
        f"The product as a chassis engineer judges it: the alerts of the `{det}` detector "
        f"(the product's, `[anomaly] detector`) over the reference method `{ref}` "
        f"({ref_label}) unless a table says otherwise, matched to the truth as "
        "`roadpreview replay --truth` does (`roadpreview.pipeline.truthmatch`). Recall counts "
        "the lead's crossings of an anomaly; a false alarm is an alert that matches none."
    )
    w("")
    _e6_operating_points(d, w)
    _e6_product_default(d, w)
    _e6_svar(d, w)
    _e6_height(d, w)
    _e6_calibration(d, w, fp)
    _e6_confirmation(d, w)
    _e6_road_class(d, w)
    _e6_generalization(d, w)


def _e6_operating_points(d: Mapping[str, Any], w: Any) -> None:
    e6 = d["results"]["e6"]
    op = e6.get("operating_points")
    if not op:
        return
    rates = [f"{r:g}" for r in op.get("fa_per_min") or []]
    grids = op.get("grids") or {}
    dets: Mapping[str, Any] = op.get("detectors") or {}
    w("### Operating points (held-out folds)")
    w("")
    w(
        f"Wild set. Recall of the anomalies with an expected signal f |δ| / d >= "
        f"{_num(op.get('min_signal_px'), 'g')} px and false alarms per minute at each rate's "
        "threshold: for each held-out fold, the lowest threshold of the detector's grid whose "
        "training folds (recordings grouped, as Table I's) stay at or below the rate; the "
        "figures are the held-out folds pooled. Fold thresholds in the detector's unit "
        "(–: no threshold of the grid is quiet enough on the training folds, the fold sends "
        "nothing). Grids: "
        + "; ".join(
            f"`{k}` {', '.join(f'{v:g}' for v in g)} {_unit(k)}".rstrip() for k, g in grids.items()
        )
        + ". Recall cells: recall (hits/expected); false alarms: per minute (count)."
    )
    w("")
    head = ["method / detector"]
    for r in rates:
        head += [f"recall at <= {r} FA/min", f"FA/min at <= {r}", f"fold thresholds at <= {r}"]
    rows = []
    methods = list(next(iter(dets.values()), {}))
    for m in methods:
        for k, by_m in dets.items():
            x = by_m.get(m)
            if x is None:
                continue
            row = [f"{_label(d, m) if m in d['methods'] else m} / {k}"]
            for r in rates:
                h = (x.get("held_out") or {}).get(r)
                thr = ", ".join(_num(t, "g") for t in (h or {}).get("thresholds") or []) or "–"
                row += [_hits(h), _fa(h), thr]
            rows.append(row)
    w(_md_table(head, rows))
    w("")
    ref = e6.get("reference_method")
    for k, by_m in dets.items():
        curve = (by_m.get(ref) or {}).get("curve") if ref else None
        if not curve:
            continue
        unit = _unit(k)
        w(
            f"The whole set's curve of `{ref}` with the `{k}` detector, per threshold"
            + (f" ({unit})" if unit else "")
            + ":"
        )
        w("")
        head = ["threshold", *[_num(c.get("threshold"), "g") for c in curve]]
        rows = [
            ["recall (hits/expected)", *[_hits(c) for c in curve]],
            ["FA/min (count)", *[_fa(c) for c in curve]],
        ]
        w(_md_table(head, rows))
        w("")


def _e6_product_default(d: Mapping[str, Any], w: Any) -> None:
    e6 = d["results"]["e6"]
    pdef: Mapping[str, Any] = e6.get("product_default") or {}
    if not pdef:
        return
    anomaly = d.get("anomaly") or {}
    configured = []
    for k in pdef:
        table = DETECTORS[k][2] if k in DETECTORS else k
        field = THRESHOLD_FIELDS.get(k)
        value = (anomaly.get(table) or {}).get(field) if field else None
        if field and value is not None:
            configured.append(f"`[anomaly.{table}] {field}` = {value:g} {_unit(k)}".rstrip())
    w("### At the configured thresholds")
    w("")
    w(
        "Wild set, the product's configuration"
        + (f" ({', '.join(configured)})" if configured else "")
        + ". Recall of every lead crossing of an anomaly and of those with f |δ| / d >= "
        f"{_num((e6.get('operating_points') or {}).get('min_signal_px'), 'g')} px; "
        "false alarms per minute (count) over the set's minutes."
    )
    w("")
    rows = []
    methods = list(next(iter(pdef.values()), {}))
    for m in methods:
        for k, by_m in pdef.items():
            x = by_m.get(m)
            if x is None:
                continue
            every, strong = x.get("all"), x.get("strong")
            rows.append(
                [
                    f"{_label(d, m) if m in d['methods'] else m} / {k}",
                    _hits(every),
                    _hits(strong),
                    _fa(every),
                    _num((every or {}).get("minutes"), ".1f"),
                ]
            )
    w(
        _md_table(
            [
                "method / detector",
                "recall, all",
                "recall, strong signal",
                "false alarms / min",
                "minutes",
            ],
            rows,
        )
    )
    w("")


def _e6_svar(d: Mapping[str, Any], w: Any) -> None:
    e6 = d["results"]["e6"]
    sv = e6.get("svar")
    if not sv:
        return
    e4 = d["results"].get("e4") or {}
    full = {"std": e4.get("methods") or {}}
    full |= {k: v.get("methods") or {} for k, v in (e4.get("detectors") or {}).items()}
    dets: Mapping[str, Any] = sv.get("detectors") or {}
    w("### SVAR-like subset")
    w("")
    w(
        "Table I's AUC on positives chosen as the paper's annotators did (SVAR): the ego felt "
        f"the anomaly (a vertical acceleration of its camera of at least "
        f"{_num(sv.get('felt_mps2'), 'g')} m/s²) and the tracker saw the lead cross it; "
        "every background clip. Beside it the AUC on the full wild set (E4). Clips: "
        + "; ".join(
            f"`{k}` {_int(x.get('positives'))}+/{_int(x.get('backgrounds'))}− "
            f"(hard {_int(x.get('hard_positives'))}+/{_int(x.get('hard_backgrounds'))}−)"
            for k, x in dets.items()
        )
        + "."
    )
    w("")
    few = [k for k, x in dets.items() if (x.get("hard_positives") or 0) < MIN_HARD_POSITIVES]
    if few:
        w(
            f"**The SVAR-like hard subset has fewer than {MIN_HARD_POSITIVES} positives for "
            f"{', '.join(f'`{k}`' for k in few)}: its AUC is too noisy to rank the methods.**"
        )
        w("")
    rows = []
    first: Mapping[str, Any] = next(iter(dets.values()), {})
    methods = list(first.get("methods") or {})
    for m in methods:
        for k, x in dets.items():
            r = (x.get("methods") or {}).get(m)
            if r is None:
                continue
            subs = (full.get(k, {}).get(m) or {}).get("subsets") or {}
            rows.append(
                [
                    f"{_label(d, m) if m in d['methods'] else m} / {k}",
                    _num(r.get("auc")),
                    _num((subs.get("entire") or {}).get("auc")),
                    _num(r.get("auc_hard")),
                    _num((subs.get("hard") or {}).get("auc")),
                ]
            )
    w(
        _md_table(
            [
                "method / detector",
                "SVAR-like AUC",
                "full AUC",
                "SVAR-like hard AUC",
                "full hard AUC",
            ],
            rows,
        )
    )
    w("")


def _e6_height(d: Mapping[str, Any], w: Any) -> None:
    e6 = d["results"]["e6"]
    h: Mapping[str, Any] = e6.get("height") or {}
    if not h:
        return
    w("### Height")
    w("")
    floor = next((x.get("min_signal_px") for x in h.values() if x), None)
    w(
        "The alerts' signed height against the matched anomaly's, on the true alerts whose "
        f"anomaly has an expected signal f |δ| / d >= {_num(floor, 'g')} px: relative error "
        "|ĥ − δ| / |δ|, the share with the right sign, and the share within two of the "
        "alert's own height std."
    )
    w("")
    rows = [
        [
            name,
            _int(x.get("n")),
            _num(x.get("median_rel_error"), ".0%"),
            _num(x.get("p90_rel_error"), ".0%"),
            _num(x.get("sign_correct"), ".0%"),
            _num(x.get("within_2_std"), ".0%"),
        ]
        for name, x in h.items()
        if x
    ]
    w(
        _md_table(
            [
                "set",
                "alerts",
                "median relative error",
                "p90 relative error",
                "sign correct",
                "within 2 std",
            ],
            rows,
        )
    )
    w("")


def _e6_calibration(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e6 = d["results"]["e6"]
    cal = e6.get("calibration")
    if not cal:
        return

    def ab(v: Any) -> str:
        return "–" if not v else f"a = {_num(v[0])}, b = {_num(v[1])}"

    w("### Alert confidence")
    w("")
    w(
        f"The two-axle alerts' confidence (`{cal.get('method', '–')}`) is "
        "P(real) = 1 / (1 + exp(−(a + b ln(z / threshold_z)))). Fitted on all wild drives: "
        f"{ab(cal.get('fit_all_wild'))}; shipped (`[anomaly.two_axle] confidence_logit`): "
        f"{ab(cal.get('shipped'))}. The wild set's reliability is cross-fitted (fit on the "
        "training folds, applied to the held-out fold); the generalization suite's is that "
        "of the shipped confidence, held out. ECE: expected calibration error, "
        "Σ n_k / n |frequency_k − confidence_k| over bins of confidence."
    )
    w("")
    rows = []
    for name, label in (
        ("wild_cross_fitted", "wild, cross-fitted"),
        ("generalization_shipped", "generalization, shipped"),
    ):
        r = cal.get(name)
        if not r:
            continue
        rows += [
            [label, _num(b.get("confidence")), _num(b.get("frequency")), _int(b.get("n")), ""]
            for b in r.get("bins") or []
        ]
        rows.append([f"**{label}, all**", "", "", _int(r.get("n")), _num(r.get("ece"))])
    if rows:
        w(
            "Reliability per bin of confidence (tenths; empty bins left out): the bin's mean "
            "confidence against the share of its alerts that were real."
        )
        w("")
        w(_md_table(["set", "mean confidence", "share real", "alerts", "ECE"], rows))
        w("")
    fig = e6.get("reliability_figure")
    if fig:
        w(f"![E6 reliability]({fp}{fig})")
        w("")


def _e6_confirmation(d: Mapping[str, Any], w: Any) -> None:
    e6 = d["results"]["e6"]
    conf: Mapping[str, Any] = e6.get("confirmation") or {}
    if not conf:
        return
    w("### Ego confirmation")
    w("")
    w(
        "When the ego reaches an alert's spot its own IMU confirms the alert (CONFIRMED), "
        "rejects it (NOT_FELT) or cannot tell (UNKNOWN); pending: never decided before the "
        "drive ended. Rows: the truth behind each alert."
    )
    w("")
    extra = [
        c
        for x in conf.values()
        for r in (x or {}).values()
        for c in r
        if c not in CONFIRMATION_COLUMNS
    ]
    cols = [*CONFIRMATION_COLUMNS, *dict.fromkeys(extra)]
    rows = []
    for name, x in conf.items():
        for kind, r in (x or {}).items():
            rows.append([name, CONFIRMATION_ROWS.get(kind, kind), *[_int(r.get(c)) for c in cols]])
    w(_md_table(["set", "truth", *cols], rows))
    w("")


def _e6_road_class(d: Mapping[str, Any], w: Any) -> None:
    e6 = d["results"]["e6"]
    rc: Mapping[str, Any] = e6.get("road_class") or {}
    if not rc:
        return
    w("### Road class")
    w("")
    w(
        "The road's ISO 8608 class estimated at the end of each drive against the drive's "
        "class (true → estimate, ? = no estimate, × drives)."
    )
    w("")
    rows = []
    for name, x in rc.items():
        if not x:
            continue
        pairs = Counter(f"{t}→{'?' if e is None else e}" for t, e in x.get("pairs") or [])
        rows.append(
            [
                name,
                str(sum(pairs.values())),
                _num(x.get("exact"), ".0%"),
                _num(x.get("within_one"), ".0%"),
                _int(x.get("unknown")),
                ", ".join(f"{p} ×{n}" for p, n in sorted(pairs.items())) or "–",
            ]
        )
    w(_md_table(["set", "drives", "exact", "within one class", "no estimate", "pairs"], rows))
    w("")


def _e6_generalization(d: Mapping[str, Any], w: Any) -> None:
    e6 = d["results"]["e6"]
    g = e6.get("generalization")
    w("### Generalization suite")
    w("")
    if not g:
        w(
            "Not in this run (the quick configuration has no generalization suite): the full "
            "evaluation runs it."
        )
        w("")
        return
    w(
        "Drives that each fix their own camera, road class, speed and gap, lead vehicle and "
        "conditions (`roadpreview.sim.presets.GENERALIZATION_DRIVES`). "
        "**They are never used for tuning**: the thresholds of the operating points and the "
        "confidence fit come from the wild set; the suite runs the product's configuration "
        f"(`{g.get('method', '–')}`, detector `{e6.get('product_detector', '–')}`) as "
        "shipped. Recall of the anomalies with f |δ| / d >= "
        f"{_num(g.get('min_signal_px'), 'g')} px (one-sided: those under only one of the "
        "lead's wheel tracks); false alarms per minute (count); mode changes of the fusion per "
        "minute, all and after the start-up (once first FUSED); textured: the share of frames "
        "with enough texture; height: median relative "
        "error of the true alerts' height."
    )
    w("")
    rows = []
    for name, x in (g.get("drives") or {}).items():
        size, fps = x.get("size"), x.get("fps")
        camera = f"{size[0]}x{size[1]}" if size else "–"
        camera += f"@{fps:g}" if fps is not None else ""
        conditions = ", ".join(x.get("conditions") or []) or "none"
        rows.append(
            [
                name,
                camera,
                f"{x.get('iso_class') or '–'} / {x.get('road_class_estimate') or '?'}",
                conditions,
                _hits(x),
                _hits(x.get("one_sided")),
                _fa(x),
                _num(x.get("mode_changes_per_min"), ".1f")
                + " / "
                + _num(x.get("mode_changes_after_startup_per_min"), ".1f"),
                _num(x.get("textured_share"), ".0%"),
                _num(x.get("height_median_rel_error"), ".0%"),
            ]
        )
    total = g.get("total")
    rows.append(
        [
            "**all drives**",
            "",
            "",
            "",
            _hits(total),
            _hits(g.get("one_sided")),
            _fa(total),
            "",
            "",
            "",
        ]
    )
    w(
        _md_table(
            [
                "drive",
                "camera",
                "ISO class / estimate",
                "conditions",
                "recall",
                "one-sided recall",
                "false alarms / min",
                "mode changes / min, all / after start-up",
                "textured",
                "height error",
            ],
            rows,
        )
    )
    w("")


def _timing_section(d: Mapping[str, Any], w: Any) -> None:
    t = d["timing"]
    w("## Run time")
    w("")
    w(
        f"Wall time {t['wall_s']:.0f} s ({t['processing_wall_s']:.0f} s simulating and running "
        f"the methods with {t['workers']} worker(s), {t['experiments_wall_s']:.0f} s for the "
        f"experiments and figures). {t['frames_simulated']} frames simulated "
        f"({_num(t['simulate_cpu_ms_per_frame'], '.1f')} ms CPU per frame), "
        f"{t['frames_evaluated']} frames through all methods "
        f"({_num(t['evaluate_cpu_ms_per_frame'], '.1f')} ms CPU per frame for all methods "
        "together). "
        + (
            "CPU time per method (its pipeline steps plus an equal share of the vision): "
            + ", ".join(f"{m} {s:.0f} s" for m, s in t["method_cpu_s"].items())
            + ". "
            if t["method_cpu_s"]
            else "Every recording's traces were cached from an earlier run (same code and "
            "configuration): this run only ran the detectors and the experiments. "
        )
        + "Wall times depend on what else runs on the machine; the CPU times do not."
    )
    w("")
