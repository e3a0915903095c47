"""SIGTERM (what systemd and ``kill`` send) in the middle of ``roadpreview replay``: exit
130, and every output readable with what was processed, the summary marked interrupted.
(SIGINT, Ctrl-C: tests/pipeline/test_replay.py.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from roadpreview.canbus import read_can_log

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

SRC = Path(__file__).resolve().parents[2] / "src"


@pytest.mark.slow
def test_sigterm_leaves_every_output_readable_and_says_interrupted(
    tiny: Recording, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "roadpreview",
            "replay",
            str(tiny.folder),
            "--out",
            str(out),
            "--pace",
            "0.5",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(SRC)},
    )
    frames_csv = out / "frames.csv"
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and proc.poll() is None:  # 60 frames flushed: 4 s in
        if frames_csv.is_file() and len(frames_csv.read_text().splitlines()) > 60:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the replay ended before it could be stopped"
    proc.send_signal(signal.SIGTERM)
    stdout, err = proc.communicate(timeout=60.0)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert "interrupted" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert 60 <= summary["frames"] < int(tiny.info["n_frames"])
    rows = frames_csv.read_text().splitlines()
    assert len(rows) == summary["frames"] + 1  # the header and every frame processed
    alerts = [json.loads(x) for x in (out / "alerts.jsonl").read_text().splitlines()]
    assert len(alerts) == summary["alerts"]
    can = list(read_can_log(out / "alerts.blf", errors="raise"))
    assert can, "no RP_STATUS in the CAN log"
    assert (out / "plots.png").stat().st_size > 0
