"""Cross-validation of a detector's threshold, as in the paper's Table I.

A method gives each clip one score (higher = more anomalous). Its threshold is
the one maximising the F-score on the training folds of a k-fold
cross-validation; balanced accuracy and F-score are measured on the test fold
and reported as mean ± standard deviation over the folds. AUC needs no
threshold. Everything is reported for the entire set and for subsets of it
(the paper's "hard" and "easy" clips).

Folds are stratified by label and, when the clips come from a few drives,
grouped by drive: clips of one recording share the lead vehicle, the light
and the road, so putting them on both sides of a split would leak. The folds
are scikit-learn's (`StratifiedGroupKFold`, `StratifiedKFold` without groups;
the ``roadpreview[eval]`` extra).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview.errors import InputDataError
from roadpreview.eval.metrics import (
    Array,
    BoolArray,
    as_labels,
    as_scores,
    auc,
    best_f_threshold,
    confusion,
    require_sklearn,
)

IndexArray = NDArray[np.intp]
#: ``choose_threshold(train_scores, train_labels) -> threshold``; labels arrive as bools
ThresholdChooser = Callable[[Array, BoolArray], float]

#: name of the subset of all items, always present in `cross_validate`'s result
ENTIRE = "entire"

__all__ = [
    "ENTIRE",
    "FoldResult",
    "SubsetResult",
    "ThresholdChooser",
    "cross_validate",
    "stratified_group_folds",
]


# ---------------------------------------------------------------------------------------------
# folds


def _check_k(k: int) -> int:
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 2:
        raise InputDataError(f"k: the number of folds must be an integer >= 2, got {k!r}")
    return int(k)


def _group_ids(groups: ArrayLike, n: int) -> IndexArray:
    """Dense group ids 0..g-1 of the n items (`InputDataError` naming ``groups``)."""
    try:
        arr = np.asarray(groups)
        if arr.ndim != 1:
            raise InputDataError(f"groups: must be a 1-D array, got shape {arr.shape}")
        if arr.size != n:
            raise InputDataError(f"groups: has {arr.size} values, expected {n} (one per label)")
        _, ids = np.unique(arr, return_inverse=True)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputDataError):
            raise
        raise InputDataError(f"groups: cannot compare the group names ({exc})") from None
    return np.asarray(ids, dtype=np.intp).ravel()


def stratified_group_folds(
    labels: ArrayLike, groups: ArrayLike | None = None, *, k: int = 5, seed: int = 0
) -> list[IndexArray]:
    """Split the items into k test folds, stratified by label and never splitting a group.

    Parameters
    ----------
    labels : array_like, shape (n,)
        0/1 or bool; 1 = anomaly.
    groups : array_like, shape (n,), optional
        A group name per item (e.g. the recording of each clip). All items of
        one group go to the same fold. None: every item is its own group.
    k : int
        Number of folds, >= 2 and at most the number of groups.
    seed : int
        Seed of the shuffling; the same seed gives the same folds.

    Returns
    -------
    list of ndarray
        k disjoint, sorted arrays of test indices that together cover 0..n-1.
        The training items of fold i are all the others.

    Raises
    ------
    InputDataError
        Bad ``labels`` or ``groups``, or ``k`` < 2 or > the number of groups.

    Notes
    -----
    Without groups: `sklearn.model_selection.StratifiedKFold` (shuffled), so
    every fold holds floor or ceil of n_pos / k positives and of n_neg / k
    negatives.

    With groups: `sklearn.model_selection.StratifiedGroupKFold` (shuffled): a
    greedy assignment of whole groups, each to the fold where it keeps the
    class shares of the folds closest to each other. How well the label
    counts balance depends on the group sizes.
    """
    y = as_labels(labels)
    k = _check_k(k)
    n = y.size
    ms = require_sklearn("sklearn.model_selection")
    if groups is None:
        if k > n:
            raise InputDataError(f"k: {k} folds need at least {k} items, got {n}")
        splitter = ms.StratifiedKFold(n_splits=k, shuffle=True, random_state=seed)
        gid: IndexArray | None = None
    else:
        gid = _group_ids(groups, n)
        n_groups = int(gid.max()) + 1
        if k > n_groups:
            raise InputDataError(
                f"k: {k} folds need at least {k} groups, got {n_groups} (groups are never split)"
            )
        splitter = ms.StratifiedGroupKFold(n_splits=k, shuffle=True, random_state=seed)
    with warnings.catch_warnings():
        # "the least populated class has fewer members than n_splits": expected with few
        # anomalies; the folds then hold 0 or 1 of them
        warnings.filterwarnings("ignore", "The least populated class", UserWarning)
        splits = splitter.split(np.zeros(n), y.astype(np.int8), gid)
        return [np.sort(np.asarray(test, dtype=np.intp)) for _, test in splits]


# ---------------------------------------------------------------------------------------------
# cross-validation


@dataclass(frozen=True)
class FoldResult:
    """One test fold of one subset.

    Metrics are NaN when the subset's part of the test fold cannot define
    them: without positives every metric is NaN; without negatives the
    balanced accuracy and the AUC are.
    """

    fold: int  #: fold number, 0..k-1
    threshold: float  #: chosen on the training folds of the entire set
    n_test: int  #: items of the subset in this test fold
    balanced_accuracy: float
    f_score: float
    auc: float


@dataclass(frozen=True)
class SubsetResult:
    """One row of Table I: one method on one subset.

    Means and standard deviations are over the folds, ignoring folds where
    the metric is NaN (see `FoldResult`); NaN when no fold defines it. The
    standard deviation is the population one (ddof = 0): the paper does not
    say which it uses.
    """

    subset: str
    n_pos: int  #: anomalies in the subset
    n_neg: int  #: normal items in the subset
    balanced_accuracy_mean: float
    balanced_accuracy_std: float
    f_score_mean: float
    f_score_std: float
    #: AUC of the subset's pooled test-fold scores. The scores are not refit per fold, so
    #: pooling the test folds gives back every item: this is the subset's AUC
    auc: float
    auc_mean: float  #: mean of the per-fold AUCs
    auc_std: float  #: population std (ddof = 0) of the per-fold AUCs
    folds: tuple[FoldResult, ...]


def _mean_std(values: list[float]) -> tuple[float, float]:
    """NaN-aware mean and population std (ddof = 0), without numpy's empty-slice warnings."""
    v = np.asarray(values, dtype=np.float64)
    v = v[~np.isnan(v)]
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std(ddof=0))


