"""Metrics of the evaluation: confusion, AUC, ROC, F-maximising threshold, rates; known answers."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roadpreview.errors import InputDataError, MissingDependencyError
from roadpreview.eval.metrics import (
    Confusion,
    auc,
    best_f_threshold,
    confusion,
    roc_curve,
)

# eight items, scores descending; anomalies (1) at 0.9, 0.8, 0.6, 0.3
SCORES = np.array([0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2])
LABELS = np.array([1, 1, 0, 1, 0, 0, 1, 0])


def _random_set(seed: int, n: int = 60, ties: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Random scores (integers 0..9 when ``ties``: many ties) with both classes present."""
    rng = np.random.default_rng(seed)
    y = rng.random(n) < 0.35
    y[:2] = [True, False]
    if ties:  # integer scores and an integer shift of the positives: ties across the classes
        s = rng.integers(0, 10, n).astype(float) + y * rng.integers(0, 3)
    else:
        s = rng.normal(size=n) + 1.5 * y * rng.random()  # some signal, seed-dependent
    return s, y.astype(int)


def _pairwise_auc(s: np.ndarray, y: np.ndarray) -> float:
    """The definition: P(score_pos > score_neg) + P(tie) / 2 over all pairs (O(n²))."""
    pos, neg = s[y == 1], s[y == 0]
    diff = pos[:, None] - neg[None, :]
    return float(((diff > 0).sum() + 0.5 * (diff == 0).sum()) / diff.size)


def _trapezoid(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.sum(np.diff(x) * (y[1:] + y[:-1]) / 2))


# --- confusion ----------------------------------------------------------------------------------


@pytest.mark.parametrize("threshold", [0.65, 0.7])  # 0.7 is a score: score >= thr is positive
def test_confusion_hand_worked(threshold: float) -> None:
    """Positive: 0.9 (1), 0.8 (1), 0.7 (0) -> tp = 2, fp = 1.

    Negative: 0.6 (1), 0.5 (0), 0.4 (0), 0.3 (1), 0.2 (0) -> fn = 2, tn = 3.
    tpr = 2/4, tnr = 3/4, BA = (1/2 + 3/4)/2 = 5/8; precision = 2/3,
    F = 2 (2/3)(1/2) / (2/3 + 1/2) = (2/3) / (7/6) = 4/7; accuracy = 5/8; fpr = 1/4.
    """
    c = confusion(SCORES, LABELS, threshold)
    assert c == Confusion(tp=2, fp=1, tn=3, fn=2)
    assert c.n == 8
    assert (c.n_pos, c.n_neg) == (4, 4)
    assert c.tpr == pytest.approx(0.5)
    assert c.recall == c.tpr
    assert c.tnr == pytest.approx(0.75)
    assert c.fpr == pytest.approx(0.25)
    assert c.precision == pytest.approx(2 / 3)
    assert c.balanced_accuracy == pytest.approx(5 / 8)
    assert c.f_score == pytest.approx(4 / 7)
    assert c.accuracy == pytest.approx(5 / 8)


def test_confusion_extreme_thresholds_and_bool_labels() -> None:
    assert confusion(SCORES, LABELS.astype(bool), math.inf) == Confusion(tp=0, fp=0, tn=4, fn=4)
    assert confusion(SCORES, LABELS, -math.inf) == Confusion(tp=4, fp=4, tn=0, fn=0)
    assert confusion(SCORES, LABELS.astype(float), 0.2) == Confusion(tp=4, fp=4, tn=0, fn=0)


def test_confusion_undefined_rates_are_nan_and_f_is_zero_without_tp() -> None:
    only_neg = Confusion(tp=0, fp=2, tn=3, fn=0)  # no positives at all
    assert math.isnan(only_neg.tpr)
    assert math.isnan(only_neg.balanced_accuracy)
    assert only_neg.precision == 0.0
    assert only_neg.f_score == 0.0  # defined 0 when tp == 0
    assert only_neg.fpr == pytest.approx(0.4)
    nothing_flagged = Confusion(tp=0, fp=0, tn=3, fn=2)
    assert math.isnan(nothing_flagged.precision)
    assert nothing_flagged.f_score == 0.0
    assert nothing_flagged.balanced_accuracy == pytest.approx(0.5)
    empty = Confusion(tp=0, fp=0, tn=0, fn=0)
    assert math.isnan(empty.accuracy)
    with pytest.raises(InputDataError, match="fp"):
        Confusion(tp=1, fp=-1, tn=0, fn=0)


# --- AUC and ROC --------------------------------------------------------------------------------


def test_auc_known_values() -> None:
    y = np.array([0, 0, 0, 1, 1, 1])
    s = np.arange(6.0)
    assert auc(s, y) == 1.0  # perfect separation
    assert auc(-s, y) == 0.0  # reversed
    assert auc(np.full(6, 3.0), y) == 0.5  # all tied: every pair counts 1/2


