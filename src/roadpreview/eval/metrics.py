"""Binary-classification metrics of the evaluation (paper Table I and the ROC curves).

Conventions, shared by every function here:

* ``scores`` are 1-D, finite floats; a HIGHER score means MORE anomalous.
* ``labels`` are 1-D, of the same length, with values 0/1 (ints, floats or
  bools); 1 (True) is an anomaly, the positive class.
* An item is predicted positive iff ``score >= threshold``.
* Bad input (NaN or infinite scores, labels other than 0/1, mismatched
  lengths, empty arrays) raises `InputDataError` naming the argument.
* A set with a single class is not an error: metrics that need both classes
  (AUC, balanced accuracy, the ROC axis of the missing class) are NaN.

Everything is vectorised: one sort per call, no Python loop over items or
thresholds. The ROC curve and the AUC are scikit-learn's (`sklearn.metrics`, the
``roadpreview[eval]`` extra, imported on use); this module checks the input and
keeps the conventions above (NaN for a missing class instead of a warning).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roadpreview.errors import InputDataError, MissingDependencyError

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = [
    "Confusion",
    "as_labels",
    "as_scores",
    "auc",
    "best_f_threshold",
    "confusion",
    "require_sklearn",
    "roc_curve",
]


def require_sklearn(module: str = "sklearn") -> ModuleType:
    """Import ``module`` of scikit-learn (the evaluation's optional dependency).

    Raises
    ------
    MissingDependencyError
        scikit-learn is not installed; the message names the extra to install.
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name is None or exc.name.split(".")[0] != "sklearn":
            raise
        raise MissingDependencyError(
            "the evaluation needs scikit-learn, which is not installed:"
            " pip install 'roadpreview[eval]'"
        ) from None


# ---------------------------------------------------------------------------------------------
# input checks


def as_scores(scores: ArrayLike, name: str = "scores") -> Array:
    """``scores`` as a 1-D float64 array, checked to be non-empty and finite.

    Infinite scores are refused as well as NaN: the ROC curve starts at the
    threshold +inf, which must predict nothing positive.

    Raises
    ------
    InputDataError
        Naming ``name``: not 1-D numbers, empty, or a NaN or infinite value.
    """
    try:
        arr = np.asarray(scores, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputDataError(f"{name}: not an array of numbers ({exc})") from None
    if arr.ndim != 1:
        raise InputDataError(f"{name}: must be a 1-D array, got shape {arr.shape}")
    if arr.size == 0:
        raise InputDataError(f"{name}: is empty")
    bad = ~np.isfinite(arr)
    if bad.any():
        first = int(np.argmax(bad))
        raise InputDataError(
            f"{name}: {int(bad.sum())} of {arr.size} values are NaN or infinite"
            f" (first at index {first}: {arr[first]}); scores must be finite"
        )
    return arr


def as_labels(labels: ArrayLike, n: int | None = None, name: str = "labels") -> BoolArray:
    """``labels`` (0/1 or bool) as a 1-D bool array of length ``n`` (when given).

    Raises
    ------
    InputDataError
        Naming ``name``: not 1-D, empty, of the wrong length, or a value other than 0 and 1.
    """
    try:
        arr = np.asarray(labels)
    except (TypeError, ValueError) as exc:  # ragged input
        raise InputDataError(f"{name}: not an array of 0/1 labels ({exc})") from None
    if arr.ndim != 1:
        raise InputDataError(f"{name}: must be a 1-D array, got shape {arr.shape}")
    if arr.size == 0:
        raise InputDataError(f"{name}: is empty")
    if n is not None and arr.size != n:
        raise InputDataError(f"{name}: has {arr.size} values, expected {n} (one per score)")
    if arr.dtype == np.bool_:
        return arr
    if arr.dtype.kind not in "iuf":
        raise InputDataError(f"{name}: must be 0/1 or bool, got dtype {arr.dtype}")
    is_one = arr == 1
    bad = ~(is_one | (arr == 0))
    if bad.any():
        first = int(np.argmax(bad))
        raise InputDataError(f"{name}: values must be 0 or 1, got {arr[first]!r} at index {first}")
    return np.asarray(is_one, dtype=np.bool_)


def _check(scores: ArrayLike, labels: ArrayLike) -> tuple[Array, BoolArray]:
    s = as_scores(scores)
    return s, as_labels(labels, s.size)


def _check_threshold(threshold: float, name: str = "threshold") -> float:
    try:
        thr = float(threshold)
    except (TypeError, ValueError):
        raise InputDataError(f"{name}: {threshold!r} is not a number") from None
    if math.isnan(thr):
        raise InputDataError(f"{name}: is NaN")
    return thr


def _ratio(num: float, den: float) -> float:
    return num / den if den else math.nan


# ---------------------------------------------------------------------------------------------
# confusion matrix


@dataclass(frozen=True)
class Confusion:
    """Counts of a binary decision: true/false positives and negatives.

    Derived rates are NaN where their denominator is 0, except `f_score`,
    which is 0 whenever ``tp == 0``.
    """

    tp: int  #: anomalies predicted as anomalies
    fp: int  #: normal items predicted as anomalies (false alarms)
    tn: int  #: normal items predicted as normal
    fn: int  #: anomalies predicted as normal (misses)

    def __post_init__(self) -> None:
        for name in ("tp", "fp", "tn", "fn"):
            if getattr(self, name) < 0:
                raise InputDataError(f"Confusion.{name}: {getattr(self, name)} is negative")

    @property
    def n(self) -> int:
        """Number of items."""
        return self.tp + self.fp + self.tn + self.fn

    @property
    def n_pos(self) -> int:
        """Number of positives (anomalies), tp + fn."""
        return self.tp + self.fn

    @property
    def n_neg(self) -> int:
        """Number of negatives, tn + fp."""
        return self.tn + self.fp

    @property
    def tpr(self) -> float:
        """True-positive rate (recall, sensitivity), tp / (tp + fn)."""
        return _ratio(self.tp, self.tp + self.fn)

    recall = tpr

    @property
    def tnr(self) -> float:
        """True-negative rate (specificity), tn / (tn + fp)."""
        return _ratio(self.tn, self.tn + self.fp)

    @property
    def fpr(self) -> float:
        """False-positive rate, fp / (fp + tn) = 1 - tnr."""
        return _ratio(self.fp, self.fp + self.tn)

    @property
    def precision(self) -> float:
        """Precision, tp / (tp + fp)."""
        return _ratio(self.tp, self.tp + self.fp)

    @property
    def balanced_accuracy(self) -> float:
        """(tpr + tnr) / 2; NaN unless both classes are present."""
        return (self.tpr + self.tnr) / 2

    @property
    def f_score(self) -> float:
        """F1 = 2 P R / (P + R), computed as 2 tp / (2 tp + fp + fn); 0 when tp == 0.

        The two forms are algebraically equal; the integer form is exact up
        to one rounding, so equal F values compare equal.
        """
        if self.tp == 0:
            return 0.0
        return 2 * self.tp / (2 * self.tp + self.fp + self.fn)

    @property
    def accuracy(self) -> float:
        """(tp + tn) / n."""
        return _ratio(self.tp + self.tn, self.n)


def confusion(scores: ArrayLike, labels: ArrayLike, threshold: float) -> Confusion:
    """Confusion matrix of the decision ``score >= threshold`` (predicted anomaly).

    Parameters
    ----------
    scores : array_like, shape (n,)
        Finite scores, higher = more anomalous.
    labels : array_like, shape (n,)
        0/1 or bool; 1 = anomaly.
    threshold : float
        Decision threshold (±inf allowed, NaN is an error).

    Returns
    -------
    Confusion
    """
    s, y = _check(scores, labels)
    thr = _check_threshold(threshold)
    pred = s >= thr
    tp = int(np.count_nonzero(pred & y))
    fp = int(np.count_nonzero(pred & ~y))
    fn = int(np.count_nonzero(y)) - tp
    tn = s.size - tp - fp - fn
    return Confusion(tp=tp, fp=fp, tn=tn, fn=fn)


# ---------------------------------------------------------------------------------------------
# threshold sweeps


def _sweep(s: Array, y: BoolArray) -> tuple[Array, NDArray[np.int64], NDArray[np.int64]]:
    """Distinct scores in descending order and the cumulative (tp, fp) at each as threshold.

    At threshold ``thr[i]`` the items with ``score >= thr[i]`` are predicted
    positive; tied scores enter together (one step).
    """
    order = np.argsort(-s, kind="stable")
    s_sorted = s[order]
    y_sorted = y[order]
    # the last index of each run of equal scores
    last = np.flatnonzero(np.r_[s_sorted[1:] != s_sorted[:-1], True])
    tp = np.cumsum(y_sorted, dtype=np.int64)[last]
    fp = (last + 1).astype(np.int64) - tp
    return s_sorted[last], tp, fp


def roc_curve(scores: ArrayLike, labels: ArrayLike) -> tuple[Array, Array, Array]:
    """ROC curve: (fpr, tpr, thresholds) for every distinct score as a threshold
    (`sklearn.metrics.roc_curve` without dropping intermediate points).

    Parameters
    ----------
    scores, labels : array_like, shape (n,)
        See the module docstring.

    Returns
    -------
    fpr, tpr : ndarray, shape (m + 1,)
        Non-decreasing rates; the first point is (0, 0) at threshold +inf
        (nothing predicted positive), the last (1, 1) at the lowest score.
        Tied scores make one step (a diagonal segment when the tie mixes the
        classes). All points are kept (no thinning of collinear ones). The
        axis of a class absent from ``labels`` is all NaN.
    thresholds : ndarray, shape (m + 1,)
        +inf, then the m distinct scores in descending order; point i is the
        decision ``score >= thresholds[i]``.
    """
    s, y = _check(scores, labels)
    sk = require_sklearn("sklearn.metrics")
    undefined = require_sklearn("sklearn.exceptions").UndefinedMetricWarning
    with warnings.catch_warnings():
        # a missing class: scikit-learn warns and gives that axis as NaN, as documented here
        warnings.simplefilter("ignore", undefined)
        fpr, tpr, thr = sk.roc_curve(y.astype(np.int8), s, drop_intermediate=False)
    return (
        np.asarray(fpr, dtype=np.float64),
        np.asarray(tpr, dtype=np.float64),
        np.asarray(thr, dtype=np.float64),
    )


def auc(scores: ArrayLike, labels: ArrayLike) -> float:
    """Area under the ROC curve (`sklearn.metrics.roc_auc_score`); NaN unless both
    classes are present.

    This is the Mann-Whitney statistic U / (n_pos n_neg): the fraction of
    (positive, negative) pairs in which the positive scores higher, a tie
    counting 1/2; the trapezoidal area under `roc_curve`.
    """
    s, y = _check(scores, labels)
    n_pos = int(np.count_nonzero(y))
    if n_pos == 0 or n_pos == s.size:
        return math.nan
    sk = require_sklearn("sklearn.metrics")
    return float(sk.roc_auc_score(y.astype(np.int8), s))


def best_f_threshold(scores: ArrayLike, labels: ArrayLike) -> float:
    """The threshold among the distinct scores that maximises F1 on this set.

    Parameters
    ----------
    scores, labels : array_like, shape (n,)
        See the module docstring.

    Returns
    -------
    float
        One of the scores. Ties in F go to the HIGHER threshold (fewer
        alarms). Without positives every threshold has F = 0, so this is the
        highest score; with only positives it is the lowest (F = 1).
    """
    s, y = _check(scores, labels)
    thr, tp, fp = _sweep(s, y)
    n_pos = int(np.count_nonzero(y))
    # F = 2 tp / (2 tp + fp + fn) = 2 tp / (tp + fp + n_pos); the denominator is >= 1 for
    # every distinct score (tp + fp counts at least the items at that score)
    f = 2 * tp / (tp + fp + n_pos)
    return float(thr[int(np.argmax(f))])  # argmax: first maximum = highest threshold
