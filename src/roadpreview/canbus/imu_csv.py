"""Read IMU samples from a phone-style CSV (the layout the simulator and logging apps write).

The file starts with optional ``#`` comment lines, then the header
`IMU_CSV_COLUMNS`::

    t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2

``t_s`` is the sensor time stamp in seconds; the values are the chip's axes
(ISO 8855: x forward, y left, z up): gyro right-handed in rad/s (so
``gyro_y > 0`` is nose DOWN) and specific force in m/s² (gravity included,
+9.81 on z at rest). Bad rows are logged with file and line and skipped.
`imu_samples` turns the table into the `ImuSample` stream the CAN decoder
also produces, in roadpreview's conventions (through an `ImuMount` when the
phone does not lie with its axes along the car's), through the same plausibility
gate as the CAN decoder (`roadpreview.plausibility`: physical ranges, gyro
spikes): an implausible row costs that row, is counted and logged once. ``roadpreview.sim.canlog``
writes these files and re-exports the reader.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from pathlib import Path

import numpy as np

from roadpreview.canbus.samples import RATE_SIGNS, ImuMeasurements, ImuMount
from roadpreview.errors import InputDataError
from roadpreview.plausibility import SampleGate
from roadpreview.types import ImuSample

log = logging.getLogger(__name__)

IMU_CSV_COLUMNS = (
    "t_s",
    "gyro_x_rad_s",
    "gyro_y_rad_s",
    "gyro_z_rad_s",
    "accel_x_m_s2",
    "accel_y_m_s2",
    "accel_z_m_s2",
)
#: the comment line the simulator writes first
IMU_CSV_COMMENT = (
    "# roadpreview IMU CSV: t_s = sensor time stamp (s); axes x forward, y left, z up"
    " (ISO 8855); gyro right-handed rad/s (gyro_y > 0 = nose down); accel = specific force"
    " m/s^2 incl. gravity (+9.81 on z at rest)"
)


def read_imu_csv(path: str | Path) -> ImuMeasurements:
    """Read an IMU CSV written by `write_imu_csv` (or a phone app in the same layout).

    Lines starting with ``#`` and blank lines are ignored; the first other
    line must be the header `IMU_CSV_COLUMNS`. A bad row (wrong column
    count, a value that is not a finite number, a time not after the
    previous row's) is logged with its file and line number and skipped.
    Raises `InputDataError` naming the file for a missing file, a wrong
    header or no valid row.
    """
    try:
        f = open(path, encoding="utf-8", errors="replace")  # noqa: SIM115 - closed below
    except FileNotFoundError:
        raise InputDataError(f"{path}: IMU CSV not found") from None
    rows: list[list[float]] = []
    skipped = 0
    header_seen = False
    with f:
        for line_no, raw in enumerate(f, start=1):
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            fields = [c.strip() for c in line.split(",")]
            if not header_seen:
                if tuple(fields) != IMU_CSV_COLUMNS:
                    raise InputDataError(
                        f"{path}:{line_no}: header {line!r}; expected {','.join(IMU_CSV_COLUMNS)}"
                    )
                header_seen = True
                continue
            reason = ""
            values: list[float] = []
            if len(fields) != len(IMU_CSV_COLUMNS):
                reason = f"{len(fields)} columns, expected {len(IMU_CSV_COLUMNS)}"
            else:
                try:
                    values = [float(c) for c in fields]
                except ValueError as exc:
                    reason = f"not a number ({exc})"
                else:
                    bad = [IMU_CSV_COLUMNS[i] for i, v in enumerate(values) if not math.isfinite(v)]
                    if bad:
                        reason = f"non-finite {', '.join(bad)}"
                    elif rows and values[0] <= rows[-1][0]:
                        reason = f"t_s = {values[0]} not after the previous {rows[-1][0]}"
            if reason:
                skipped += 1
                log.warning("%s:%d: bad IMU row (%s); row skipped", path, line_no, reason)
                continue
            rows.append(values)
    if not header_seen:
        raise InputDataError(f"{path}: no header line; expected {','.join(IMU_CSV_COLUMNS)}")
    if not rows:
        raise InputDataError(f"{path}: no valid IMU rows ({skipped} bad)")
    if skipped:
        log.warning("%s: %d bad IMU row(s) skipped, %d read", path, skipped, len(rows))
    table = np.asarray(rows, dtype=np.float64)
    problems: Counter[str] = Counter({"skipped_bad_line": skipped} if skipped else {})
    return ImuMeasurements(table[:, 0].copy(), table[:, 1:4].copy(), table[:, 4:7].copy(), problems)


def imu_samples(
    meas: ImuMeasurements,
    source: str = "imu.csv",
    *,
    mount: ImuMount | None = None,
    gate: SampleGate | None = None,
) -> list[ImuSample]:
    """The rows as `ImuSample` in roadpreview's conventions (pitch nose up +: -gyro_y);
    with a ``mount`` (a calibration) first turned into the car's axes and the camera's
    clock. Rows the plausibility ``gate`` (default: a new one with the car defaults)
    rejects are left out, counted in ``gate.problems`` and logged once with the file."""
    if mount is not None:
        meas = mount.apply(meas)
    gate = gate if gate is not None else SampleGate()
    rates = meas.gyro_rad_s * RATE_SIGNS
    out: list[ImuSample] = []
    rejected = 0
    for t, r, a in zip(meas.t_s, rates, meas.accel_m_s2, strict=True):
        sample = ImuSample(
            float(t),
            (float(r[0]), float(r[1]), float(r[2])),
            (float(a[0]), float(a[1]), float(a[2])),
            source,
        )
        why = gate.check(sample)
        if why:
            rejected += 1
            if rejected == 1:
                log.warning(
                    "%s: IMU row at t_s = %.6f skipped: %s (%s); further ones are counted",
                    source,
                    sample.t_s,
                    why,
                    gate.describe(sample, why),
                )
            continue
        out.append(sample)
    if rejected:
        log.warning(
            "%s: %d implausible IMU row(s) skipped (%s), %d kept",
            source,
            rejected,
            ", ".join(f"{k} {v}" for k, v in sorted(gate.problems.items())),
            len(out),
        )
    return out
