"""``roadpreview evaluate --quick`` end to end: the orderings the method predicts where
they are clear, the s(d) fit, and the report.

The quick configuration is small by design (a few short drives at 640x360); the
orderings checked here are the ones its data set makes clear, not the full
evaluation's numbers.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest

from roadpreview.cli.main import main
from roadpreview.eval.report.markdown import render

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def quick(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("evaluate-quick")
    report = root / "docs" / "evaluation.md"
    rc = main(["evaluate", "--quick", "--out", str(root / "run"), "--report", str(report)])
    assert rc == 0
    results = json.loads((root / "run" / "results.json").read_text())
    return {"root": root, "report": report, "results": results}


def test_compensation_beats_no_compensation_on_the_hard_subset(quick: dict[str, Any]) -> None:
    e4 = quick["results"]["results"]["e4"]
    hard = {m: r["subsets"]["hard"] for m, r in e4["methods"].items()}
    assert hard["uncompensated"]["n_pos"] > 0
    assert hard["uncompensated"]["n_neg"] > 0
    best_compensated = max(hard["fused-kalman"]["auc"], hard["visual"]["auc"])
    assert best_compensated > hard["uncompensated"]["auc"]


def test_fused_beats_visual_only_when_texture_is_lost(quick: dict[str, Any]) -> None:
    tl = quick["results"]["results"]["e5"]["texture_loss"]["methods"]
    # the gyro bridges fog, tunnel and night; the visual chain holds its last value
    # (what the 1 s detector window sees)
    for fused in ("fused-kalman", "fused-fg"):
        assert tl[fused]["pitch_rms_hp_inside_deg"] < tl["visual"]["pitch_rms_hp_inside_deg"]
    # and the drift over each segment, for the better of the two back ends
    best = min(tl[m]["pitch_rms_aligned_inside_deg"] for m in ("fused-kalman", "fused-fg"))
    assert best < tl["visual"]["pitch_rms_aligned_inside_deg"]


def test_signal_falls_with_distance(quick: dict[str, Any]) -> None:
    e1 = quick["results"]["results"]["e1"]["methods"]
    for m in ("fused-kalman", "visual", "uncompensated"):
        assert e1[m]["alpha"] > 0, m
    # on the smooth controlled road the compensated fit explains the crossings well
    assert e1["fused-kalman"]["r2"] > 0.5


def test_report_has_table1_and_figures(quick: dict[str, Any]) -> None:
    report: Path = quick["report"]
    text = report.read_text()
    assert "QUICK CONFIGURATION" in text
    assert "## E4: the paper's Table I" in text
    labels = {m["label"] for m in quick["results"]["methods"].values()}
    assert len(labels) == 7  # the paper's four, the gyro with the fusion's estimates, ours two
    table_lines = [line for line in text.splitlines() if line.startswith("| ")]
    for label in labels:
        assert any(line.startswith(f"| {label} |") for line in table_lines), label
    figures = sorted((report.parent / "eval").glob("*.png"))
    names = {f.name for f in figures}
    assert {
        "e1_signal_vs_distance.png",
        "e2_ego_bump.png",
        "e3_fpr_vs_rotation.png",
        "e4_roc.png",
        "e5_texture_loss.png",
        "e5_range.png",
        "e5_lead_time.png",
    } <= names
    for name in names:
        assert f"](eval/{name})" in text, name


def test_report_has_every_detector_and_the_product(quick: dict[str, Any]) -> None:
    text = quick["report"].read_text()
    res = quick["results"]["results"]
    table_lines = [line for line in text.splitlines() if line.startswith("| ")]
    detectors = res["e4"]["detectors"]
    assert detectors
    assert "### Every detector side by side" in text
    for label in {m["label"] for m in quick["results"]["methods"].values()}:
        for det in ("std", *detectors):
            assert any(line.startswith(f"| {label} / {det} |") for line in table_lines), (
                label,
                det,
            )
    assert "e6" in res
    for heading in (
        "## E6: the product at its operating point",
        "### Operating points (held-out folds)",
        "### At the configured thresholds",
        "### SVAR-like subset",
        "### Height",
        "### Ego confirmation",
        "### Road class",
        "### Generalization suite",
    ):
        assert heading in text, heading
    # E6 comes after E5, and the product's reliability diagram is linked
    assert text.index("## E5: beyond the paper") < text.index("## E6:")
    if res["e6"]["product_detector"] == "two-axle":
        assert "### Alert confidence" in text
        fig = res["e6"]["reliability_figure"]
        assert (quick["report"].parent / "eval" / fig).is_file()
        assert f"](eval/{fig})" in text


def test_report_has_the_error_budget(quick: dict[str, Any]) -> None:
    """E7: the product's budget on the wild set, each variant a row; with every term true
    the residual is 0 (the truth wherever the product had a lead); every method's pitch
    error; E2's ego-only crossings."""
    text = quick["report"].read_text()
    res = quick["results"]["results"]
    e7 = res["e7"]
    rows = e7["budgets"]["wild"]["fused-kalman"]["rows"]
    assert set(rows) == {"product", "pitch only", "+ pitch + heave + distance + tracking"}
    full = rows["+ pitch + heave + distance + tracking"]
    assert full["r_std_px"][1] == pytest.approx(0.0, abs=1e-6)
    assert rows["product"]["r_std_px"][0] > 0.0
    assert 0.0 <= rows["product"]["auc"]["two-axle"]["entire"] <= 1.0
    assert "fused-kalman" in e7["pitch"]["wild"]
    assert "## E7: the compensation's error budget" in text
    assert "### wild: ours fused (Kalman)" in text
    eo = res["e2"]["ego_only"]
    assert eo is not None
    assert "### The ego's own anomalies, every ego-only crossing" in text


