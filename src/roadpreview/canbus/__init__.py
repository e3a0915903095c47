"""CAN: the project's DBC and its E2E protection; CAN log files (BLF, ASC, candump) in and out."""

from roadpreview.canbus.dbc import (
    E2E_COUNTER_MODULUS,
    IMU_ACCEL,
    IMU_RATES,
    RESERVED_OUTPUT_IDS,
    VEHICLE_SPEED,
    WHEEL_SPEEDS,
    check_protected,
    e2e_layout,
    encode_protected,
    load_database,
)
from roadpreview.canbus.logio import CanLogReader, LogProblem, read_can_log, write_can_log

__all__ = [
    "E2E_COUNTER_MODULUS",
    "IMU_ACCEL",
    "IMU_RATES",
    "RESERVED_OUTPUT_IDS",
    "VEHICLE_SPEED",
    "WHEEL_SPEEDS",
    "CanLogReader",
    "LogProblem",
    "check_protected",
    "e2e_layout",
    "encode_protected",
    "load_database",
    "read_can_log",
    "write_can_log",
]
