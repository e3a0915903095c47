"""E7's section of the report: the compensation's error budget."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from roadpreview.eval.report.tables import md_table, method_label, num


def _pair(x: Any, fmt: str = ".2f") -> str:
    if not x:
        return "–"
    return f"{num(x[0], fmt)} / {num(x[1], fmt)}"


def _auc(row: Mapping[str, Any], det: str) -> str:
    a = (row.get("auc") or {}).get(det)
    if not a:
        return "–"
    return f"{num(a.get('entire'), '.3f')} / {num(a.get('hard'), '.3f')}"


def _recall(t: Mapping[str, Any] | None) -> str:
    if not t:
        return "–"
    return f"{num(t.get('recall'), '.2f')} ({num(t.get('fa_per_min'), '.2f')}/min)"


def e7_section(d: Mapping[str, Any], w: Any) -> None:
    e7 = d["results"]["e7"]
    w("## E7: the compensation's error budget")
    w("")
    w(
        "The residual r = y_c - y_c,true per frame, y_c,true the true compensated row (the "
        "rendered row of the lead's rear centre less the true pitch and heave terms, as the "
        "ceiling's). Each input of the product's y_c = y - f tan φ - f Δz / d is replaced by the "
        "simulator's truth, one at a time ('… only') and cumulatively ('+ …'): the pitch φ, "
        "the heave Δz, the lead distance d of the heave term, and the lead's tracked row y (the "
        "grid's mean row -> the lead's rear centre). With all four, r is 0 wherever the product "
        "had a lead (frames without one stay without). Per variant: the 1 s-window std of r "
        "(detrended as the detector's s), median / 95th percentile over the frames, in px at "
        "the drive's resolution and in mrad; each detector's AUC entire / hard on the wild "
        "clips; the product detector's recall of anomalies with f|δ|/d >= 1 px at <= 0.5 false "
        "alarms per minute on the held-out folds (thresholds chosen on the training folds), "
        "and at the shipped threshold (`experiments.budget`). A term's cost: the AUC the "
        "variant with only that term true gains over the product."
    )
    w("")
    for dataset, per_method in (e7.get("budgets") or {}).items():
        for m, b in per_method.items():
            rows = b["rows"]
            w(f"### {dataset}: {method_label(d, m)}")
            w("")
            costs = b.get("costs", {}).get("two-axle") or {}
            detected = any((r.get("auc") or r.get("at_shipped")) for r in rows.values())
            if detected and costs:
                order = b.get("largest") or []
                w(
                    "Largest terms (two-axle AUC, entire): "
                    + ", ".join(f"**{t}** {num(costs.get(t), '+.3f')}" for t in order)
                    + "."
                )
                w("")
            header = ["variant", "std r (px)", "std r (mrad)"]
            if detected:
                header += [
                    "two-axle AUC",
                    "std AUC",
                    "recall held out, <= 0.5 FA/min",
                    "recall at shipped threshold",
                ]
            table = []
            for name, r in rows.items():
                line = [name, _pair(r["r_std_px"]), _pair(r["r_std_mrad"], ".3f")]
                if detected:
                    line += [
                        _auc(r, "two-axle"),
                        _auc(r, "std"),
                        _recall(r.get("recall_held_out")),
                        _recall(r.get("at_shipped")),
                    ]
                table.append(line)
            w(md_table(header, table))
            w("")
    pitch = e7.get("pitch") or {}
    if pitch:
        w("### Pitch error per method")
        w("")
        w(
            "The detrended 1 s std of each method's pitch error (φ - the true camera pitch; a "
            "constant offset and a linear drift within the second do not count: the detector "
            "does not see them), median / 95th percentile over the frames, in degrees. "
            "'IMU with the fusion's bias and offset' is the gyro alone, integrated with the bias "
            "and camera-IMU offset that the Kalman fusion estimates (the `imu-estimated` back "
            "end); 'IMU only' is the paper's raw integration (bias 0, offset 0)."
        )
        w("")
        sets = list(pitch)
        methods = list(dict.fromkeys(m for ds in sets for m in pitch[ds]))
        rows = [
            [method_label(d, m), *(_pair(pitch[ds].get(m), ".4f") for ds in sets)]
            for m in methods
        ]
        w(md_table(["method", *(f"{ds} (deg)" for ds in sets)], rows))
        w("")
