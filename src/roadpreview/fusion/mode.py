"""The fusion modes, shared by the fusion, the detector, the CAN status message and reports."""

from __future__ import annotations

from enum import IntEnum


class FusionMode(IntEnum):
    """Where the pitch used for compensation comes from at a frame.

    The integer values are the ones sent on CAN (``data/roadpreview.dbc``).
    """

    #: visual pitch and gyro both valid and fused
    FUSED = 0
    #: no IMU (absent or timed out): visual pitch only
    VISUAL_ONLY = 1
    #: vision failed (too few points, poor fit, low texture): gyro integration, bias frozen
    IMU_ONLY = 2
    #: neither source usable: no compensation can be trusted
    DEGRADED = 3
