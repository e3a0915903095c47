"""What every experiment shares: JSON-ready numbers and a few truth look-ups.

Pure functions over arrays and the truth's ``truth.json`` mapping; no files, no plots.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, SupportsFloat

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: the JSON form of a number: a float, or None for NaN / inf
JsonFloat = float | None


def jf(x: SupportsFloat) -> JsonFloat:
    """A JSON-ready float (None for NaN / inf)."""
    v = float(x)
    return v if math.isfinite(v) else None


def jfs(xs: Iterable[SupportsFloat]) -> list[JsonFloat]:
    """`jf` of each value."""
    return [jf(x) for x in xs]


def crossings(info: Mapping[str, Any], who: str, hits_only: bool = True) -> list[float]:
    """Front-axle crossing times of ``who`` ("lead" or "ego") from ``truth.json``."""
    out = []
    for e in info["events"]:
        t = e.get(f"{who}_front_t_s")
        if t is not None and (e.get(f"{who}_hits") or not hits_only):
            out.append(float(t))
    return out


def segments(info: Mapping[str, Any]) -> list[tuple[str, float, float]]:
    """The drive's condition segments (fog, tunnel, night): (kind, start, end) in s."""
    return [(c["kind"], float(c["start_s"]), float(c["end_s"])) for c in info.get("conditions", [])]


def in_segments(t: Array, segs: Sequence[tuple[str, float, float]]) -> BoolArray:
    """Whether each time lies inside one of ``segs``."""
    m = np.zeros(t.shape, dtype=np.bool_)
    for _, s0, s1 in segs:
        m |= (t >= s0) & (t <= s1)
    return m


def hp_error(t: Array, err: Array, window_s: float) -> Array:
    """``err`` minus its trailing mean over ``window_s`` (the detector's window T): the part
    of a pitch error that the detector sees (a constant offset cancels in s)."""
    n = max(2, round(window_s / float(np.median(np.diff(t)))))
    ok = np.isfinite(err)
    e = np.where(ok, err, 0.0)
    c = np.concatenate([[0.0], np.cumsum(e)])
    k = np.concatenate([[0], np.cumsum(ok)])
    idx = np.arange(err.size)
    lo = np.maximum(idx + 1 - n, 0)
    cnt = k[idx + 1] - k[lo]
    mean = (c[idx + 1] - c[lo]) / np.maximum(cnt, 1)
    out = err - mean
    out[(idx < n - 1) | ~ok] = math.nan
    return np.asarray(out, dtype=np.float64)


def rms(x: Array) -> float:
    """Root mean square of the finite values (NaN when there are none)."""
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan
