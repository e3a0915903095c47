"""CAN: the project's DBC and E2E protection, input decoding for any car, outputs, logs, live bus.

* `dbc`: ``roadpreview.dbc`` (inputs; outputs ``RP_ALERT``, ``RP_STATUS``,
  ``RP_ROAD_STATUS``, ``RP_ALERT_DETAIL``, ``RP_CONFIRM``), AUTOSAR E2E P01.
* `mapping` + `decode`: any car's DBC + a mapping file -> `ImuSample` / `SpeedSample`.
* `imu_csv`: phone-style IMU CSV files.
* `output`: `Alert` / `ConfirmationResult` / `Status` -> E2E-protected frames, and back.
* `logio`: CAN log files in every format python-can reads (BLF, ASC, candump, TRC, CSV, .gz).
* `live`: python-can buses, a bounded-queue listener, a log played onto a bus.

The names below are imported lazily (PEP 562): ``import roadpreview.canbus`` loads no
python-can bus, DBC or E2E code until one of them is used.
"""

from __future__ import annotations

import importlib
from typing import Any

#: public name -> the module that defines it
_EXPORTS = {
    "AlertDetailEncoder": "roadpreview.canbus.output",
    "AlertEncoder": "roadpreview.canbus.output",
    "BoundedQueueListener": "roadpreview.canbus.live",
    "CanInputDecoder": "roadpreview.canbus.decode",
    "CanLogReader": "roadpreview.canbus.logio",
    "CanReceiver": "roadpreview.canbus.live",
    "ConfirmEncoder": "roadpreview.canbus.output",
    "DETECTOR_CODES": "roadpreview.canbus.output",
    "DecodeStats": "roadpreview.canbus.decode",
    "E2E_COUNTER_MODULUS": "roadpreview.canbus.dbc",
    "FrameProblem": "roadpreview.canbus.decode",
    "IMU_ACCEL": "roadpreview.canbus.dbc",
    "IMU_CSV_COLUMNS": "roadpreview.canbus.imu_csv",
    "IMU_RATES": "roadpreview.canbus.dbc",
    "InputMapping": "roadpreview.canbus.mapping",
    "LogProblem": "roadpreview.canbus.logio",
    "OutputDecoder": "roadpreview.canbus.output",
    "OutputEncoders": "roadpreview.canbus.output",
    "QUANTITIES": "roadpreview.canbus.mapping",
    "RESERVED_OUTPUT_IDS": "roadpreview.canbus.dbc",
    "RP_ALERT": "roadpreview.canbus.dbc",
    "RP_ALERT_DETAIL": "roadpreview.canbus.dbc",
    "RP_CONFIRM": "roadpreview.canbus.dbc",
    "RP_ROAD_STATUS": "roadpreview.canbus.dbc",
    "RP_STATUS": "roadpreview.canbus.dbc",
    "ReceivedAlert": "roadpreview.canbus.output",
    "ReceivedAlertDetail": "roadpreview.canbus.output",
    "ReceivedConfirm": "roadpreview.canbus.output",
    "ReceivedOutput": "roadpreview.canbus.output",
    "ReceivedRoadStatus": "roadpreview.canbus.output",
    "ReceivedStatus": "roadpreview.canbus.output",
    "RoadStatusEncoder": "roadpreview.canbus.output",
    "StatusEncoder": "roadpreview.canbus.output",
    "VEHICLE_SPEED": "roadpreview.canbus.dbc",
    "WHEEL_SPEEDS": "roadpreview.canbus.dbc",
    "alert_frames": "roadpreview.canbus.output",
    "available_mappings": "roadpreview.canbus.mapping",
    "bind_mapping": "roadpreview.canbus.mapping",
    "check_protected": "roadpreview.canbus.dbc",
    "decode_log": "roadpreview.canbus.decode",
    "detector_code": "roadpreview.canbus.output",
    "e2e_layout": "roadpreview.canbus.dbc",
    "encode_protected": "roadpreview.canbus.dbc",
    "imu_samples": "roadpreview.canbus.imu_csv",
    "load_database": "roadpreview.canbus.dbc",
    "load_mapping": "roadpreview.canbus.mapping",
    "open_bus": "roadpreview.canbus.live",
    "read_can_log": "roadpreview.canbus.logio",
    "read_imu_csv": "roadpreview.canbus.imu_csv",
    "replay": "roadpreview.canbus.live",
    "split_samples": "roadpreview.canbus.decode",
    "write_can_log": "roadpreview.canbus.logio",
}


def __getattr__(name: str) -> Any:
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])


__all__ = sorted(_EXPORTS)
