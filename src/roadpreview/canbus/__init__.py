"""CAN: the project's DBC and E2E protection, input decoding for any car, outputs, logs, live bus.

* `dbc`: ``roadpreview.dbc`` (inputs; outputs ``RP_ALERT``, ``RP_STATUS``,
  ``RP_ROAD_STATUS``, ``RP_ALERT_DETAIL``, ``RP_CONFIRM``), AUTOSAR E2E P01.
* `mapping` + `decode`: any car's DBC + a mapping file -> `ImuSample` / `SpeedSample`.
* `imu_csv`: phone-style IMU CSV files.
* `output`: `Alert` / `ConfirmationResult` / `Status` -> E2E-protected frames, and back.
* `logio`: CAN log files in every format python-can reads (BLF, ASC, candump, TRC, CSV, .gz).
* `live`: python-can buses, a bounded-queue listener, periodic status.
"""

from roadpreview.canbus.dbc import (
    E2E_COUNTER_MODULUS,
    IMU_ACCEL,
    IMU_RATES,
    RESERVED_OUTPUT_IDS,
    RP_ALERT,
    RP_ALERT_DETAIL,
    RP_CONFIRM,
    RP_ROAD_STATUS,
    RP_STATUS,
    VEHICLE_SPEED,
    WHEEL_SPEEDS,
    check_protected,
    e2e_layout,
    encode_protected,
    load_database,
)
from roadpreview.canbus.decode import (
    CanInputDecoder,
    DecodeStats,
    FrameProblem,
    decode_log,
    split_samples,
)
from roadpreview.canbus.imu_csv import IMU_CSV_COLUMNS, imu_samples, read_imu_csv
from roadpreview.canbus.live import BoundedQueueListener, CanOutput, CanReceiver, open_bus, replay
from roadpreview.canbus.logio import CanLogReader, LogProblem, read_can_log, write_can_log
from roadpreview.canbus.mapping import (
    QUANTITIES,
    InputMapping,
    available_mappings,
    bind_mapping,
    load_mapping,
)
from roadpreview.canbus.output import (
    DETECTOR_CODES,
    AlertDetailEncoder,
    AlertEncoder,
    ConfirmEncoder,
    OutputDecoder,
    OutputEncoders,
    ReceivedAlert,
    ReceivedAlertDetail,
    ReceivedConfirm,
    ReceivedOutput,
    ReceivedRoadStatus,
    ReceivedStatus,
    RoadStatusEncoder,
    StatusEncoder,
    alert_frames,
    detector_code,
)
from roadpreview.types import ImuSample, InputSample, SpeedSample, Status

__all__ = [
    "DETECTOR_CODES",
    "E2E_COUNTER_MODULUS",
    "IMU_ACCEL",
    "IMU_CSV_COLUMNS",
    "IMU_RATES",
    "QUANTITIES",
    "RESERVED_OUTPUT_IDS",
    "RP_ALERT",
    "RP_ALERT_DETAIL",
    "RP_CONFIRM",
    "RP_ROAD_STATUS",
    "RP_STATUS",
    "VEHICLE_SPEED",
    "WHEEL_SPEEDS",
    "AlertDetailEncoder",
    "AlertEncoder",
    "BoundedQueueListener",
    "CanInputDecoder",
    "CanLogReader",
    "CanOutput",
    "CanReceiver",
    "ConfirmEncoder",
    "DecodeStats",
    "FrameProblem",
    "ImuSample",
    "InputMapping",
    "InputSample",
    "LogProblem",
    "OutputDecoder",
    "OutputEncoders",
    "ReceivedAlert",
    "ReceivedAlertDetail",
    "ReceivedConfirm",
    "ReceivedOutput",
    "ReceivedRoadStatus",
    "ReceivedStatus",
    "RoadStatusEncoder",
    "SpeedSample",
    "Status",
    "StatusEncoder",
    "alert_frames",
    "available_mappings",
    "bind_mapping",
    "check_protected",
    "decode_log",
    "detector_code",
    "e2e_layout",
    "encode_protected",
    "imu_samples",
    "load_database",
    "load_mapping",
    "open_bus",
    "read_can_log",
    "read_imu_csv",
    "replay",
    "split_samples",
    "write_can_log",
]
