"""The fleet report of a batch: ``report.md`` and ``report.png``.

`fleet_figures` pools the drives' outcomes into the fleet's figures (`FleetFigures`);
`write_report` writes them with a row per drive, the failed drives and their messages,
and, where the drives were matched to truth, the pooled detection and false-alarm
figures.

Pooling: the fleet's figures count the drives that did not fail (``done`` and
``skipped``: a skipped drive's figures are its earlier run's); a failed drive is listed
with its message, not pooled. Rates are ratios of sums (the fleet's alerts over the
fleet's kilometres), not means of the drives' rates, so that a short drive weighs what
it drove; the mode shares are weighted by the drives' durations. Each rate pools only
the drives that have its denominator (a drive without a speed input has no distance).
NaN: undefined (nothing to pool).

The figure keeps its per-drive panels legible for hundreds of drives: at most
`MAX_BARS` drives a panel (the ones with the most alerts per km; for the truth panel,
the most misses and false alarms), as its title says.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, cast

from roadpreview.batch.outcome import MODES, DriveOutcome
from roadpreview.batch.tables import TABLE_FILES, write_atomically

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

#: at most this many drives in a per-drive panel of the figure
MAX_BARS = 40

#: the files `write_report` writes
REPORT_MD = "report.md"
REPORT_PNG = "report.png"

#: a fusion mode's colour in the figure
MODE_COLORS = {
    "FUSED": "tab:green",
    "VISUAL_ONLY": "tab:blue",
    "IMU_ONLY": "tab:orange",
    "DEGRADED": "tab:red",
}

#: a drive's id in the figure is cut to this many characters
_LABEL_CHARS = 28


# -- the fleet's figures --------------------------------------------------------------------
@dataclass(frozen=True)
class FleetFigures:
    """The fleet's pooled figures (module docstring). NaN: undefined."""

    drives: int  #: outcomes given
    done: int
    skipped: int
    failed: int
    duration_h: float  #: drive time of the drives with a duration, h
    distance_km: float  #: distance of the drives with a distance, km
    drives_with_distance: int
    alerts: int  #: alerts of the drives that did not fail
    alerts_per_km: float  #: over the drives with a distance
    alerts_per_hour: float  #: over the drives with a duration
    #: share of the fleet's time in each fusion mode (`MODES`), weighted by duration, 0..1
    mode_shares: dict[str, float]
    truth_drives: int  #: drives matched to truth
    truth_expected: float  #: true events, summed over them
    truth_hits: float  #: true events alerted
    recall: float  #: hits / expected
    false_alarms: float
    truth_minutes: float  #: drive time of the truth drives with a duration, min
    false_alarms_per_min: float  #: over the truth drives with a duration

    @property
    def has_truth(self) -> bool:
        return self.truth_drives > 0


def _finite(x: float | None) -> bool:
    return x is not None and math.isfinite(x)


def _ratio(num: float, den: float) -> float:
    return num / den if den > 0 else math.nan


def _sum_or_nan(values: Sequence[float]) -> float:
    """The sum; NaN when there is nothing to sum (unknown, not zero)."""
    return math.fsum(values) if values else math.nan


def fleet_figures(outcomes: Iterable[DriveOutcome]) -> FleetFigures:
    """Pool the outcomes into the fleet's figures (module docstring: what is pooled how)."""
    outcomes = list(outcomes)
    ok = [o for o in outcomes if o.ok]
    timed = [o for o in ok if _finite(o.duration_s) and o.duration_s >= 0]
    located = [o for o in ok if _finite(o.distance_km) and o.distance_km >= 0]
    hours = _sum_or_nan([o.duration_s / 3600.0 for o in timed])
    km = _sum_or_nan([o.distance_km for o in located])

    weighted = [o for o in timed if o.modes and o.duration_s > 0]
    total_s = math.fsum(o.duration_s for o in weighted)
    shares = {
        m: _ratio(math.fsum(o.duration_s * o.modes.get(m, 0.0) for o in weighted), total_s)
        for m in MODES
    }

    truths = [o.truth for o in ok if o.truth is not None]
    expected = _sum_or_nan([t.get("expected", 0.0) for t in truths])
    hits = _sum_or_nan([t.get("hits", 0.0) for t in truths])
    false_alarms = _sum_or_nan([t.get("false_alarms", 0.0) for t in truths])
    timed_truths = [t for t in truths if _finite(t.get("minutes")) and t["minutes"] > 0]
    minutes = _sum_or_nan([t["minutes"] for t in timed_truths])
    return FleetFigures(
        drives=len(outcomes),
        done=sum(o.status == "done" for o in outcomes),
        skipped=sum(o.status == "skipped" for o in outcomes),
        failed=sum(o.status == "failed" for o in outcomes),
        duration_h=hours,
        distance_km=km,
        drives_with_distance=len(located),
        alerts=sum(o.alerts for o in ok),
        alerts_per_km=_ratio(sum(o.alerts for o in located), km),
        alerts_per_hour=_ratio(sum(o.alerts for o in timed), hours),
        mode_shares=shares,
        truth_drives=len(truths),
        truth_expected=expected,
        truth_hits=hits,
        recall=_ratio(hits, expected),
        false_alarms=false_alarms,
        truth_minutes=minutes,
        false_alarms_per_min=_ratio(
            math.fsum(t.get("false_alarms", 0.0) for t in timed_truths), minutes
        ),
    )