def test_report_has_the_alert_timing_and_the_preview(quick: dict[str, Any]) -> None:
    """Issue 27: per hit the latency of the first RP_ALERT (never later than the
    confirmation) and the lead time; the provisional operating point beside the confirmed
    one, whose recall and false alarms the provisional stage leaves as they are; the road
    preview against the true road, in millimetres of a road."""
    text = quick["report"].read_text()
    e6 = quick["results"]["results"]["e6"]
    p = e6["provisional"]
    shipped, without = p["wild_shipped"], p["wild_without"]
    assert (shipped["hits"], shipped["false_alarms"]) == (
        without["hits"],
        without["false_alarms"],
    )
    if shipped["hits"]:
        assert shipped["latency_median_s"] <= shipped["latency_confirmed_median_s"] + 1e-9
    assert shipped["provisional_fa_per_min"] >= 0.0
    assert len(p["curve"]) >= 2
    # a lower threshold never sends fewer provisional alerts
    counts = [c["provisional"] for c in p["curve"]]
    assert counts == sorted(counts, reverse=True)
    assert "### Alert timing and provisional alerts" in text
    pv = e6["preview"]["wild"]
    bins = [x for x in pv["drives"].values() if x["bins"]]
    assert bins, "the quick wild drives have previewed bins"
    for x in bins:
        assert 0.0 < x["rms_mm"] < 100.0
        assert 0.0 < x["true_rms_mm"] < 100.0
    assert "### Road preview (RP_PREVIEW)" in text


def test_report_renders_without_the_new_blocks(quick: dict[str, Any]) -> None:
    data = copy.deepcopy(quick["results"])
    e6 = data["results"]["e6"]
    for key in ("calibration", "reliability_figure", "svar", "generalization", "provisional"):
        e6.pop(key, None)
    e6.pop("preview", None)
    e6["operating_points"]["detectors"]["std"]["fused-kalman"]["held_out"]["1"] = None
    text = render(data)
    assert "## E6: the product at its operating point" in text
    assert "### Alert confidence" not in text
    del data["results"]["e6"]
    del data["results"]["e4"]["detectors"]
    text = render(data)
    assert "## E6:" not in text
    assert "### Every detector side by side" not in text
    assert "## E4: the paper's Table I" in text


def test_a_second_run_reuses_everything(
    quick: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    run = quick["root"] / "run"
    rc = main(["evaluate", "--quick", "--out", str(run), "--experiments", "e4", "--jobs", "1"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "cached" in out
    assert "simulated" not in out
    assert "Table I" in out


def test_bad_experiment_name_is_a_clear_error(capsys: pytest.CaptureFixture[str]) -> None:
    rc = main(["evaluate", "--quick", "--experiments", "e9"])
    assert rc == 1
    assert "e9" in capsys.readouterr().err
