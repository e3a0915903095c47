"""A phone-style IMU CSV (``roadpreview.canbus.imu_csv`` reads the format) as a source of
`ImuSample`, shifted by ``offset_s`` onto the pipeline's clock; with a calibrated ``mount``
(a mapping's ``[mount]``, ``roadpreview calibrate``) turned into the car's axes first."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from pathlib import Path

from roadpreview.canbus.imu_csv import imu_samples, read_imu_csv
from roadpreview.canbus.samples import ImuMeasurements, ImuMount
from roadpreview.errors import InputDataError
from roadpreview.plausibility import PlausibilityConfig, SampleGate
from roadpreview.sources import shifted
from roadpreview.types import InputSample


class ImuCsvSource:
    """The rows of an IMU CSV as samples, time ``t_s + offset_s``; bad rows are skipped
    (and logged) by the reader."""

    live = False

    def __init__(
        self,
        path: str | Path,
        *,
        offset_s: float = 0.0,
        mount: ImuMount | None = None,
        plausibility: PlausibilityConfig | None = None,
    ) -> None:
        self.path = Path(path)
        self.name = str(self.path)
        if not self.path.is_file():
            raise InputDataError(f"{self.path}: IMU CSV not found")
        self.offset_s = offset_s
        self.mount = mount
        self._table: ImuMeasurements | None = None
        self._closed = False
        self.gate = SampleGate(
            plausibility
        )  #: the plausibility gate (ranges, gyro spikes) of the rows

    @property
    def problems(self) -> Counter[str]:
        """Rows skipped by the reader and rejected by the plausibility gate, by reason."""
        table = self._table.problems if self._table is not None else Counter()
        return table + self.gate.problems

    @property
    def errors(self) -> int:
        """Rows lost: skipped as unreadable, or rejected as implausible."""
        p = self.problems
        return sum(v for k, v in p.items() if k != "spike_gate_reset")

    @property
    def table(self) -> ImuMeasurements:
        """The file's rows, read once (its first time tells its clock before a replay)."""
        if self._table is None:
            self._table = read_imu_csv(self.path)
        return self._table

    @property
    def first_s(self) -> float:
        """The first time stamp as stored, s."""
        return float(self.table.t_s[0])

    def __iter__(self) -> Iterator[InputSample]:
        for s in imu_samples(self.table, source=str(self.path), mount=self.mount, gate=self.gate):
            if self._closed:
                return
            yield shifted(s, self.offset_s)

    def close(self) -> None:
        self._closed = True


__all__ = ["ImuCsvSource"]
