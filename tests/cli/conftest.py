"""Fixtures of the command-line tests: one tiny recording, and the logging levels that
`roadpreview.cli.main.main` sets put back after each test."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording


@pytest.fixture(scope="session")
def tiny(make_recording: Callable[..., Recording]) -> Recording:
    """8 s of the demo drive at 640x360 (240 frames, the lead crosses one bump at 6 s)."""
    return make_recording("demo", seed=0, duration_s=8.0, width=640, height=360)