def _subset_masks(subsets: Mapping[str, ArrayLike] | None, n: int) -> dict[str, BoolArray]:
    masks: dict[str, BoolArray] = {ENTIRE: np.ones(n, dtype=np.bool_)}
    for name, mask in (subsets or {}).items():
        where = f"subsets[{name!r}]"
        if not isinstance(name, str):
            raise InputDataError(f"{where}: subset names must be strings")
        m = np.asarray(mask)
        if m.dtype != np.bool_:
            raise InputDataError(
                f"{where}: must be a boolean mask over all items, got dtype {m.dtype}"
                " (index arrays are not accepted)"
            )
        if m.shape != (n,):
            raise InputDataError(f"{where}: shape {m.shape}, expected ({n},) (one per item)")
        if name == ENTIRE and not m.all():
            raise InputDataError(f"{where}: {ENTIRE!r} is reserved for all items")
        masks[name] = m
    return masks


def _fold_metrics(s: Array, y: BoolArray, threshold: float) -> tuple[float, float, float]:
    """Balanced accuracy, F-score and AUC of one subset's test items; NaN where undefined."""
    if s.size == 0 or not y.any():
        return math.nan, math.nan, math.nan
    c = confusion(s, y, threshold)
    return c.balanced_accuracy, c.f_score, auc(s, y)


