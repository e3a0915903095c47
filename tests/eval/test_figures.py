"""The figures draw from the experiments' results alone (no data, no files but the PNG)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from roadpreview.eval import figures
from roadpreview.eval.experiments.detection_range import DetectionRange, RangeOfSize, RangeRow
from roadpreview.eval.experiments.lead_time import LeadTime, LeadTimeRow
from roadpreview.eval.experiments.signal_distance import GapRow, SignalFit, SignalVsDistance


def test_figures_are_written_from_results(tmp_path: Path) -> None:
    fit = SignalFit(
        alpha=0.5,
        beta=0.2,
        r2=0.9,
        background_p99_pooled=0.4,
        separation_distance_m=20.0,
        per_gap=(GapRow(10.0, 11.0, (2.0, 1.8), 0.4, 0.2, 300, True),),
        d=(11.0, 11.5),
        s=(2.0, 1.8),
    )
    e1 = SignalVsDistance(focal_px=1000.0, size=(1920, 1080), delta_m=0.06, methods={"visual": fit})
    assert figures.plot_signal_vs_distance(e1, tmp_path / "e1.png") == "e1.png"
    row = RangeRow(1.0, 0.1, (1.0, math.nan), (3, 0), 40.0, True)
    rng = DetectionRange(
        bins_m=(0.0, 20.0, 40.0), sizes={"640x360": RangeOfSize(2, 3, 9, 1, {"fused-kalman": row})}
    )
    figures.plot_range(rng, tmp_path / "range.png")
    lt = LeadTime({"fused-kalman": LeadTimeRow(2, 3, 1, 2.0, (1.5, 2.0))})
    assert lt.as_dict()["methods"]["fused-kalman"]["recall"] == 2 / 3
    figures.plot_lead_time(lt, tmp_path / "lead.png")
    for name in ("e1.png", "range.png", "lead.png"):
        png = (tmp_path / name).read_bytes()
        assert png.startswith(b"\x89PNG")
        assert len(png) > 1000
    assert np.isnan(row.recall[1])
    assert rng.as_dict()["sizes"]["640x360"]["methods"]["fused-kalman"]["recall"] == [1.0, None]
