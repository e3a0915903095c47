"""Folds and cross-validation: stratification, groups, no test-fold leakage, known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roadpreview.errors import InputDataError
from roadpreview.eval.cv import ENTIRE, cross_validate, stratified_group_folds
from roadpreview.eval.metrics import auc, best_f_threshold, confusion


def _labels(n_pos: int, n_neg: int, seed: int = 0) -> np.ndarray:
    y = np.r_[np.ones(n_pos, int), np.zeros(n_neg, int)]
    return np.random.default_rng(seed).permutation(y)


def _assert_partition(folds: list[np.ndarray], n: int, k: int) -> None:
    assert len(folds) == k
    assert all(len(f) > 0 for f in folds)
    assert all(np.all(np.diff(f) > 0) for f in folds)  # sorted, no repeats
    everything = np.concatenate(folds)
    assert len(everything) == n  # disjoint ...
    np.testing.assert_array_equal(np.sort(everything), np.arange(n))  # ... and covering


# --- folds without groups -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("n_pos", "n_neg", "k"),
    [(10, 10, 5), (13, 41, 5), (3, 50, 5), (7, 2, 3), (25, 0, 4), (4, 9, 2)],
)
def test_folds_partition_and_stratify(n_pos: int, n_neg: int, k: int) -> None:
    y = _labels(n_pos, n_neg)
    folds = stratified_group_folds(y, k=k, seed=3)
    _assert_partition(folds, len(y), k)
    for f in folds:
        assert abs(int(y[f].sum()) - n_pos / k) < 1  # floor or ceil of n_pos / k
        assert abs(int((y[f] == 0).sum()) - n_neg / k) < 1
    sizes = [len(f) for f in folds]
    assert max(sizes) - min(sizes) <= 1


def test_folds_are_deterministic_per_seed() -> None:
    y = _labels(20, 60)
    a = stratified_group_folds(y, k=5, seed=7)
    b = stratified_group_folds(y.astype(bool), k=5, seed=7)
    c = stratified_group_folds(y, k=5, seed=8)
    for fa, fb in zip(a, b, strict=True):
        np.testing.assert_array_equal(fa, fb)
    assert any(not np.array_equal(fa, fc) for fa, fc in zip(a, c, strict=True))


# --- folds with groups --------------------------------------------------------------------------


def _grouped(seed: int, n_groups: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Groups ("drive07", ...) of 1-12 clips, shuffled; about 30 % anomalies."""
    rng = np.random.default_rng(seed)
    names = np.repeat([f"drive{g:02d}" for g in range(n_groups)], rng.integers(1, 13, n_groups))
    order = rng.permutation(len(names))
    y = (rng.random(len(names)) < 0.3).astype(int)
    return y, names[order]


@pytest.mark.parametrize("seed", range(4))
def test_groups_are_never_split_and_labels_still_balance(seed: int) -> None:
    y, groups = _grouped(seed)
    k = 5
    folds = stratified_group_folds(y, groups, k=k, seed=seed)
    _assert_partition(folds, len(y), k)
    fold_of = np.empty(len(y), int)
    for i, f in enumerate(folds):
        fold_of[f] = i
    for g in np.unique(groups):
        assert len(set(fold_of[groups == g].tolist())) == 1, g
    # greedy balance: every fold within one group's worth of the target, for each class
    for cls in (0, 1):
        target = np.sum(y == cls) / k
        _, per_group = np.unique(groups[y == cls], return_counts=True)
        for f in folds:
            assert abs(np.sum(y[f] == cls) - target) <= per_group.max()
    same = stratified_group_folds(y, groups, k=k, seed=seed)
    assert all(np.array_equal(a, b) for a, b in zip(folds, same, strict=True))


def test_one_group_per_fold_when_k_equals_the_number_of_groups() -> None:
    groups = np.array(["a", "a", "b", "c", "c", "c", "d", "e", "e"])
    y = np.array([1, 0, 1, 0, 1, 0, 0, 1, 1])
    folds = stratified_group_folds(y, groups, k=5)
    assert sorted(tuple(sorted(set(groups[f].tolist()))) for f in folds) == [
        ("a",),
        ("b",),
        ("c",),
        ("d",),
        ("e",),
    ]


def test_fold_errors_name_the_argument() -> None:
    y = _labels(3, 3)
    with pytest.raises(InputDataError, match=r"^k: 5 folds need at least 5 groups, got 3"):
        stratified_group_folds(y, ["a", "a", "b", "b", "c", "c"], k=5)
    with pytest.raises(InputDataError, match=r"^k:"):
        stratified_group_folds(y, k=7)
    with pytest.raises(InputDataError, match=r"^k:"):
        stratified_group_folds(y, k=1)
    with pytest.raises(InputDataError, match=r"^groups:"):
        stratified_group_folds(y, ["a", "b"], k=2)
    with pytest.raises(InputDataError, match=r"^labels:"):
        stratified_group_folds([0, 1, 3], k=2)


# --- no leakage ---------------------------------------------------------------------------------


class _Spy:
    """A threshold chooser that records what it was shown and returns the median."""

    def __init__(self) -> None:
        self.calls: list[tuple[np.ndarray, np.ndarray]] = []

    def __call__(self, scores: np.ndarray, labels: np.ndarray) -> float:
        self.calls.append((scores.copy(), labels.copy()))
        return float(np.median(scores))


@pytest.mark.parametrize("use_groups", [False, True])
def test_threshold_chooser_never_sees_the_test_fold(use_groups: bool) -> None:
    y, groups = _grouped(5)
    n = len(y)
    scores = np.random.default_rng(0).permutation(n).astype(float)  # unique: identifies items
    hard = np.random.default_rng(1).random(n) < 0.4
    spy = _Spy()
    g = groups if use_groups else None
    res = cross_validate(
        scores,
        y,
        subsets={"hard": hard, "easy": ~hard},
        groups=g,
        k=5,
        seed=2,
        choose_threshold=spy,
    )
    folds = stratified_group_folds(y, g, k=5, seed=2)
    assert len(spy.calls) == 5  # once per fold, on the entire set, not once per subset
    item_of = {float(v): i for i, v in enumerate(scores)}
    for (seen_scores, seen_labels), test in zip(spy.calls, folds, strict=True):
        seen = {item_of[float(v)] for v in seen_scores}
        assert seen.isdisjoint(test.tolist())
        assert seen == set(range(n)) - set(test.tolist())  # all of the training folds
        assert seen_labels.dtype == np.bool_
        np.testing.assert_array_equal(seen_labels, y[[item_of[float(v)] for v in seen_scores]])
    assert list(res) == [ENTIRE, "hard", "easy"]
    for name, mask in ((ENTIRE, np.ones(n, bool)), ("hard", hard), ("easy", ~hard)):
        assert [r.n_test for r in res[name].folds] == [int(mask[f].sum()) for f in folds]
        assert [r.threshold for r in res[name].folds] == [float(np.median(c[0])) for c in spy.calls]


def test_honest_cv_value_not_the_test_fold_optimum() -> None:
    """Per-fold score offsets: tuning on the test fold separates it perfectly, honest CV cannot.

    10 anomalies and 10 normal items, k = 5: 2 + 2 per fold. In fold f the
    anomalies score 10 f + 1, the normal items 10 f. On training folds
    g0 < g1 < g2 < g3, threshold 10 g_j + 1 flags the anomalies of 4 - j folds and
    the normal items of 3 - j: F = 2 tp / (tp + fp + 8) = 16/22, 12/18, 8/14, 4/10
    for j = 0..3, and 10 g_j is worse (same tp, more fp). So the threshold is
    10 g0 + 1: 11 for test fold 0 (its scores 0, 1 are all below: tp = 0, F = 0,
    BA = (0 + 1)/2), and 1 for folds 1-4 (all flagged: tp = 2, fp = 2,
    F = 4/6, BA = (1 + 0)/2). F: mean 8/15, population std
    sqrt(4 (2/3)^2 / 5 - (8/15)^2) = sqrt(80/225 - 64/225) = 4/15; BA 1/2 ± 0.
    Tuned on the test fold, F = BA = 1 in every fold. Per-fold AUC 1; pooled,
    an anomaly of fold f beats a normal item of fold g iff f >= g: 15 of 25
    fold pairs, AUC 0.6.
    """
    y = _labels(10, 10, seed=4)
    folds = stratified_group_folds(y, k=5, seed=9)
    scores = np.empty(20)
    for f, test in enumerate(folds):
        scores[test] = 10 * f + y[test]
    # the leaky optimum really is visibly higher
    for test in folds:
        leaky = best_f_threshold(scores[test], y[test])
        assert confusion(scores[test], y[test], leaky).f_score == 1.0

    r = cross_validate(scores, y, k=5, seed=9)[ENTIRE]
    assert [fr.threshold for fr in r.folds] == [11, 1, 1, 1, 1]
    assert [fr.f_score for fr in r.folds] == pytest.approx([0, 2 / 3, 2 / 3, 2 / 3, 2 / 3])
    assert r.f_score_mean == pytest.approx(8 / 15)
    assert r.f_score_std == pytest.approx(4 / 15)  # ddof = 0 (ddof = 1 would be 0.298)
    assert r.balanced_accuracy_mean == pytest.approx(0.5)
    assert r.balanced_accuracy_std == pytest.approx(0.0)
    assert r.auc == pytest.approx(0.6)
    assert r.auc_mean == 1.0
    assert r.auc_std == 0.0
    assert (r.n_pos, r.n_neg) == (10, 10)


