"""The report's sections of E1-E5: the paper's Table I (E4, with every detector side by
side), Fig. 4 (E1), Fig. 5 (E2), Fig. 6 (E3), then ours (E5: texture loss, detection
range, alert lead time). Each writes Markdown lines from ``results.json``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from roadpreview.eval.report.tables import (
    CEILING_LABEL,
    MIN_HARD_POSITIVES,
    TABLE1_SUBSETS,
    TRACKED_SUBSETS,
    detector_label,
    md_table,
    method_label,
    num,
    table1_cells,
    table1_head,
    table1_header,
    table1_rows,
)


def e4_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
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
    w(md_table(table1_header(d), table1_rows(d)))
    w("")
    w("The same, on the tracked clips only (threshold still chosen on all training clips):")
    w("")
    w(md_table(table1_header(d, TRACKED_SUBSETS), table1_rows(d, TRACKED_SUBSETS)))
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
                method_label(d, m),
                num(r["threshold_f_max_px"]),
                ", ".join(num(v) for v in r["fold_thresholds_px"]),
                f"{num(r['at_f_max']['tpr'])} / {num(r['at_f_max']['fpr'])}",
                f"{num(r['at_1px']['tpr'])} / {num(r['at_1px']['fpr'])}",
                str(r["no_lead_clips"]),
            ]
        )
    w(
        md_table(
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
    head = ["f abs(δ) / d (px)", "positives", *[method_label(d, m) for m in names]]
    rows = []
    for b in bins:
        hi = "∞" if b["hi_px"] is None else f"{b['hi_px']:g}"
        rows.append(
            [f"[{b['lo_px']:g}, {hi})", str(b["n_pos"])] + [num(b["auc"].get(m)) for m in names]
        )
    return md_table(head, rows)


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
        + "; ".join(f"`{det}` = {detector_label(det)}" for det in dets)
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
                rows.append([f"{method_label(d, m)} / {det}", *table1_cells(res, TABLE1_SUBSETS)])
    for det, r in dets.items():
        if r.get("ceiling") is not None:
            rows.append([f"ceiling / {det}", *table1_cells(r["ceiling"], TABLE1_SUBSETS)])
    w(md_table(table1_head(e4["methods"], TABLE1_SUBSETS, "method / detector"), rows))
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


def e1_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e1 = d["results"]["e1"]
    w("## E1: signal strength vs distance (paper Fig. 4)")
    w("")
    w(
        f"`controlled` drives at {e1['size'][0]}x{e1['size'][1]} "
        f"(f = {num(e1['focal_px'], '.0f')} px). Positive: the clip score at each bump "
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
                method_label(d, m),
                num(r["alpha"]),
                num(r["beta"]),
                num(r["r2"]),
                str(r["n_points"]),
                num(r["background_p99_pooled"]),
                num(r["separation_distance_m"], ".1f"),
            ]
        )
    w(
        md_table(
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
                num(g["distance_m"], ".1f"),
                ", ".join(num(v) for v in g["positive_s"]),
                num(g["background_p99"]),
                "yes" if g["separated"] else "no",
            ]
            for g in fk["per_gap"]
        ]
        w(
            md_table(
                ["gap (m)", "distance (m)", "crossing scores (px)", "background p99", "separated"],
                rows,
            )
        )
        w("")
    w(f"![E1]({fp}{e1['figure']})")
    w("")


def e2_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
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
        "the window (the detector's 1 s std of y_c, detrended), frames whose window holds a "
        "crossing of the lead left out: what the ego's own bump leaves in y_c, ideally 0."
    )
    w("")
    rows = [
        [
            method_label(d, m),
            num(r["rms_error_window_deg"], ".3f"),
            num(r["max_abs_error_window_deg"], ".3f"),
            num(r["rms_error_hp_drive_deg"], ".3f"),
            num(r["s_max_window_px"]),
        ]
        for m, r in e2["methods"].items()
    ]
    w(
        md_table(
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
    eo = e2.get("ego_only")
    if eo:
        w("### The ego's own anomalies, every ego-only crossing")
        w("")
        w(
            f"{eo['n_crossings']} crossings of an anomaly by the ego on the wild set and the "
            "generalization suite with no crossing of the lead (either side, hit or passed) from "
            "1 s before to 3.5 s after (`experiments.ego_bump.ego_only_crossings`). Per crossing "
            "the largest detrended 1 s std of y_c from the front axle's crossing to 1.5 s after; "
            "median, 90th percentile and largest over the crossings. The truth's row is the true "
            "compensated trajectory: what the lead's own bouncing on a rough road leaves."
        )
        w("")
        rows = [
            [method_label(d, m), *(num(v) for v in x), _worst(eo, m)]
            for m, x in eo["methods"].items()
        ]
        rows.append(["truth", *(num(v) for v in eo["truth"]), ""])
        w(md_table(["method", "median (px)", "90th pct (px)", "max (px)", "largest at"], rows))
        w("")


def _worst(eo: Mapping[str, Any], m: str) -> str:
    w = (eo.get("worst") or {}).get(m)
    return f"`{w[0]}` {w[1]:.1f} s" if w else ""


def e3_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
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
        f"{num(c, '.2f')} deg/s (n={n})" for c, n in zip(centers, e3["bin_counts"], strict=True)
    ]
    rows = []
    for m, r in e3["methods"].items():
        rows.append([method_label(d, m), num(r["threshold_px"])] + [num(v) for v in r["fpr"]])
    w(md_table(["method", "threshold (px)", *bins], rows))
    w("")
    rows = [
        [method_label(d, m), num(r["fpr_all_at_default"])] + [num(v) for v in r["fpr_at_default"]]
        for m, r in e3["methods"].items()
    ]
    w(md_table(["method", "all windows", *bins], rows))
    w("")
    w(f"![E3]({fp}{e3['figure']})")
    w("")


def e5_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
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
                method_label(d, m),
                f"{num(ins['auc'])} / {num(ins['ba'])} ({ins['n_pos']}+/{ins['n_neg']}−)",
                f"{num(outs['auc'])} / {num(outs['ba'])} ({outs['n_pos']}+/{outs['n_neg']}−)",
                num(r["pitch_rms_hp_inside_deg"], ".3f"),
                num(r["pitch_rms_aligned_inside_deg"], ".3f"),
            ]
        )
    w(
        md_table(
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
            rng_txt = ("≥ " if x["range_open"] else "") + num(x["range_m"], ".0f") + " m"
            rows.append(
                [method_label(d, m), num(x["threshold_px"]), num(x.get("fpr")), rng_txt]
                + [f"{num(v)} ({n})" for v, n in zip(x["recall"], x["positives"], strict=True)]
            )
        w(md_table(["method", "threshold (px)", "FPR", "range", *bin_names], rows))
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
            method_label(d, m),
            f"{r['alerts_hits']}/{r['lead_crossings']}",
            num(r["false_alarms_per_min"], ".1f"),
            num(r["lead_time_median_s"]),
            num(r["lead_time_p10_s"]),
            num(r["lead_time_p90_s"]),
            str(r["late_alerts"]),
        ]
        for m, r in lt["methods"].items()
    ]
    w(
        md_table(
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