def _misses(o: DriveOutcome) -> float:
    t = o.truth or {}
    return max(t.get("expected", 0.0) - t.get("hits", 0.0), 0.0)


def _by_alert_rate(outcomes: Sequence[DriveOutcome], n: int) -> list[DriveOutcome]:
    """The ``n`` drives with the most alerts per km (then per hour: the drives without a
    distance come last), most first."""

    def key(o: DriveOutcome) -> tuple[float, float, str]:
        per_km, per_h = o.alerts_per_km, o.alerts_per_hour
        return (
            -per_km if _finite(per_km) else math.inf,
            -per_h if _finite(per_h) else math.inf,
            o.drive,
        )

    return sorted(outcomes, key=key)[:n]


def _by_truth_errors(outcomes: Sequence[DriveOutcome], n: int) -> list[DriveOutcome]:
    """The ``n`` truth drives with the most misses plus false alarms, most first."""

    def key(o: DriveOutcome) -> tuple[float, str]:
        t = o.truth or {}
        return (-(_misses(o) + t.get("false_alarms", 0.0)), o.drive)

    return sorted(outcomes, key=key)[:n]


# -- Markdown -------------------------------------------------------------------------------
def _num(x: float | None, digits: int = 1) -> str:
    return f"{x:.{digits}f}" if _finite(x) else "—"


def _count(x: float | None) -> str:
    return f"{x:g}" if _finite(x) else "—"


def _pct(x: float | None) -> str:
    return f"{100.0 * x:.0f} %" if x is not None and _finite(x) else "—"


