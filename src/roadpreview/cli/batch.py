"""``roadpreview batch``: replay a folder (or a manifest) of drives on Dask, one sub-folder
of outputs per drive, and the fleet's tables and report (``docs/batch.md``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from roadpreview.cli._pipeline_args import add_pipeline_arguments, pipeline_config

OUTPUTS = (
    "<drive>/ (replay's outputs, replay.log, batch.json), alerts.parquet, alerts.csv,"
    " drives.parquet, drives.csv, report.md, report.png, fleet.json"
)


def add_subparser(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "batch",
        help="replay many drives (a folder or a manifest) on a Dask cluster, local or remote",
        description=(
            "Replay every drive of INPUT through the pipeline, one Dask task per drive, and "
            "write the fleet's alert table, per-drive table and report.\n\n"
            "INPUT is a folder (each recording folder, ROS bag, or video with its companions "
            "<stem>.blf/.asc/..., <stem>.imu.csv, <stem>.frames.csv is a drive) or a manifest "
            "(.csv with a header, or .toml with [defaults] and [[drive]] tables; keys: input, "
            "drive, camera, can, imu_csv, frames_csv, video_start_s, can_offset_s, "
            "imu_offset_s, image_topic, imu_topic, speed_topic, start_s, end_s, config, dbc, "
            "mapping). See docs/batch.md.\n\n"
            f"Outputs in --out: {OUTPUTS}. A second run skips every drive whose outputs are "
            "complete and whose inputs, configuration and package code are unchanged.\n\n"
            "A drive that fails (unreadable video, a CAN log that gives nothing, ...) is "
            "reported in the tables and the report with its error; the others go on, and the "
            "exit code is 1."
        ),
    )
    p.add_argument("input", type=Path, help="a folder of drives, or a manifest (.csv/.toml)")
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="output folder; a folder an earlier batch wrote is resumed",
    )
    p.add_argument(
        "--camera",
        type=Path,
        help="camera calibration (TOML) of the videos and bags that have none of their own",
    )
    add_pipeline_arguments(p)
    p.add_argument(
        "--truth",
        action="store_true",
        help="simulator recordings: match the alerts to the true events; the report pools"
        " the detection and false-alarm figures",
    )
    p.add_argument(
        "--force", action="store_true", help="replay every drive, even those that could be skipped"
    )
    p.add_argument(
        "--allow-missing",
        action="store_true",
        help="a drive with an input that gives nothing (a CAN log without a usable frame, an"
        " IMU CSV without a valid row) counts as done, not failed",
    )
    engine = p.add_argument_group(
        "engine",
        "Default: a local Dask cluster of --workers processes, one thread each. An existing "
        "cluster: --scheduler, or Dask's scheduler-address setting (DASK_SCHEDULER_ADDRESS).",
    )
    engine.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="the Dask scheduler of an existing cluster, e.g. tcp://host:8786",
    )
    engine.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="local worker processes; default: one per core",
    )
    engine.add_argument(
        "--memory-limit",
        default="auto",
        metavar="SIZE",
        help="memory limit of each local worker, e.g. 4GiB ('auto': the machine's memory"
        " shared evenly); a worker past 95 %% is restarted and its drive run again",
    )
    p.set_defaults(func=_run)


def _existing_batch(out: Path) -> bool:
    """``out`` is empty, or holds what a batch writes (fleet.json, or drive folders)."""
    from roadpreview.batch.drive import BATCH_JSON
    from roadpreview.batch.fleet import FLEET_JSON

    if not out.exists():
        return True
    entries = list(out.iterdir())
    return (
        not entries
        or (out / FLEET_JSON).is_file()
        or any((e / BATCH_JSON).is_file() for e in entries if e.is_dir())
    )


def _run(args: argparse.Namespace) -> int:
    from roadpreview.batch.drive import BatchSettings
    from roadpreview.batch.engine import open_engine
    from roadpreview.batch.fleet import run_batch
    from roadpreview.batch.manifest import load_drives
    from roadpreview.digests import replay_source_digest
    from roadpreview.errors import ConfigError

    out: Path = args.out
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: is a file, not a folder")
    if not _existing_batch(out):
        raise ConfigError(
            f"--out {out}: holds files that no batch wrote; choose an empty folder or an"
            " earlier batch's"
        )
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers {args.workers}: need at least 1")
    specs = load_drives(args.input, camera=args.camera)
    settings = BatchSettings(
        out=out,
        config=pipeline_config(args),
        package=replay_source_digest(),
        force=args.force,
        truth=args.truth,
        allow_missing=args.allow_missing,
    )
    quiet = getattr(args, "verbosity", 0) < 0
    with open_engine(args.scheduler, workers=args.workers, memory_limit=args.memory_limit) as eng:
        print(f"{len(specs)} drive(s) on the {eng.describe()}", flush=True)
        result = run_batch(specs, settings, eng, progress=not quiet)
    print(
        f"{len(result.done)} replayed, {len(result.skipped)} skipped (unchanged),"
        f" {len(result.failed)} failed, in {result.seconds:.1f} s"
    )
    for o in result.failed:
        print(f"roadpreview batch: drive {o.drive} failed: {o.message}", file=sys.stderr)
    print(f"outputs in {out}: {OUTPUTS}")
    return 1 if result.failed else 0
