"""E5, alert lead time: the product's alerts matched to the wild set's lead crossings."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from roadpreview.eval.experiments.base import jf
from roadpreview.eval.experiments.data import EvalData
from roadpreview.pipeline.truthmatch import match_alerts


@dataclass(frozen=True)
class LeadTimeRow:
    alerts_hits: int
    lead_crossings: int
    false_alarms: int
    minutes: float
    #: ego arrival minus alert emission of each detected crossing, s
    lead_times_s: tuple[float, ...]

    @property
    def recall(self) -> float:
        return self.alerts_hits / self.lead_crossings if self.lead_crossings else math.nan

    @property
    def false_alarms_per_min(self) -> float:
        return self.false_alarms / self.minutes if self.minutes else math.nan

    def as_dict(self) -> dict[str, Any]:
        arr = np.asarray(self.lead_times_s, dtype=np.float64)
        some = bool(arr.size)
        return {
            "alerts_hits": self.alerts_hits,
            "lead_crossings": self.lead_crossings,
            "recall": jf(self.recall),
            "false_alarms_per_min": jf(self.false_alarms_per_min),
            "lead_time_median_s": jf(np.median(arr)) if some else None,
            "lead_time_p10_s": jf(np.percentile(arr, 10)) if some else None,
            "lead_time_p90_s": jf(np.percentile(arr, 90)) if some else None,
            "lead_time_min_s": jf(arr.min()) if some else None,
            "late_alerts": int((arr <= 0).sum()),
        }


@dataclass(frozen=True)
class LeadTime:
    methods: dict[str, LeadTimeRow]

    def as_dict(self) -> dict[str, Any]:
        return {"methods": {m: r.as_dict() for m, r in self.methods.items()}}


def lead_time(data: EvalData) -> LeadTime:
    """The product's alerts (default detector settings) matched to the wild set's lead
    crossings: recall, false alarms per minute and the lead time (ego arrival minus
    alert emission) of the detected ones."""
    res: dict[str, LeadTimeRow] = {}
    for m in data.method_names:
        hits = expected = fa = 0
        minutes = 0.0
        lead_times: list[float] = []
        for job in data.jobs["wild"]:
            info = data.info(job)
            dur = float(info["duration_s"])
            rep = match_alerts(
                data.detection(job, m).alerts,
                info["events"],
                t0=0.0,
                duration_s=dur,
                max_distance_m=math.inf,
            )
            hits += rep.hits
            expected += rep.expected
            fa += len(rep.false_alarms)
            minutes += dur / 60.0
            lead_times += [
                r.lead_time_s
                for r in rep.rows
                if r.alert is not None and r.expected and math.isfinite(r.lead_time_s)
            ]
        res[m] = LeadTimeRow(hits, expected, fa, minutes, tuple(lead_times))
    return LeadTime(res)