def test_auc_hand_computed_with_a_tie() -> None:
    """Positives 0.9, 0.5, 0.3; negatives 0.5, 0.2, 0.1: 9 pairs.

    0.9 beats all three (3); 0.5 ties 0.5 (1/2) and beats 0.2, 0.1 (2);
    0.3 loses to 0.5 and beats 0.2, 0.1 (2). AUC = 7.5 / 9 = 5/6.
    """
    s = np.array([0.9, 0.5, 0.3, 0.5, 0.2, 0.1])
    y = np.array([1, 1, 1, 0, 0, 0])
    assert auc(s, y) == pytest.approx(5 / 6, abs=1e-15)


def test_roc_curve_hand_computed() -> None:
    """Scores 1 (neg), 2 (pos), 2 (neg), 3 (pos): the tie at 2 is one diagonal step.

    thr inf: nothing -> (0, 0); thr 3: one pos -> (0, 1/2); thr 2: both pos and
    one neg -> (1/2, 1); thr 1: everything -> (1, 1). Area 0.5 * 1.5 / 2 + 0.5 * 2 / 2
    = 0.875 = pairs (3>1, 3>2, 2>1, 2=2 -> 1/2) 3.5 / 4.
    """
    fpr, tpr, thr = roc_curve([1, 2, 2, 3], [0, 1, 0, 1])
    np.testing.assert_array_equal(thr, [math.inf, 3, 2, 1])
    np.testing.assert_array_equal(fpr, [0, 0, 0.5, 1])
    np.testing.assert_array_equal(tpr, [0, 0.5, 1, 1])
    assert auc([1, 2, 2, 3], [0, 1, 0, 1]) == pytest.approx(0.875)
    assert _trapezoid(fpr, tpr) == pytest.approx(0.875)


@pytest.mark.parametrize("ties", [False, True])
@pytest.mark.parametrize("seed", range(5))
def test_auc_is_the_pairwise_probability_and_the_area_under_roc(seed: int, ties: bool) -> None:
    s, y = _random_set(seed, ties=ties)
    a = auc(s, y)
    assert a == pytest.approx(_pairwise_auc(s, y), abs=1e-12)
    fpr, tpr, thr = roc_curve(s, y)
    assert _trapezoid(fpr, tpr) == pytest.approx(a, abs=1e-12)
    # one point per distinct score plus the start, monotone, from (0, 0) to (1, 1)
    assert len(thr) == len(np.unique(s)) + 1
    assert np.all(np.diff(thr) < 0)
    assert np.all(np.diff(fpr) >= 0)
    assert np.all(np.diff(tpr) >= 0)
    assert (fpr[0], tpr[0], fpr[-1], tpr[-1]) == (0, 0, 1, 1)


@settings(max_examples=60, deadline=None)
@given(
    pairs=st.lists(st.tuples(st.integers(-5, 5).map(float), st.booleans()), min_size=2, max_size=30)
)
def test_auc_property(pairs: list[tuple[float, bool]]) -> None:
    s = np.array([p[0] for p in pairs])
    y = np.array([p[1] for p in pairs], dtype=int)
    if y.all() or not y.any():
        assert math.isnan(auc(s, y))
        return
    assert auc(s, y) == pytest.approx(_pairwise_auc(s, y), abs=1e-12)
    fpr, tpr, _ = roc_curve(s, y)
    assert _trapezoid(fpr, tpr) == pytest.approx(_pairwise_auc(s, y), abs=1e-12)


def test_single_class_gives_nan_not_a_crash() -> None:
    s = np.array([0.1, 0.5, 0.7])
    for y in (np.zeros(3, int), np.ones(3, int)):
        assert math.isnan(auc(s, y))
        assert math.isnan(confusion(s, y, 0.4).balanced_accuracy)
    fpr, tpr, _ = roc_curve(s, np.zeros(3, int))
    assert np.isnan(tpr).all()
    np.testing.assert_array_equal(fpr, [0, 1 / 3, 2 / 3, 1])
    fpr, tpr, _ = roc_curve(s, np.ones(3, int))
    assert np.isnan(fpr).all()
    np.testing.assert_array_equal(tpr, [0, 1 / 3, 2 / 3, 1])


# --- best F threshold ---------------------------------------------------------------------------


def test_best_f_threshold_hand_worked() -> None:
    """F = 2 tp / (tp + fp + n_pos), n_pos = 4, for each score of SCORES as threshold.

    0.9: 2/5 = .40   0.8: 4/6 = .67   0.7: 4/7 = .57   0.6: 6/8 = .75
    0.5: 6/9 = .67   0.4: 6/10 = .60  0.3: 8/11 = .73  0.2: 8/12 = .67  -> 0.6.
    """
    assert best_f_threshold(SCORES, LABELS) == 0.6
    assert confusion(SCORES, LABELS, 0.6).f_score == pytest.approx(0.75)