def _cell(text: object) -> str:
    """Text for a Markdown table cell: one line, no column breaks."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _table(header: Sequence[str], rows: Iterable[Sequence[object]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines


def _errors(o: DriveOutcome) -> str:
    parts = [
        f"{n} {what}"
        for n, what in (
            (o.decode_failures, "decode"),
            (o.input_errors, "input"),
            (o.unusable_inputs, "unusable"),
        )
        if n
    ]
    return ", ".join(parts) or "0"


def report_markdown(
    outcomes: Sequence[DriveOutcome],
    figures: FleetFigures,
    *,
    title: str = "Fleet replay",
    notes: Sequence[str] = (),
) -> str:
    """The text of ``report.md``: the headline figures, a row per drive (in the order
    given), the failed drives with their messages, the pooled truth figures (when there
    are), the notes, and links to the figure and the tables."""
    f = figures
    lines = [f"# {title}", "", "## Fleet", ""]
    head: list[tuple[str, str]] = [
        ("drives", f"{f.drives} ({f.done} done, {f.skipped} skipped, {f.failed} failed)"),
        ("drive time (h)", _num(f.duration_h, 2)),
        ("distance (km)", f"{_num(f.distance_km, 2)} ({f.drives_with_distance} drives)"),
        ("alerts", str(f.alerts)),
        ("alerts per km", _num(f.alerts_per_km, 2)),
        ("alerts per hour", _num(f.alerts_per_hour, 1)),
    ]
    head += [(f"time in {m}", _pct(f.mode_shares.get(m))) for m in MODES]
    if f.has_truth:
        head += [
            ("recall (pooled)", _pct(f.recall)),
            ("false alarms per minute (pooled)", _num(f.false_alarms_per_min, 3)),
        ]
    lines += _table(("figure", "value"), head)

    lines += ["", "## Drives", ""]
    lines += _table(
        (
            "drive",
            "status",
            "frames",
            "duration (min)",
            "km",
            "alerts",
            "alerts/km",
            "alerts/h",
            "FUSED",
            "road class",
            "errors",
        ),
        (
            (
                o.drive,
                o.status,
                o.frames,
                _num(o.duration_s / 60.0, 1),
                _num(o.distance_km, 2),
                o.alerts,
                _num(o.alerts_per_km, 2),
                _num(o.alerts_per_hour, 1),
                _pct(o.modes.get("FUSED", 0.0)) if o.modes else "—",
                o.road_class or "—",
                _errors(o),
            )
            for o in outcomes
        ),
    )

    lines += ["", "## Failed drives", ""]
    failed = [o for o in outcomes if o.status == "failed"]
    lines += [f"- **{_cell(o.drive)}**: {_cell(o.message or '(no message)')}" for o in failed]
    if not failed:
        lines.append("none")

    if f.has_truth:
        lines += ["", "## Detection against truth (pooled)", ""]
        lines += _table(
            ("figure", "value"),
            (
                ("drives with truth", f.truth_drives),
                ("true events", _count(f.truth_expected)),
                ("hits", _count(f.truth_hits)),
                ("recall", _pct(f.recall)),
                ("false alarms", _count(f.false_alarms)),
                ("drive time (min)", _num(f.truth_minutes, 1)),
                ("false alarms per minute", _num(f.false_alarms_per_min, 3)),
            ),
        )

    if notes:
        lines += ["", "## Notes", ""]
        lines += [f"- {' '.join(n.split())}" for n in notes]

    lines += ["", "## Files", "", f"![fleet figure]({REPORT_PNG})", ""]
    lines += [f"- [{name}]({name})" for name in TABLE_FILES]
    return "\n".join(lines) + "\n"


# -- the figure -----------------------------------------------------------------------------
def _label(drive: str) -> str:
    return drive if len(drive) <= _LABEL_CHARS else drive[: _LABEL_CHARS - 3] + "..."


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _caption(what: str, shown: int, total: int, order: str) -> str:
    if shown < total:
        return f"{what}\n(the {shown} of {total} drives with the most {order})"
    return what


def _empty(ax: Axes, title: str, text: str) -> None:
    ax.set_title(title, fontsize=9)
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")
    ax.set_axis_off()


def _rows(ax: Axes, labels: Sequence[str]) -> list[int]:
    """Horizontal-bar rows, the first label at the top."""
    ys = list(range(len(labels)))
    ax.set_yticks(ys, [_label(s) for s in labels], fontsize=7)
    ax.set_ylim(len(labels) - 0.5, -0.5)
    return ys


def _legend_below(ax: Axes, *, ncol: int) -> None:
    """The legend under the x axis' label (a fixed offset in points, whatever the
    figure's height)."""
    from matplotlib.transforms import offset_copy

    # our axes sit on a Figure (`_plot`), never a SubFigure
    fig = cast("Figure", ax.figure)
    below = offset_copy(ax.transAxes, fig=fig, y=-34.0, units="points")
    ax.legend(
        fontsize=7,
        ncol=ncol,
        loc="upper center",
        bbox_to_anchor=(0.5, 0.0),
        bbox_transform=below,
        frameon=False,
    )


def _panel_rates(ax: Axes, shown: Sequence[DriveOutcome], total: int) -> None:
    """(a) Alerts per km per drive; a drive without a distance gets its rate per hour
    written in place of its bar."""
    title = _caption("(a) alerts per km", len(shown), total, "alerts per km")
    if not shown:
        _empty(ax, title, "no drive completed")
        return
    ys = _rows(ax, [o.drive for o in shown])
    rates = [o.alerts_per_km if _finite(o.alerts_per_km) else 0.0 for o in shown]
    ax.barh(ys, rates, color="tab:purple", height=0.7)
    for y, o in zip(ys, shown, strict=True):
        if not _finite(o.alerts_per_km):
            text = "no distance"
            if _finite(o.alerts_per_hour):
                text += f": {o.alerts_per_hour:.1f} alerts/h"
            ax.text(0.0, y, " " + text, va="center", fontsize=7, color="0.35", style="italic")
    ax.set_xlim(0.0, max(max(rates) * 1.1, 1.0))
    ax.set_xlabel("alerts per km")
    ax.set_title(title, fontsize=9)
    ax.grid(axis="x", alpha=0.3)


