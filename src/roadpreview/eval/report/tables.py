"""What the report's tables share: cell formats (a number, mean ± std, missing values as
"–"), Markdown tables, the labels of methods and detectors, and Table I's rows (Markdown
and console alike)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

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
#: Table I's last row: the true compensated trajectory (`experiments.ceiling_scores`)
CEILING_LABEL = "truth-compensated y (ceiling, not a method)"


def num(v: Any, fmt: str = ".2f") -> str:
    """A number in ``fmt``; "–" for None, NaN or inf."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, fmt)


def pm(mean: Any, std: Any) -> str:
    """mean ± std (the std left out when None); "–" without a mean."""
    if mean is None:
        return "–"
    return f"{mean:.2f} ± {std:.2f}" if std is not None else f"{mean:.2f}"


def compact(x: Any) -> str:
    """A settings mapping on one line (JSON without spaces)."""
    return json.dumps(x, separators=(",", ":"), default=str)


def md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table of already formatted cells."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def method_label(d: Mapping[str, Any], m: str) -> str:
    """How the report names method ``m`` (its label in ``results.json``, or the ceiling)."""
    if m == "ceiling":
        return CEILING_LABEL
    return str(d["methods"][m]["label"])


def detector_label(det: str) -> str:
    """How the report names a detector of the registry."""
    return DETECTOR_LABELS.get(det, det)


def table1_cells(r: Mapping[str, Any], subsets: Sequence[str]) -> list[str]:
    """BA, F and AUC of each subset of one Table I row (``{"subsets": {...}}``)."""
    row: list[str] = []
    for sub in subsets:
        s = (r.get("subsets") or {}).get(sub)
        if s is None:
            row += ["–", "–", "–"]
            continue
        row += [pm(s["ba_mean"], s["ba_std"]), pm(s["f_mean"], s["f_std"]), num(s["auc"])]
    return row


def table1_rows(d: Mapping[str, Any], subsets: Sequence[str] = TABLE1_SUBSETS) -> list[list[str]]:
    e4 = d["results"]["e4"]["methods"]
    rows = [[method_label(d, m), *table1_cells(r, subsets)] for m, r in e4.items()]
    ceiling = d["results"]["e4"].get("ceiling")
    if ceiling is not None:
        rows.append([CEILING_LABEL, *table1_cells(ceiling, subsets)])
    return rows


def table1_head(
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
    return table1_head(d["results"]["e4"]["methods"], subsets)
