"""Fixtures shared by the fault tests (issue 17's bad-input suite).

``fault_drive``: one short simulated drive for every fault test, rendered once per session
(through the session's ``make_recording`` cache): the ``demo`` preset, seed 0, 10 s at
640x360, with ``video.mp4``, ``frames.csv``, ``can.blf`` (IMU 0x130/0x131 at ~104 Hz, speed
at 50 Hz, E2E-protected) and ``imu.csv``. Copy or rewrite its files in ``tmp_path`` to inject
a fault; replay it with ``roadpreview.apps.replay.ReplayInputs.from_recording(
fault_drive.folder)`` (``dataclasses.replace(inputs, can_logs=[...])`` for a rewritten log).
A replay of it takes about 8-10 s on a loaded 2-core machine: share a clean run per module.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

FAULT_DRIVE = {"seed": 0, "duration_s": 10.0, "width": 640, "height": 360}


@pytest.fixture(scope="session")
def fault_drive(make_recording: Callable[..., Recording]) -> Recording:
    """The fault tests' drive (module docstring)."""
    return make_recording("demo", **FAULT_DRIVE)
