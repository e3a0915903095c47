"""A short simulated drive for the input tests (rendered once per session), and helpers."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

#: the drive every input test replays: 4 s at 30 fps, 640x360, phone-grade IMU at 104 Hz
#: whose stamps lag the true sample times by imu_time_offset_s (truth.json)
DRIVE = {"duration_s": 4.0, "width": 640, "height": 360}


@pytest.fixture
def drive(make_recording: Callable[..., Any]) -> Any:
    return make_recording("demo", seed=0, **DRIVE)
