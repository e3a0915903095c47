"""Write simulated IMU and speed samples as a car's logger would: CAN logs, phone-style IMU CSV.

CAN: each IMU sample becomes an ``IMU_RATES`` and an ``IMU_ACCEL`` frame,
each speed sample a ``VEHICLE_SPEED`` and a ``WHEEL_SPEEDS`` frame of the
project's DBC (``docs/can-interface.md``), encoded with cantools, with alive
counters and AUTOSAR E2E P01 CRCs. Frames are queued at their sample's
stamp and serialised on one bus: a frame is logged when its last bit has
been received, one frame after another (111 bits for 8 data bytes, stuff
bits ignored), so simultaneous frames are spread by about 0.22 ms at
500 kbit/s, as on a real bus. Times are written as Unix times: the
simulation's t = 0 is ``t0_unix_s`` (default `DEFAULT_T0_UNIX_S`).

CSV: ``t_s`` and the raw sensor axes (ISO 8855, x forward, y left, z up):
gyro in rad/s (right-handed, so gyro_y > 0 is nose DOWN) and specific force
in m/s² (gravity included), as a phone logger app writes them.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import can
import numpy as np
from cantools.database.can import Database
from cantools.database.can import Message as MessageDef

from roadpreview.canbus.dbc import (
    IMU_ACCEL,
    IMU_RATES,
    VEHICLE_SPEED,
    WHEEL_SPEEDS,
    e2e_layout,
    encode_protected,
    load_database,
)
from roadpreview.canbus.imu_csv import IMU_CSV_COLUMNS as IMU_CSV_COLUMNS
from roadpreview.canbus.imu_csv import IMU_CSV_COMMENT as _CSV_COMMENT
from roadpreview.canbus.imu_csv import read_imu_csv as read_imu_csv
from roadpreview.canbus.logio import write_can_log
from roadpreview.canbus.samples import ImuMeasurements
from roadpreview.errors import InputDataError
from roadpreview.sim.imu import DEG, KMH, ImuSamples, SpeedSamples

log = logging.getLogger(__name__)

# read_imu_csv and IMU_CSV_COLUMNS moved to roadpreview.canbus.imu_csv; imported above for users

#: default Unix time of the simulation's t = 0 (2025-01-01T00:00:00Z): loggers store Unix time
DEFAULT_T0_UNIX_S = 1735689600.0
#: default bus speed, bit/s (high-speed CAN of chassis buses)
DEFAULT_BITRATE = 500_000
#: the simulator's bus: channel 0 (ASC/BLF number it 1, candump calls it can0)
SIM_CHANNEL = 0

# ---------------------------------------------------------------------------------------------
# CAN


def _frame_bits(dlc: int) -> int:
    """Bits of a classic standard-ID data frame incl. interframe space, without stuff bits."""
    return 47 + 8 * dlc


def _encode_stream(
    message: MessageDef,
    times: np.ndarray,
    columns: Mapping[str, np.ndarray],
    channel: int,
) -> list[can.Message]:
    """One frame per row: physical values clipped to the DBC range, NaN -> SignalNotAvailable."""
    layout = e2e_layout(message)
    cols: dict[str, np.ndarray] = {}
    invalid: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        sig = message.get_signal_by_name(name)
        v = np.asarray(values, dtype=np.float64)
        bad = ~np.isfinite(v)
        has_sna = "SignalNotAvailable" in map(str, (sig.choices or {}).values())
        if bad.any() and not has_sna:
            raise InputDataError(f"{message.name}.{name}: NaN values and no SignalNotAvailable")
        lo = sig.minimum if sig.minimum is not None else -math.inf
        hi = sig.maximum if sig.maximum is not None else math.inf
        clipped = np.clip(np.where(bad, 0.0, v), lo, hi)
        n_clip = int(np.count_nonzero((v < lo) | (v > hi)))
        if n_clip:
            log.info(
                "%s.%s: %d value(s) clipped to [%g, %g] %s",
                message.name,
                name,
                n_clip,
                lo,
                hi,
                sig.unit or "",
            )
        cols[name] = clipped
        invalid[name] = bad
    out: list[can.Message] = []
    names = list(cols)
    for k in range(len(times)):
        frame_values: dict[str, float | int | str] = {}
        for name in names:
            frame_values[name] = "SignalNotAvailable" if invalid[name][k] else float(cols[name][k])
        data = encode_protected(message, frame_values, k, layout=layout)
        out.append(
            can.Message(
                timestamp=float(times[k]),
                arbitration_id=message.frame_id,
                is_extended_id=False,
                dlc=message.length,
                data=data,
                channel=channel,
                is_rx=True,
            )
        )
    return out


def imu_to_messages(
    samples: ImuSamples | ImuMeasurements,
    db: Database | None = None,
    *,
    t0_unix_s: float = DEFAULT_T0_UNIX_S,
    channel: int = SIM_CHANNEL,
) -> list[can.Message]:
    """``IMU_RATES`` then ``IMU_ACCEL`` per sample, timestamped at ``t0_unix_s`` + the stamp.

    Rates go out in roadpreview's convention (PitchRate nose up +, i.e. minus
    the sensor's y rate) in deg/s; values beyond a signal's range are
    clipped to it (the sensor's own saturation usually comes first).
    Counters start at 0 and run modulo 15. Use `merge_on_bus` to give the
    frames bus timing.
    """
    db = db or load_database()
    meas = samples.measurements() if isinstance(samples, ImuSamples) else samples
    times = t0_unix_s + np.asarray(meas.t_s, dtype=np.float64)
    rates_deg_s = meas.rates_rad_s / DEG
    rates = _encode_stream(
        db.get_message_by_name(IMU_RATES),
        times,
        {
            "RollRate": rates_deg_s[:, 0],
            "PitchRate": rates_deg_s[:, 1],
            "YawRate": rates_deg_s[:, 2],
        },
        channel,
    )
    accel = _encode_stream(
        db.get_message_by_name(IMU_ACCEL),
        times,
        {
            "AccelX": meas.accel_m_s2[:, 0],
            "AccelY": meas.accel_m_s2[:, 1],
            "AccelZ": meas.accel_m_s2[:, 2],
        },
        channel,
    )
    return [m for pair in zip(rates, accel, strict=True) for m in pair]


def speed_to_messages(
    samples: SpeedSamples,
    db: Database | None = None,
    *,
    t0_unix_s: float = DEFAULT_T0_UNIX_S,
    channel: int = SIM_CHANNEL,
) -> list[can.Message]:
    """``VEHICLE_SPEED`` then ``WHEEL_SPEEDS`` per sample (km/h on the bus)."""
    db = db or load_database()
    times = t0_unix_s + np.asarray(samples.t_stamp_s, dtype=np.float64)
    wheels_kmh = samples.wheel_speeds_m_s / KMH
    speed = _encode_stream(
        db.get_message_by_name(VEHICLE_SPEED),
        times,
        {
            "VehicleSpeed": samples.speed_m_s / KMH,
            "MovingDirection": samples.direction.astype(np.float64),
        },
        channel,
    )
    wheels = _encode_stream(
        db.get_message_by_name(WHEEL_SPEEDS),
        times,
        {
            "WheelSpeedFL": wheels_kmh[:, 0],
            "WheelSpeedFR": wheels_kmh[:, 1],
            "WheelSpeedRL": wheels_kmh[:, 2],
            "WheelSpeedRR": wheels_kmh[:, 3],
        },
        channel,
    )
    return [m for pair in zip(speed, wheels, strict=True) for m in pair]


def merge_on_bus(
    streams: Iterable[Sequence[can.Message]], *, bitrate: int | None = DEFAULT_BITRATE
) -> list[can.Message]:
    """Merge frame streams by time, as one CAN bus and its logger would see them.

    Each stream must be in time order. Frames are sent in order of their
    queue time (lower ID first on a tie, as arbitration decides) and each
    is logged when it has been fully received:
    ``max(queue time, end of the previous frame) + frame bits / bitrate``.
    ``bitrate=None`` only merges (times unchanged). The messages are
    updated in place and returned as one list in reception order.
    """
    keyed = (
        [(m.timestamp, m.arbitration_id, i, j, m) for j, m in enumerate(s)]
        for i, s in enumerate(streams)
    )
    merged = [item[-1] for item in heapq.merge(*keyed, key=lambda x: x[:4])]
    if bitrate is None:
        return merged
    if bitrate <= 0:
        raise InputDataError(f"bitrate = {bitrate}: must be > 0 bit/s")
    bus_free = -math.inf
    for m in merged:
        end = max(m.timestamp, bus_free) + _frame_bits(m.dlc) / bitrate
        m.timestamp = end
        bus_free = end
    return merged


def write_drive_can(
    path: str | Path,
    imu: ImuSamples | ImuMeasurements | None,
    speed: SpeedSamples | None = None,
    *,
    db: Database | None = None,
    t0_unix_s: float = DEFAULT_T0_UNIX_S,
    bitrate: int | None = DEFAULT_BITRATE,
    channel: int = SIM_CHANNEL,
) -> int:
    """Write a drive's CAN log (format by suffix: .blf, .asc, .log, .asc.gz, .log.gz).

    Returns the number of frames. The log's times are ``t0_unix_s`` plus the
    simulation time plus bus delay (`merge_on_bus`).
    """
    db = db or load_database()
    streams: list[list[can.Message]] = []
    if imu is not None:
        streams.append(imu_to_messages(imu, db, t0_unix_s=t0_unix_s, channel=channel))
    if speed is not None:
        streams.append(speed_to_messages(speed, db, t0_unix_s=t0_unix_s, channel=channel))
    messages = merge_on_bus(streams, bitrate=bitrate)
    return write_can_log(path, messages)


# ---------------------------------------------------------------------------------------------
# IMU CSV


def write_imu_csv(path: str | Path, samples: ImuSamples | ImuMeasurements) -> int:
    """Write stamped IMU samples as a phone-style CSV (module docstring); return the row count.

    Times are written to 1 µs, values with 9 significant digits.
    """
    meas = samples.measurements() if isinstance(samples, ImuSamples) else samples
    table = np.column_stack([meas.t_s, meas.gyro_rad_s, meas.accel_m_s2])
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(_CSV_COMMENT + "\n")
        f.write(",".join(IMU_CSV_COLUMNS) + "\n")
        for row in table:
            f.write(f"{row[0]:.6f}," + ",".join(f"{v:.9g}" for v in row[1:]) + "\n")
    return len(table)
