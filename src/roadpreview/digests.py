"""Digests that key caches and skip decisions: of a JSON-able value, and of the package's
own source code (so that a change to the code re-runs what it produces).

Used by the evaluation's trace cache (`roadpreview.eval.runner`) and by the batch's
resume check (`roadpreview.batch.drive`)."""

from __future__ import annotations

import hashlib
import json
from functools import cache
from pathlib import Path
from typing import Any

from roadpreview import __version__

_PACKAGE = Path(__file__).resolve().parent

#: sub-packages whose source does not change what a replay or a trace holds (the
#: evaluation, the command line, the benchmarks, the simulator, the batch around it)
NOT_REPLAY = ("eval", "cli", "bench", "sim", "batch")


def digest(obj: Any) -> str:
    """16 hex digits of the SHA-256 of ``obj`` as canonical JSON."""
    text = json.dumps(obj, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@cache
def source_digest(parts: tuple[str, ...], exclude: tuple[str, ...] = ()) -> str:
    """Digest of the package's source files under ``parts`` (``("",)``: all), minus
    ``exclude`` (top-level names or paths relative to the package); data files (DBC,
    mappings) included."""
    h = hashlib.sha256(__version__.encode())
    for part in parts:
        root = _PACKAGE / part
        for path in [root] if root.is_file() else sorted(root.rglob("*")):
            rel = path.relative_to(_PACKAGE)
            if not path.is_file() or path.suffix not in (".py", ".dbc", ".toml"):
                continue
            if rel.parts and (rel.parts[0] in exclude or rel.as_posix() in exclude):
                continue
            h.update(str(rel).encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def replay_source_digest() -> str:
    """What a replay's outputs depend on besides its inputs and configuration: the source
    of everything but `NOT_REPLAY` (the pipeline, the sources, the sinks, the apps)."""
    return source_digest(("",), NOT_REPLAY)


__all__ = ["NOT_REPLAY", "digest", "replay_source_digest", "source_digest"]
