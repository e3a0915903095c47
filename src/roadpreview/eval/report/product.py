"""The report's section of E6, the product at its operating point
(`roadpreview.eval.product`): operating points, the configured thresholds, the SVAR-like
subset, height, alert confidence, ego confirmation, road class, the generalization
suite, the alerts' timing with the provisional alerts, the road preview."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from typing import Any

from roadpreview.anomaly import DETECTORS
from roadpreview.eval.detectors import THRESHOLD_FIELDS
from roadpreview.eval.report.tables import MIN_HARD_POSITIVES, md_table, method_label, num

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
    return f"{num(t.get('recall'))} ({_int(t.get('hits'))}/{_int(t.get('expected'))})"


def _fa(t: Mapping[str, Any] | None) -> str:
    """A tally's false alarms per minute with the count."""
    if not t:
        return "–"
    return f"{num(t.get('fa_per_min'))} ({_int(t.get('false_alarms'))})"


def _unit(det: str) -> str:
    return THRESHOLD_UNITS.get(det, "")


def e6_section(d: Mapping[str, Any], w: Any, fp: str) -> None:
    e6 = d["results"]["e6"]
    det = e6.get("product_detector") or "–"
    ref = e6.get("reference_method") or "–"
    ref_label = method_label(d, ref) if ref in d.get("methods", {}) else ref
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
    _e6_timing(d, w)
    _e6_preview(d, w)


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
        f"{num(op.get('min_signal_px'), 'g')} px and false alarms per minute at each rate's "
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
            row = [f"{method_label(d, m) if m in d['methods'] else m} / {k}"]
            for r in rates:
                h = (x.get("held_out") or {}).get(r)
                thr = ", ".join(num(t, "g") for t in (h or {}).get("thresholds") or []) or "–"
                row += [_hits(h), _fa(h), thr]
            rows.append(row)
    w(md_table(head, rows))
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
        head = ["threshold", *[num(c.get("threshold"), "g") for c in curve]]
        rows = [
            ["recall (hits/expected)", *[_hits(c) for c in curve]],
            ["FA/min (count)", *[_fa(c) for c in curve]],
        ]
        w(md_table(head, rows))
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
        f"{num((e6.get('operating_points') or {}).get('min_signal_px'), 'g')} px; "
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
                    f"{method_label(d, m) if m in d['methods'] else m} / {k}",
                    _hits(every),
                    _hits(strong),
                    _fa(every),
                    num((every or {}).get("minutes"), ".1f"),
                ]
            )
    w(
        md_table(
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
        f"{num(sv.get('felt_mps2'), 'g')} m/s²) and the tracker saw the lead cross it; "
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
                    f"{method_label(d, m) if m in d['methods'] else m} / {k}",
                    num(r.get("auc")),
                    num((subs.get("entire") or {}).get("auc")),
                    num(r.get("auc_hard")),
                    num((subs.get("hard") or {}).get("auc")),
                ]
            )
    w(
        md_table(
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
        f"anomaly has an expected signal f |δ| / d >= {num(floor, 'g')} px: relative error "
        "|ĥ − δ| / |δ|, the share with the right sign, and the share within two of the "
        "alert's own height std."
    )
    w("")
    rows = [
        [
            name,
            _int(x.get("n")),
            num(x.get("median_rel_error"), ".0%"),
            num(x.get("p90_rel_error"), ".0%"),
            num(x.get("sign_correct"), ".0%"),
            num(x.get("within_2_std"), ".0%"),
        ]
        for name, x in h.items()
        if x
    ]
    w(
        md_table(
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
        return "–" if not v else f"a = {num(v[0])}, b = {num(v[1])}"

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
            [label, num(b.get("confidence")), num(b.get("frequency")), _int(b.get("n")), ""]
            for b in r.get("bins") or []
        ]
        rows.append([f"**{label}, all**", "", "", _int(r.get("n")), num(r.get("ece"))])
    if rows:
        w(
            "Reliability per bin of confidence (tenths; empty bins left out): the bin's mean "
            "confidence against the share of its alerts that were real."
        )
        w("")
        w(md_table(["set", "mean confidence", "share real", "alerts", "ECE"], rows))
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
    w(md_table(["set", "truth", *cols], rows))
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
                num(x.get("exact"), ".0%"),
                num(x.get("within_one"), ".0%"),
                _int(x.get("unknown")),
                ", ".join(f"{p} ×{n}" for p, n in sorted(pairs.items())) or "–",
            ]
        )
    w(md_table(["set", "drives", "exact", "within one class", "no estimate", "pairs"], rows))
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
        f"{num(g.get('min_signal_px'), 'g')} px (one-sided: those under only one of the "
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
                num(x.get("mode_changes_per_min"), ".1f")
                + " / "
                + num(x.get("mode_changes_after_startup_per_min"), ".1f"),
                num(x.get("textured_share"), ".0%"),
                num(x.get("height_median_rel_error"), ".0%"),
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
        md_table(
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


def _timing_row(name: str, t: Mapping[str, Any]) -> list[str]:
    """One row of the timing table from a `roadpreview.eval.provisional.Timing` dict."""
    far = t.get("headway_far") or 0
    short = t.get("lead_time_far_short")
    return [
        name,
        _hits(t),
        _fa(t),
        f"{num(t.get('latency_share'))} ({_int(t.get('latency_le_target'))}/{_int(t.get('hits'))})",
        f"{num(t.get('latency_median_s'))} / {num(t.get('latency_confirmed_median_s'))}",
        f"{_int(short)} of {far} (min {num(t.get('lead_time_far_min_s'))} s)" if far else "–",
        _int(t.get("late")),
        f"{num(t.get('provisional_fa_per_min'))} ({_int(t.get('provisional_false'))})",
        f"{num(t.get('cancelled_share'))} ({_int(t.get('cancelled_in_time'))})",
        f"{_int(t.get('provisional_confirmed'))} / {_int(t.get('provisional'))}",
    ]


def _e6_timing(d: Mapping[str, Any], w: Any) -> None:
    p = d["results"]["e6"].get("provisional")
    w("### Alert timing and provisional alerts")
    w("")
    chosen = ", ".join(
        num(x, "g") for x in ((p or {}).get("held_out") or {}).get("thresholds") or []
    )
    if not p:
        w("Not in this run (the product's detector has no provisional stage here).")
        w("")
        return
    w(
        "When the controller hears of an anomaly (`roadpreview.eval.provisional`): per hit "
        "(an anomaly with f|δ|/d >= 1 px the lead crossed, matched by a confirmed alert), the "
        "latency of its first `RP_ALERT` (the PROVISIONAL one when the alert had one) and of "
        "its confirmation after the lead's front axle crossed the anomaly's apex "
        f"(target: <= {num(p.get('latency_target_s'), 'g')} s for 90 % of hits), the lead time "
        "left for the ego (its front axle at the anomaly minus the first RP_ALERT; target: "
        f">= {num(p.get('lead_time_min_s'), 'g')} s at a time headway >= "
        f"{num(p.get('headway_min_s'), 'g')} s: the column counts the hits at such a headway "
        "that miss it), and the hits alerted only after the ego arrived ('late'). Provisional "
        "alerts: their false alarms per minute (target <= "
        f"{num(p.get('fa_target_per_min'), 'g')}), the share of those CANCELLED before the ego "
        "would have reached the spot they named (target >= 80 %), and how many were confirmed. "
        "The confirmed alerts' recall and false alarms are the product's: the provisional stage "
        "leaves them unchanged ('without' runs the same detector with `provisional = false`). "
        f"Threshold `provisional_threshold_z`: shipped {num(p.get('shipped_threshold'), 'g')}, "
        "chosen on the wild set (the training data) for the target rate; held out: per fold the "
        "lowest of the grid keeping the training folds at or below it "
        f"(chosen: {chosen})."
    )
    w("")
    header = [
        "",
        "recall (confirmed)",
        "false alarms / min",
        "first RP_ALERT <= target",
        "latency median, first / confirmed (s)",
        "short lead time at headway >= target",
        "late",
        "provisional false / min",
        "cancelled in time",
        "provisional confirmed / sent",
    ]
    rows = []
    if p.get("wild_without"):
        rows.append(_timing_row("wild, without provisional", p["wild_without"]))
    rows.append(_timing_row("wild, shipped threshold (tuned here)", p.get("wild_shipped") or {}))
    rows.append(_timing_row("wild, held-out folds", p.get("held_out") or {}))
    g = p.get("generalization") or {}
    if g.get("pooled"):
        rows.append(_timing_row("**generalization suite** (held out)", g["pooled"]))
    w(md_table(header, rows))
    w("")
    curve = p.get("curve") or []
    if curve:
        w("The wild set over the provisional threshold (every drive):")
        w("")
        w(
            md_table(
                header[:1] + header[3:],
                [
                    _timing_row(f"z >= {num(c.get('threshold'), 'g')}", c)[:1]
                    + _timing_row("", c)[3:]
                    for c in curve
                ],
            )
        )
        w("")
    drives = g.get("drives") or {}
    if drives:
        w("Per drive of the generalization suite (shipped threshold):")
        w("")
        w(md_table(header, [_timing_row(name, t) for name, t in drives.items()]))
        w("")
    cal = p.get("calibration") or {}
    if cal.get("logit"):
        a, b = cal["logit"]
        w(
            f"Provisional confidence: logistic fit on the wild set's {cal.get('n')} provisional "
            f"alerts ({cal.get('real')} real) at the shipped threshold: a = {num(a)}, "
            f"b = {num(b)} (`provisional_confidence_logit`)."
        )
        w("")


def _e6_preview(d: Mapping[str, Any], w: Any) -> None:
    p = d["results"]["e6"].get("preview")
    w("### Road preview (RP_PREVIEW)")
    w("")
    if not p:
        w("Not in this run (`[preview] enabled = false`).")
        w("")
        return
    w(
        "The previewed road against the simulator's (`roadpreview.eval.preview`): over the "
        f"bins whose spot the lead's wheels passed within the last {num(p.get('recent_s'), 'g')} "
        "s before each preview, each side's least-squares line removed as the preview's "
        "(level and grade are not observable). RMS of the height error in mm: the product (the "
        "profile with the confirmed alerts' bins), the profile alone, and the profile alone on "
        "the true compensated trajectory (every compensation term and the tracked row from the "
        "truth: what the trajectory leaves to the inversion itself); the true road's RMS at "
        "the same bins is the error's scale (an estimate of 0 would score it). 'ego accel': "
        "the correlation of the ego's vertical acceleration predicted from the previewed road "
        "under its front axle (the nominal quarter car) with the one the simulator's ego had. "
        "Road classes A-C are the target (<= 15 mm); the generalization suite is reported "
        "apart (never tuned on; the preview has no tuned parameter)."
    )
    w("")
    header = [
        "",
        "drives",
        "RMS error (mm)",
        "profile alone",
        "on the true trajectory",
        "true road RMS",
        "ego accel (median r)",
    ]
    rows = []
    for ds, label in (("wild", "wild"), ("generalization", "**generalization suite**")):
        x = p.get(ds) or {}
        for part, name in (("target", "A-C"), ("rough", "D-E")):
            t = x.get(part) or {}
            if not t.get("bins"):
                continue
            rows.append(
                [
                    f"{label}, class {name}",
                    _int(t.get("drives")),
                    num(t.get("rms_mm"), ".1f"),
                    num(t.get("rms_alone_mm"), ".1f"),
                    num(t.get("rms_true_trajectory_mm"), ".1f"),
                    num(t.get("true_rms_mm"), ".1f"),
                    num(t.get("accel_correlation_median")),
                ]
            )
    w(md_table(header, rows))
    w("")
    drives = (p.get("generalization") or {}).get("drives") or {}
    if drives:
        w("Per drive of the generalization suite:")
        w("")
        w(
            md_table(
                [
                    "drive",
                    "class",
                    "RMS error (mm)",
                    "profile alone",
                    "true road RMS",
                    "ego accel r",
                ],
                [
                    [
                        n,
                        x.get("road_class") or "–",
                        num(x.get("rms_mm"), ".1f"),
                        num(x.get("rms_alone_mm"), ".1f"),
                        num(x.get("true_rms_mm"), ".1f"),
                        num(x.get("accel_correlation")),
                    ]
                    for n, x in drives.items()
                ],
            )
        )
        w("")
