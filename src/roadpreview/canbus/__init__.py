"""CAN: the project's DBC and E2E protection, input decoding for any car, outputs, logs, live bus.

* `dbc`: ``roadpreview.dbc`` (inputs; outputs ``RP_ALERT``, ``RP_ALERT_DETAIL``,
  ``RP_ALERT_END``, ``RP_STATUS``, ``RP_ROAD_STATUS``, ``RP_CONFIRM``, ``RP_INPUT_STATUS``,
  ``RP_PREVIEW``), AUTOSAR E2E P01.
* `mapping` + `decode`: any car's DBC + a mapping file -> `ImuSample` / `SpeedSample`.
* `imu_csv`: phone-style IMU CSV files; `samples.ImuMount`: a calibrated IMU mount.
* `output`: `Alert` / `ConfirmationResult` / `Status` / `RoadPreview` -> E2E-protected
  frames; `received`: those frames back, as a receiver sees them (`OutputDecoder`);
  `receiver`: reference receivers, each alert's state (`AlertReceiver`) and the road
  preview put together again (`PreviewAssembler`).
* `repetition`: each alert repeated with its distance and time to arrival as of the send
  until the ego has passed the spot, then ``RP_ALERT_END`` (passed / cancelled).
* `logio`: CAN log files in every format python-can reads (BLF, ASC, candump, TRC, CSV,
  MF4, SQLite, .gz).
* `live`: python-can buses, a bounded-queue listener, a log played onto a bus.
* `cyclic`: frames built and sent every period by a supervised thread of their own on a
  clock (RP_STATUS on a live bus).

The names below are imported lazily (PEP 562): ``import roadpreview.canbus`` loads no
python-can bus, DBC or E2E code until one of them is used.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the real names for type checkers; at run time they load lazily
    from roadpreview.canbus.dbc import (
        DBC_VERSION as DBC_VERSION,
    )
    from roadpreview.canbus.dbc import (
        E2E_COUNTER_MODULUS as E2E_COUNTER_MODULUS,
    )
    from roadpreview.canbus.dbc import (
        IMU_ACCEL as IMU_ACCEL,
    )
    from roadpreview.canbus.dbc import (
        IMU_RATES as IMU_RATES,
    )
    from roadpreview.canbus.dbc import (
        RESERVED_OUTPUT_IDS as RESERVED_OUTPUT_IDS,
    )
    from roadpreview.canbus.dbc import (
        RP_ALERT as RP_ALERT,
    )
    from roadpreview.canbus.dbc import (
        RP_ALERT_DETAIL as RP_ALERT_DETAIL,
    )
    from roadpreview.canbus.dbc import (
        RP_ALERT_END as RP_ALERT_END,
    )
    from roadpreview.canbus.dbc import (
        RP_CONFIRM as RP_CONFIRM,
    )
    from roadpreview.canbus.dbc import (
        RP_INPUT_STATUS as RP_INPUT_STATUS,
    )
    from roadpreview.canbus.dbc import (
        RP_PREVIEW as RP_PREVIEW,
    )
    from roadpreview.canbus.dbc import (
        RP_ROAD_STATUS as RP_ROAD_STATUS,
    )
    from roadpreview.canbus.dbc import (
        RP_STATUS as RP_STATUS,
    )
    from roadpreview.canbus.dbc import (
        VEHICLE_SPEED as VEHICLE_SPEED,
    )
    from roadpreview.canbus.dbc import (
        WHEEL_SPEEDS as WHEEL_SPEEDS,
    )
    from roadpreview.canbus.dbc import (
        check_protected as check_protected,
    )
    from roadpreview.canbus.dbc import (
        e2e_layout as e2e_layout,
    )
    from roadpreview.canbus.dbc import (
        encode_protected as encode_protected,
    )
    from roadpreview.canbus.dbc import (
        load_database as load_database,
    )
    from roadpreview.canbus.decode import (
        CanInputDecoder as CanInputDecoder,
    )
    from roadpreview.canbus.decode import (
        DecodeStats as DecodeStats,
    )
    from roadpreview.canbus.decode import (
        FrameProblem as FrameProblem,
    )
    from roadpreview.canbus.decode import (
        decode_log as decode_log,
    )
    from roadpreview.canbus.decode import (
        split_samples as split_samples,
    )
    from roadpreview.canbus.imu_csv import (
        IMU_CSV_COLUMNS as IMU_CSV_COLUMNS,
    )
    from roadpreview.canbus.imu_csv import (
        imu_samples as imu_samples,
    )
    from roadpreview.canbus.imu_csv import (
        read_imu_csv as read_imu_csv,
    )
    from roadpreview.canbus.live import (
        BoundedQueueListener as BoundedQueueListener,
    )
    from roadpreview.canbus.live import (
        CanLogPlayer as CanLogPlayer,
    )
    from roadpreview.canbus.live import (
        CanReceiver as CanReceiver,
    )
    from roadpreview.canbus.live import (
        open_bus as open_bus,
    )
    from roadpreview.canbus.live import (
        replay as replay,
    )
    from roadpreview.canbus.logio import (
        CanLogReader as CanLogReader,
    )
    from roadpreview.canbus.logio import (
        LogProblem as LogProblem,
    )
    from roadpreview.canbus.logio import (
        read_can_log as read_can_log,
    )
    from roadpreview.canbus.logio import (
        write_can_log as write_can_log,
    )
    from roadpreview.canbus.mapping import (
        QUANTITIES as QUANTITIES,
    )
    from roadpreview.canbus.mapping import (
        InputMapping as InputMapping,
    )
    from roadpreview.canbus.mapping import (
        available_mappings as available_mappings,
    )
    from roadpreview.canbus.mapping import (
        bind_mapping as bind_mapping,
    )
    from roadpreview.canbus.mapping import (
        load_mapping as load_mapping,
    )
    from roadpreview.canbus.output import (
        DETECTOR_CODES as DETECTOR_CODES,
    )
    from roadpreview.canbus.output import (
        AlertDetailEncoder as AlertDetailEncoder,
    )
    from roadpreview.canbus.output import (
        AlertEncoder as AlertEncoder,
    )
    from roadpreview.canbus.output import (
        AlertEndEncoder as AlertEndEncoder,
    )
    from roadpreview.canbus.output import (
        ConfirmEncoder as ConfirmEncoder,
    )
    from roadpreview.canbus.output import (
        OutputEncoders as OutputEncoders,
    )
    from roadpreview.canbus.output import (
        PreviewEncoder as PreviewEncoder,
    )
    from roadpreview.canbus.output import (
        RoadStatusEncoder as RoadStatusEncoder,
    )
    from roadpreview.canbus.output import (
        StatusEncoder as StatusEncoder,
    )
    from roadpreview.canbus.output import (
        alert_frames as alert_frames,
    )
    from roadpreview.canbus.output import (
        detector_code as detector_code,
    )
    from roadpreview.canbus.received import OutputDecoder as OutputDecoder
    from roadpreview.canbus.received import ReceivedAlert as ReceivedAlert
    from roadpreview.canbus.received import ReceivedAlertDetail as ReceivedAlertDetail
    from roadpreview.canbus.received import ReceivedAlertEnd as ReceivedAlertEnd
    from roadpreview.canbus.received import ReceivedConfirm as ReceivedConfirm
    from roadpreview.canbus.received import ReceivedInputStatus as ReceivedInputStatus
    from roadpreview.canbus.received import ReceivedOutput as ReceivedOutput
    from roadpreview.canbus.received import ReceivedPreviewHeader as ReceivedPreviewHeader
    from roadpreview.canbus.received import ReceivedPreviewPage as ReceivedPreviewPage
    from roadpreview.canbus.received import ReceivedRoadStatus as ReceivedRoadStatus
    from roadpreview.canbus.received import ReceivedStatus as ReceivedStatus
    from roadpreview.canbus.receiver import AlertReceiver as AlertReceiver
    from roadpreview.canbus.receiver import AlertTransition as AlertTransition
    from roadpreview.canbus.receiver import PreviewAssembler as PreviewAssembler
    from roadpreview.canbus.receiver import ReceivedAlertLife as ReceivedAlertLife
    from roadpreview.canbus.receiver import ReceiverState as ReceiverState
    from roadpreview.canbus.repetition import (
        AlertEnd as AlertEnd,
    )
    from roadpreview.canbus.repetition import (
        AlertRepeater as AlertRepeater,
    )
    from roadpreview.canbus.repetition import (
        AlertSend as AlertSend,
    )
    from roadpreview.canbus.repetition import (
        EndCause as EndCause,
    )
    from roadpreview.canbus.repetition import (
        EndReason as EndReason,
    )
    from roadpreview.canbus.repetition import (
        RepetitionConfig as RepetitionConfig,
    )
    from roadpreview.canbus.samples import (
        ImuMount as ImuMount,
    )

#: public name -> the module that defines it
_EXPORTS = {
    "AlertDetailEncoder": "roadpreview.canbus.output",
    "AlertEncoder": "roadpreview.canbus.output",
    "AlertEnd": "roadpreview.canbus.repetition",
    "AlertEndEncoder": "roadpreview.canbus.output",
    "AlertReceiver": "roadpreview.canbus.receiver",
    "AlertRepeater": "roadpreview.canbus.repetition",
    "AlertSend": "roadpreview.canbus.repetition",
    "AlertTransition": "roadpreview.canbus.receiver",
    "BoundedQueueListener": "roadpreview.canbus.live",
    "CanInputDecoder": "roadpreview.canbus.decode",
    "CanLogPlayer": "roadpreview.canbus.live",
    "CanLogReader": "roadpreview.canbus.logio",
    "CanReceiver": "roadpreview.canbus.live",
    "ConfirmEncoder": "roadpreview.canbus.output",
    "DBC_VERSION": "roadpreview.canbus.dbc",
    "DETECTOR_CODES": "roadpreview.canbus.output",
    "DecodeStats": "roadpreview.canbus.decode",
    "E2E_COUNTER_MODULUS": "roadpreview.canbus.dbc",
    "EndCause": "roadpreview.canbus.repetition",
    "EndReason": "roadpreview.canbus.repetition",
    "FrameProblem": "roadpreview.canbus.decode",
    "IMU_ACCEL": "roadpreview.canbus.dbc",
    "IMU_CSV_COLUMNS": "roadpreview.canbus.imu_csv",
    "IMU_RATES": "roadpreview.canbus.dbc",
    "ImuMount": "roadpreview.canbus.samples",
    "InputMapping": "roadpreview.canbus.mapping",
    "LogProblem": "roadpreview.canbus.logio",
    "OutputDecoder": "roadpreview.canbus.received",
    "OutputEncoders": "roadpreview.canbus.output",
    "PreviewAssembler": "roadpreview.canbus.receiver",
    "PreviewEncoder": "roadpreview.canbus.output",
    "QUANTITIES": "roadpreview.canbus.mapping",
    "RESERVED_OUTPUT_IDS": "roadpreview.canbus.dbc",
    "RP_ALERT": "roadpreview.canbus.dbc",
    "RP_ALERT_DETAIL": "roadpreview.canbus.dbc",
    "RP_ALERT_END": "roadpreview.canbus.dbc",
    "RP_CONFIRM": "roadpreview.canbus.dbc",
    "RP_INPUT_STATUS": "roadpreview.canbus.dbc",
    "RP_PREVIEW": "roadpreview.canbus.dbc",
    "RP_ROAD_STATUS": "roadpreview.canbus.dbc",
    "RP_STATUS": "roadpreview.canbus.dbc",
    "ReceivedAlert": "roadpreview.canbus.received",
    "ReceivedAlertDetail": "roadpreview.canbus.received",
    "ReceivedAlertEnd": "roadpreview.canbus.received",
    "ReceivedAlertLife": "roadpreview.canbus.receiver",
    "ReceivedConfirm": "roadpreview.canbus.received",
    "ReceivedOutput": "roadpreview.canbus.received",
    "ReceivedInputStatus": "roadpreview.canbus.received",
    "ReceivedPreviewHeader": "roadpreview.canbus.received",
    "ReceivedPreviewPage": "roadpreview.canbus.received",
    "ReceiverState": "roadpreview.canbus.receiver",
    "ReceivedRoadStatus": "roadpreview.canbus.received",
    "ReceivedStatus": "roadpreview.canbus.received",
    "RepetitionConfig": "roadpreview.canbus.repetition",
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
