"""The evaluation on the console: Table I as aligned plain text and the headline figures
(``roadpreview evaluate`` prints them when the run is done)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from roadpreview.eval.report.tables import (
    TABLE1_SUBSETS,
    num,
    table1_header,
    table1_rows,
)


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
                f"fused-kalman: F-max threshold {num(fk['threshold_f_max_px'])} px on the whole "
                f"set (folds {', '.join(num(v) for v in fk['fold_thresholds_px'])}); "
                "default 1.0 px"
            )
        for det, r in (res["e4"].get("detectors") or {}).items():
            fk = (r.get("methods") or {}).get("fused-kalman")
            if fk:
                sub = fk.get("subsets") or {}
                lines.append(
                    f"{det} detector, fused-kalman AUC: entire "
                    f"{num((sub.get('entire') or {}).get('auc'))}, hard "
                    f"{num((sub.get('hard') or {}).get('auc'))}"
                )
    if "e1" in res:
        for m in ("uncompensated", "fused-kalman"):
            r = res["e1"]["methods"].get(m)
            if r:
                lines.append(
                    f"E1 {m}: s(d) = {num(r['alpha'])}·fδ/d + {num(r['beta'])} "
                    f"(R² {num(r['r2'])}), separates up to "
                    f"{num(r['separation_distance_m'], '.1f')} m"
                )
    if "e5" in res:
        tl = res["e5"]["texture_loss"]["methods"]
        parts = [
            f"{m} {num(tl[m]['pitch_rms_hp_inside_deg'], '.3f')}"
            for m in ("visual", "fused-kalman", "fused-fg")
            if m in tl
        ]
        lines.append("E5 pitch error in low texture (deg, 1 s high-pass RMS): " + ", ".join(parts))
        for size, r in res["e5"]["range"]["sizes"].items():
            fk = r["methods"].get("fused-kalman")
            if fk:
                more = "+" if fk["range_open"] else ""
                lines.append(f"E5 range {size} (fused-kalman): {num(fk['range_m'], '.0f')}{more} m")
    lines.append(f"wall time {d['timing']['wall_s']:.0f} s")
    return "\n".join(lines)