def _panel_modes(
    ax: Axes, shown: Sequence[DriveOutcome], figures: FleetFigures, total: int
) -> None:
    """(b) Share of time in each fusion mode: the fleet's (top row), then the drives of
    panel (a)."""
    title = _caption("(b) time in each fusion mode", len(shown), total, "alerts per km")
    if not shown:
        _empty(ax, title, "no drive completed")
        return
    labels = ["FLEET", *(o.drive for o in shown)]
    ys = _rows(ax, labels)
    table = [figures.mode_shares, *(o.modes for o in shown)]
    left = [0.0] * len(labels)
    for m in MODES:
        widths = [s.get(m, 0.0) if _finite(s.get(m)) else 0.0 for s in table]
        ax.barh(ys, widths, left=left, height=0.7, color=MODE_COLORS.get(m), label=m)
        left = [a + b for a, b in zip(left, widths, strict=True)]
    ax.get_yticklabels()[0].set_fontweight("bold")
    ax.set_xlim(0.0, 1.0)
    ax.set_xlabel("share of drive time")
    ax.set_title(title, fontsize=9)
    _legend_below(ax, ncol=len(MODES))


def _panel_truth(ax: Axes, shown: Sequence[DriveOutcome], total: int) -> None:
    """(c) Hits, misses and false alarms per truth drive, stacked."""
    title = _caption("(c) against truth", len(shown), total, "misses and false alarms")
    ys = _rows(ax, [o.drive for o in shown])
    hits = [(o.truth or {}).get("hits", 0.0) for o in shown]
    misses = [_misses(o) for o in shown]
    fas = [(o.truth or {}).get("false_alarms", 0.0) for o in shown]
    left = [0.0] * len(shown)
    for values, color, name in (
        (hits, "tab:green", "hits"),
        (misses, "tab:orange", "misses"),
        (fas, "tab:red", "false alarms"),
    ):
        ax.barh(ys, values, left=left, height=0.7, color=color, label=name)
        left = [a + b for a, b in zip(left, values, strict=True)]
    ax.set_xlim(0.0, max([*left, 1.0]) * 1.05)
    ax.set_xlabel("events")
    ax.set_title(title, fontsize=9)
    _legend_below(ax, ncol=3)


def _plot(outcomes: Sequence[DriveOutcome], figures: FleetFigures, title: str, path: Path) -> None:
    """Draw ``report.png`` into ``path`` (Agg, no pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ok = [o for o in outcomes if o.ok]
    shown = _by_alert_rate(ok, MAX_BARS)
    truth = [o for o in ok if o.truth is not None]
    truth_shown = _by_truth_errors(truth, MAX_BARS)
    panels = 3 if truth else 2
    rows = max(len(shown) + 1, len(truth_shown), 6)
    fig = Figure(figsize=(5.5 * panels, 2.0 + 0.22 * rows), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, panels, squeeze=False)[0]
    _panel_rates(axes[0], shown, len(ok))
    _panel_modes(axes[1], shown, figures, len(ok))
    if truth:
        _panel_truth(axes[2], truth_shown, len(truth))
    fig.suptitle(
        f"{title}: {_plural(figures.drives, 'drive')} ({figures.done} done,"
        f" {figures.skipped} skipped, {figures.failed} failed),"
        f" {_plural(figures.alerts, 'alert')}",
        fontsize=10,
    )
    fig.savefig(path, format="png", dpi=100)


def _write_text(text: str, path: Path) -> None:
    path.write_text(text, encoding="utf-8")


def write_report(
    outcomes: Iterable[DriveOutcome],
    out: Path,
    *,
    title: str = "Fleet replay",
    notes: Sequence[str] = (),
) -> tuple[Path, Path]:
    """Write ``report.md`` and ``report.png`` into ``out`` (created if needed), each
    under a temporary name first; returns their paths (Markdown, PNG). Drives are listed
    by id; ``notes``: lines added to the report as they are."""
    ordered = sorted(outcomes, key=lambda o: o.drive)
    figures = fleet_figures(ordered)
    out.mkdir(parents=True, exist_ok=True)
    png = write_atomically(out / REPORT_PNG, partial(_plot, ordered, figures, title))
    text = report_markdown(ordered, figures, title=title, notes=notes)
    md = write_atomically(out / REPORT_MD, partial(_write_text, text))
    return md, png


__all__ = [
    "MAX_BARS",
    "REPORT_MD",
    "REPORT_PNG",
    "FleetFigures",
    "fleet_figures",
    "report_markdown",
    "write_report",
]