def cross_validate(
    scores: ArrayLike,
    labels: ArrayLike,
    *,
    subsets: Mapping[str, ArrayLike] | None = None,
    groups: ArrayLike | None = None,
    k: int = 5,
    seed: int = 0,
    choose_threshold: ThresholdChooser = best_f_threshold,
) -> dict[str, SubsetResult]:
    """Table I for one method: k-fold cross-validated BA and F, and AUC, per subset.

    For each fold of `stratified_group_folds` (``labels``, ``groups``, ``k``,
    ``seed``), the threshold is ``choose_threshold(scores[train],
    labels[train])`` on the training folds of the ENTIRE set (one call per
    fold, whatever the subsets); each subset is then scored on its members
    in the test fold. The test fold is never shown to ``choose_threshold``.

    Parameters
    ----------
    scores : array_like, shape (n,)
        One finite score per item, higher = more anomalous.
    labels : array_like, shape (n,)
        0/1 or bool; 1 = anomaly.
    subsets : mapping of str to bool array of shape (n,), optional
        Named boolean masks over all items (e.g. ``{"hard": ..., "easy": ...}``).
        ``"entire"`` (all items) is always added first; passing it is allowed
        only as an all-True mask.
    groups : array_like, shape (n,), optional
        Group (recording) of each item; a group is never split across folds.
    k, seed : int
        Number of folds and the seed of the split.
    choose_threshold : callable
        ``(train_scores float64 array, train_labels bool array) -> threshold``;
        defaults to `best_f_threshold` (the F-maximising threshold, as in the paper).

    Returns
    -------
    dict of str to SubsetResult
        ``"entire"`` first, then the subsets in the given order. Fold metrics
        follow `FoldResult`; means and stds are NaN-aware, with the
        population std (ddof = 0).

    Raises
    ------
    InputDataError
        Bad ``scores``, ``labels``, ``subsets``, ``groups`` or ``k`` (named in
        the message), or ``choose_threshold`` returned NaN.
    """
    s = as_scores(scores)
    y = as_labels(labels, s.size)
    masks = _subset_masks(subsets, s.size)
    folds = stratified_group_folds(y, groups, k=k, seed=seed)

    per_subset: dict[str, list[FoldResult]] = {name: [] for name in masks}
    for f, test in enumerate(folds):
        in_test = np.zeros(s.size, dtype=np.bool_)
        in_test[test] = True
        train = ~in_test
        raw = choose_threshold(s[train], y[train])
        try:
            thr = float(raw)
        except (TypeError, ValueError):
            raise InputDataError(f"choose_threshold: returned {raw!r} on fold {f}") from None
        if math.isnan(thr):
            raise InputDataError(f"choose_threshold: returned NaN on fold {f}")
        for name, mask in masks.items():
            sel = in_test & mask
            ba, fs, a = _fold_metrics(s[sel], y[sel], thr)
            per_subset[name].append(
                FoldResult(
                    fold=f,
                    threshold=thr,
                    n_test=int(np.count_nonzero(sel)),
                    balanced_accuracy=ba,
                    f_score=fs,
                    auc=a,
                )
            )

    results: dict[str, SubsetResult] = {}
    for name, mask in masks.items():
        fr = per_subset[name]
        ba_mean, ba_std = _mean_std([r.balanced_accuracy for r in fr])
        f_mean, f_std = _mean_std([r.f_score for r in fr])
        auc_mean, auc_std = _mean_std([r.auc for r in fr])
        n_pos = int(np.count_nonzero(y[mask]))
        results[name] = SubsetResult(
            subset=name,
            n_pos=n_pos,
            n_neg=int(np.count_nonzero(mask)) - n_pos,
            balanced_accuracy_mean=ba_mean,
            balanced_accuracy_std=ba_std,
            f_score_mean=f_mean,
            f_score_std=f_std,
            auc=auc(s[mask], y[mask]) if mask.any() else math.nan,
            auc_mean=auc_mean,
            auc_std=auc_std,
            folds=tuple(fr),
        )
    return results
