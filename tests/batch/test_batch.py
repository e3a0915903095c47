"""``roadpreview batch`` on a 2-worker local Dask cluster: the same alerts as plain
replays, failed drives reported with their messages while the others complete, a second
run that skips every drive, a worker killed mid-batch, and the resume rules."""

from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow.parquet as pq
import pytest

from roadpreview.apps.replay import ReplayInputs, replay
from roadpreview.batch.drive import BatchSettings, run_drive
from roadpreview.batch.engine import Engine, open_engine
from roadpreview.batch.fleet import BatchResult, run_batch
from roadpreview.batch.manifest import DriveSpec, discover, read_manifest
from roadpreview.cli.main import main
from roadpreview.digests import replay_source_digest
from roadpreview.errors import ConfigError
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.sinks.files import alert_record

if TYPE_CHECKING:
    from roadpreview.sim.recording import Recording

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def fleet(
    make_recording: Callable[..., Recording], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    """Four short simulated drives as a folder of recordings (links to the session's)."""
    recs = {
        "a_demo": make_recording("demo", seed=0, duration_s=8.0, width=1280, height=720),
        "b_controlled": make_recording("controlled", seed=0, duration_s=3.0, width=320, height=180),
        "c_demo": make_recording("demo", seed=1, duration_s=4.0, width=320, height=180),
        "d_controlled": make_recording("controlled", seed=1, duration_s=3.0, width=320, height=180),
    }
    folder = tmp_path_factory.mktemp("fleet")
    for name, rec in recs.items():
        (folder / name).symlink_to(rec.folder, target_is_directory=True)
    return folder


@pytest.fixture(scope="module")
def engine() -> Iterator[Engine]:
    with open_engine(workers=2, memory_limit="3GiB") as eng:
        yield eng


def _settings(out: Path, **kw: Any) -> BatchSettings:
    return BatchSettings(out=out, config=PipelineConfig(), package=replay_source_digest(), **kw)


def _plain_rows(folder: Path) -> list[dict[str, Any]]:
    """The alerts of a plain in-process replay, as alerts.jsonl rows."""
    result = replay(ReplayInputs.from_recording(folder), PipelineConfig())
    felt = {c.alert_id: c for c in result.confirmations}
    rows = [alert_record(a, felt.get(a.alert_id)) for a in result.alerts]
    return list(json.loads(json.dumps(rows)))


@pytest.fixture(scope="module")
def first_run(fleet: Path, engine: Engine, tmp_path_factory: pytest.TempPathFactory) -> BatchResult:
    out = tmp_path_factory.mktemp("batch") / "out"
    return run_batch(discover(fleet), _settings(out), engine, progress=False)


def test_a_batch_gives_the_alerts_of_plain_replays(fleet: Path, first_run: BatchResult) -> None:
    assert [o.status for o in first_run.outcomes] == ["done"] * 4
    assert {o.worker for o in first_run.outcomes} != {"local"}  # ran on the workers
    total = 0
    for o in first_run.outcomes:
        expected = _plain_rows(fleet / o.drive)
        assert o.alert_rows == expected, o.drive
        total += len(expected)
    assert total >= 1, "the fleet has no alert: the comparison would prove nothing"
    table = pq.read_table(first_run.out / "alerts.parquet").to_pylist()
    assert [r["drive"] for r in table] == [
        o.drive for o in first_run.outcomes for _ in o.alert_rows
    ]
    drives = pq.read_table(first_run.out / "drives.parquet").to_pylist()
    assert [r["drive"] for r in drives] == [o.drive for o in first_run.outcomes]
    for o in first_run.outcomes:  # each drive's usual outputs in its own sub-folder
        summary = json.loads((first_run.out / o.drive / "summary.json").read_text())
        assert summary["alerts"] == o.alerts == len(o.alert_rows)


def test_a_second_run_skips_every_drive(
    fleet: Path, first_run: BatchResult, engine: Engine
) -> None:
    out = first_run.out
    before = {
        o.drive: (out / o.drive / "summary.json").stat().st_mtime_ns for o in first_run.outcomes
    }
    again = run_batch(discover(fleet), _settings(out), engine, progress=False)
    assert [o.status for o in again.outcomes] == ["skipped"] * 4
    assert [o.alert_rows for o in again.outcomes] == [o.alert_rows for o in first_run.outcomes]
    after = {o.drive: (out / o.drive / "summary.json").stat().st_mtime_ns for o in again.outcomes}
    assert after == before, "a skipped drive's outputs were rewritten"
    assert pq.read_table(out / "alerts.parquet").num_rows == sum(
        o.alerts for o in first_run.outcomes
    )


def test_resume_rules(fleet: Path, first_run: BatchResult, tmp_path: Path) -> None:
    """Touching an input does not re-run a drive; changing one, or the configuration, or
    --force does (run in this process: `run_drive` is the task itself)."""
    src = fleet / "d_controlled"
    copy = tmp_path / "d"
    shutil.copytree(src, copy)
    spec = DriveSpec("d", copy)
    settings = _settings(tmp_path / "out")
    assert run_drive(spec, settings).status == "done"
    os.utime(copy / "can.blf", ns=(time.time_ns(), time.time_ns() + 10**9))  # same content
    assert run_drive(spec, settings).status == "skipped"
    with (copy / "camera.toml").open("a") as fh:  # content changed
        fh.write("# checked again\n")
    assert run_drive(spec, settings).status == "done"
    assert run_drive(spec, settings).status == "skipped"
    cfg = PipelineConfig()
    other = BatchSettings(
        out=settings.out,
        config=cfg.with_overrides(estimator="essential"),
        package=settings.package,
    )
    assert run_drive(spec, other).status == "done"
    forced = _settings(tmp_path / "out", force=True)
    assert run_drive(spec, forced).status == "done"
    (tmp_path / "out" / "d" / "alerts.blf").unlink()  # outputs incomplete: run again
    assert run_drive(spec, settings).status == "done"


def _broken_fleet(fleet: Path, folder: Path) -> Path:
    """One good drive, one whose video is cut short, one whose CAN log is garbage."""
    folder.mkdir()
    (folder / "good").symlink_to(fleet / "b_controlled", target_is_directory=True)
    shutil.copytree(fleet / "d_controlled", folder / "truncated_video", symlinks=False)
    video = folder / "truncated_video" / "video.mp4"
    with video.open("r+b") as fh:
        fh.truncate(video.stat().st_size * 2 // 5)
    shutil.copytree(fleet / "d_controlled", folder / "corrupt_can")
    log = folder / "corrupt_can" / "can.blf"
    log.write_bytes(os.urandom(log.stat().st_size))
    return folder


def test_failed_drives_are_reported_and_the_others_complete(
    fleet: Path, engine: Engine, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The command line, on the running cluster (``--scheduler``)."""
    broken = _broken_fleet(fleet, tmp_path / "broken")
    out = tmp_path / "out"
    on_cluster = ["--scheduler", engine.address, "-q"]
    code = main(["batch", str(broken), "--out", str(out), *on_cluster])
    assert code == 1, "some drives failed: the exit code must say so"
    rows = {r["drive"]: r for r in pq.read_table(out / "drives.parquet").to_pylist()}
    assert rows["good"]["status"] == "done"
    assert rows["truncated_video"]["status"] == "failed"
    assert "video.mp4" in rows["truncated_video"]["message"]
    assert rows["corrupt_can"]["status"] == "failed"
    assert "can.blf" in rows["corrupt_can"]["message"]
    report = (out / "report.md").read_text()
    for drive in ("truncated_video", "corrupt_can"):
        assert rows[drive]["message"] in report
    err = capsys.readouterr().err
    assert "drive truncated_video failed" in err
    assert "drive corrupt_can failed" in err
    # the failed drives are tried again on the next run, the good one is skipped
    assert main(["batch", str(broken), "--out", str(out), *on_cluster]) == 1
    rows = {r["drive"]: r for r in pq.read_table(out / "drives.parquet").to_pylist()}
    assert rows["good"]["status"] == "skipped"
    assert rows["corrupt_can"]["status"] == "failed"


def test_a_killed_worker_is_replaced_and_the_batch_completes(
    fleet: Path, first_run: BatchResult, engine: Engine, tmp_path: Path
) -> None:
    client = engine.client
    killed: list[str] = []

    def kill_a_busy_worker() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            busy = [w for w, keys in client.processing().items() if keys]
            if busy:
                pid = engine.worker_pids()[busy[0]]
                time.sleep(0.5)  # inside the drive's replay
                os.kill(pid, signal.SIGKILL)
                killed.append(busy[0])
                return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_a_busy_worker)
    killer.start()
    specs = [s for s in discover(fleet) if s.drive in ("a_demo", "b_controlled")]
    result = run_batch(specs, _settings(tmp_path / "out"), engine, progress=False)
    killer.join()
    assert killed, "no worker was busy: nothing was killed"
    assert [o.status for o in result.outcomes] == ["done"] * 2
    earlier = {o.drive: o.alert_rows for o in first_run.outcomes}
    assert [o.alert_rows for o in result.outcomes] == [earlier[s.drive] for s in specs]
    assert len(engine.worker_pids()) == 2  # the nanny started a new one


def test_a_manifest_lists_drives_with_overrides(fleet: Path, tmp_path: Path) -> None:
    (tmp_path / "fleet.csv").write_text(
        "drive,input,start_s,end_s,mapping\n"
        f"one,{fleet / 'a_demo'},1.5,6,\n"
        f"two,{fleet / 'b_controlled'},,,roadpreview\n"
    )
    specs = read_manifest(tmp_path / "fleet.csv")
    assert [(s.drive, s.start_s, s.end_s, s.mapping) for s in specs] == [
        ("one", 1.5, 6.0, None),
        ("two", None, None, "roadpreview"),
    ]
    toml = tmp_path / "fleet.toml"
    toml.write_text(
        '[defaults]\nend_s = 2.0\n[[drive]]\ninput = "x.mp4"\ncamera = "cam.toml"\n'
        'can = ["x.blf", "y.asc"]\n'
    )
    (tmp_path / "x.mp4").write_bytes(b"")
    (spec,) = read_manifest(toml)
    assert spec.drive == "x"
    assert spec.end_s == 2.0
    assert spec.can == (tmp_path / "x.blf", tmp_path / "y.asc")
    assert spec.camera == tmp_path / "cam.toml"
    (tmp_path / "bad.csv").write_text("input,speed\nx.mp4,3\n")
    with pytest.raises(ConfigError, match=r"bad.csv: unknown column\(s\) \['speed'\]"):
        read_manifest(tmp_path / "bad.csv")
    (tmp_path / "twice.csv").write_text("drive,input\na,x.mp4\na,x.mp4\n")
    with pytest.raises(ConfigError, match="drive id 'a' twice"):
        read_manifest(tmp_path / "twice.csv")