def test_best_f_threshold_tie_goes_to_the_higher_threshold() -> None:
    """Scores 4 (pos), 3, 2 (neg), 1 (pos); F = 2 tp / (tp + fp + 2).

    thr 4 -> 2/3, thr 3 -> 2/4, thr 2 -> 2/5, thr 1 -> 4/6 = 2/3: a tie of 4 and 1.
    """
    assert best_f_threshold([4, 3, 2, 1], [1, 0, 0, 1]) == 4.0


def test_best_f_threshold_single_class() -> None:
    s = [0.3, 0.9, 0.1]
    assert best_f_threshold(s, [1, 1, 1]) == 0.1  # everything flagged: F = 1
    assert best_f_threshold(s, [0, 0, 0]) == 0.9  # F = 0 everywhere: the highest threshold


def _brute_force_best_f(s: np.ndarray, y: np.ndarray) -> float:
    """A plain loop over all candidate thresholds, F from precision and recall."""
    best_thr, best_f = math.nan, -1.0
    for thr in sorted(set(s.tolist()), reverse=True):
        pred = s >= thr
        tp = int(np.sum(pred & (y == 1)))
        fp = int(np.sum(pred & (y == 0)))
        if tp == 0:
            f = 0.0
        else:
            precision, recall = tp / (tp + fp), tp / int(np.sum(y == 1))
            f = 2 * precision * recall / (precision + recall)
        if f > best_f + 1e-12:  # strictly better: the earlier (higher) threshold keeps ties
            best_thr, best_f = thr, f
    return best_thr


@pytest.mark.parametrize("ties", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_best_f_threshold_matches_a_brute_force_loop(seed: int, ties: bool) -> None:
    s, y = _random_set(seed, n=80, ties=ties)
    assert best_f_threshold(s, y) == _brute_force_best_f(s, y)


# --- ROC against the confusion matrix ----------------------------------------------------------


@pytest.mark.parametrize("seed", range(3))
def test_roc_curve_agrees_with_confusion(seed: int) -> None:
    s, y = _random_set(seed, ties=True)
    fpr, tpr, thr = roc_curve(s, y)
    assert thr[0] == math.inf
    assert (fpr[0], tpr[0]) == (0.0, 0.0)
    for t, tp_rate, fp_rate in zip(thr[1:], tpr[1:], fpr[1:], strict=True):
        c = confusion(s, y, t)
        assert (c.tpr, c.fpr) == (tp_rate, fp_rate)


# --- against scikit-learn (only when it happens to be installed) ----------------------------------


@pytest.mark.parametrize("seed", range(3))
def test_against_scikit_learn(seed: int) -> None:
    sk = pytest.importorskip("sklearn.metrics")
    s, y = _random_set(seed, n=200, ties=True)
    assert auc(s, y) == pytest.approx(sk.roc_auc_score(y, s), abs=1e-12)
    thr = best_f_threshold(s, y)
    pred = (s >= thr).astype(int)
    c = confusion(s, y, thr)
    assert c.f_score == pytest.approx(sk.f1_score(y, pred), abs=1e-12)
    assert c.balanced_accuracy == pytest.approx(sk.balanced_accuracy_score(y, pred), abs=1e-12)


# --- bad input ----------------------------------------------------------------------------------

_FUNCTIONS: list[Callable[[Any, Any], object]] = [
    lambda s, y: confusion(s, y, 0.5),
    roc_curve,
    auc,
    best_f_threshold,
]


@pytest.mark.parametrize("fn", _FUNCTIONS)
@pytest.mark.parametrize(
    ("scores", "labels", "name"),
    [
        ([0.1, math.nan, 0.3], [0, 1, 1], "scores"),
        ([0.1, math.inf, 0.3], [0, 1, 1], "scores"),
        ([], [], "scores"),
        ([[0.1, 0.2]], [0, 1], "scores"),
        (["a", "b"], [0, 1], "scores"),
        ([0.1, 0.2, 0.3], [0, 1], "labels"),
        ([0.1, 0.2, 0.3], [0, 1, 2], "labels"),
        ([0.1, 0.2, 0.3], [0, 1, math.nan], "labels"),
        ([0.1, 0.2, 0.3], ["a", "b", "c"], "labels"),
    ],
)
def test_bad_input_names_the_argument(
    fn: Callable[[Any, Any], object], scores: Any, labels: Any, name: str
) -> None:
    with pytest.raises(InputDataError, match=f"^{name}:"):
        fn(scores, labels)


def test_bad_thresholds_name_the_argument() -> None:
    with pytest.raises(InputDataError, match=r"^threshold:"):
        confusion([0.1, 0.2], [0, 1], math.nan)


def test_missing_scikit_learn_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sklearn.metrics", None)  # import fails as if absent
    with pytest.raises(MissingDependencyError, match=r"roadpreview\[eval\]"):
        auc([0.1, 0.9], [0, 1])
