"""The output folder of a command (``--out``, ``--force``): never a file, never silently
mixed with what an earlier run left there.

An ``--out`` that is a file is an error; a folder that holds anything is refused unless
``--force``, which then deletes the command's own output files found there (the names
it writes, nothing else) and leaves every other file alone, saying so.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable, Collection
from pathlib import Path

from roadpreview.errors import ConfigError

log = logging.getLogger(__name__)


def add_output_arguments(p: argparse.ArgumentParser, *, what: str) -> None:
    """``--out`` (required) and ``--force``; ``what``: the files the command writes."""
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help=f"output folder ({what}); created if missing, refused if not empty",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="write into a non-empty --out: this command's own files found there are"
        " replaced, other files are left as they are",
    )


def prepare_output_folder(
    out: Path,
    *,
    force: bool,
    ours: Collection[str] | None = None,
    say: Callable[[str], object] | None = log.warning,
) -> list[str]:
    """Check (module docstring) and create ``out``; returns the names of the stale files
    of ours that ``force`` deleted. ``ours``: the file names the command writes (None:
    it overwrites them itself, nothing is deleted). ``say``: tells what ``force`` did."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: is a file, not a folder")
    if out.is_dir():
        entries = sorted(p.name for p in out.iterdir())
        if entries and not force:
            shown = ", ".join(entries[:5]) + (", ..." if len(entries) > 5 else "")
            raise ConfigError(
                f"--out {out}: folder not empty ({len(entries)} entries: {shown}); "
                "choose another folder or add --force"
            )
        removed = []
        for name in entries:
            path = out / name
            if ours is not None and name in ours and path.is_file():
                path.unlink()
                removed.append(name)
        others = [n for n in entries if n not in removed]
        if say is not None and removed:
            say(f"--force: deleted the earlier outputs in {out}: {', '.join(removed)}")
        if say is not None and others:
            say(f"--force: {len(others)} other entries in {out} left as they are")
        return removed
    out.mkdir(parents=True)
    return []