# --- subsets and aggregation --------------------------------------------------------------------


def test_subsets_use_the_entire_set_threshold_and_nan_aware_means() -> None:
    """A subset holding the anomalies of folds 0-1 only and every normal item.

    Folds 2-4 of the subset have no anomaly: all their metrics are NaN and the
    means and stds come from folds 0-1 alone (without numpy warnings, which
    this test suite turns into errors).
    """
    y = _labels(15, 25, seed=1)
    rng = np.random.default_rng(2)
    scores = rng.normal(size=40) + 1.2 * y
    folds = stratified_group_folds(y, k=5, seed=0)
    subset = y == 0
    subset[folds[0]] = True
    subset[folds[1]] = True
    res = cross_validate(scores, y, subsets={"part": subset, "none": np.zeros(40, bool)}, seed=0)
    entire, part, none = res[ENTIRE], res["part"], res["none"]
    for fe, fp_ in zip(entire.folds, part.folds, strict=True):
        assert fe.threshold == fp_.threshold
    for f in (0, 1):
        test = folds[f]
        c = confusion(scores[test], y[test], entire.folds[f].threshold)  # folds 0-1: all in subset
        assert part.folds[f].f_score == pytest.approx(c.f_score)
        assert part.folds[f].balanced_accuracy == pytest.approx(c.balanced_accuracy)
        assert part.folds[f].auc == pytest.approx(auc(scores[test], y[test]))
    for f in (2, 3, 4):
        assert math.isnan(part.folds[f].f_score)
        assert math.isnan(part.folds[f].balanced_accuracy)
        assert math.isnan(part.folds[f].auc)
    f01 = np.array([part.folds[0].f_score, part.folds[1].f_score])
    assert part.f_score_mean == pytest.approx(f01.mean())
    assert part.f_score_std == pytest.approx(f01.std())
    assert part.auc == pytest.approx(auc(scores[subset], y[subset]))
    assert (part.n_pos, part.n_neg) == (int(y[subset].sum()), 25)
    assert (none.n_pos, none.n_neg) == (0, 0)
    assert math.isnan(none.auc)
    assert math.isnan(none.f_score_mean)
    assert math.isnan(none.balanced_accuracy_std)
    # the entire set: mean of the fold values, pooled AUC of everything
    assert entire.f_score_mean == pytest.approx(np.mean([fr.f_score for fr in entire.folds]))
    assert entire.auc == pytest.approx(auc(scores, y))


def test_groups_reach_the_folds() -> None:
    y, groups = _grouped(3)
    scores = np.random.default_rng(0).normal(size=len(y)) + y
    res = cross_validate(scores, y, groups=groups, k=4, seed=1)[ENTIRE]
    folds = stratified_group_folds(y, groups, k=4, seed=1)
    assert [r.n_test for r in res.folds] == [len(f) for f in folds]


def test_cross_validate_errors_name_the_argument() -> None:
    y = _labels(5, 5)
    s = np.linspace(0, 1, 10)
    with pytest.raises(InputDataError, match=r"^scores:"):
        cross_validate(np.r_[s[:-1], math.nan], y)
    with pytest.raises(InputDataError, match=r"^labels:"):
        cross_validate(s, y[:-1])
    with pytest.raises(InputDataError, match=r"^subsets\['hard'\]: must be a boolean mask"):
        cross_validate(s, y, subsets={"hard": np.arange(3)})
    with pytest.raises(InputDataError, match=r"^subsets\['hard'\]: shape"):
        cross_validate(s, y, subsets={"hard": np.ones(9, bool)})
    with pytest.raises(InputDataError, match=r"^subsets\['entire'\]"):
        cross_validate(s, y, subsets={ENTIRE: s > 0.5})
    with pytest.raises(InputDataError, match=r"^choose_threshold: returned NaN"):
        cross_validate(s, y, choose_threshold=lambda a, b: math.nan)
    with pytest.raises(InputDataError, match=r"^k:"):
        cross_validate(s, y, k=11)
    # "entire" given as all True is accepted and stays first
    assert list(cross_validate(s, y, subsets={"x": s > 0.5, ENTIRE: np.ones(10, bool)})) == [
        ENTIRE,
        "x",
    ]
