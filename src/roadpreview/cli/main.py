"""Entry point of the ``roadpreview`` command.

Each sub-command lives in its own module of this package exposing
``add_subparser(subparsers)``; the module sets ``func`` on its parser. Heavy
imports happen inside the command functions, so ``roadpreview --help`` is fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from roadpreview import __version__
from roadpreview.errors import RoadPreviewError

#: command name -> module (in the order ``--help`` lists them)
COMMANDS: dict[str, str] = {
    "demo": "roadpreview.cli.demo",
    "simulate": "roadpreview.cli.simulate",
    "replay": "roadpreview.cli.replay",
    "run": "roadpreview.cli.run",
    "bench": "roadpreview.cli.bench",
    "evaluate": "roadpreview.cli.evaluate",
    "calibrate": "roadpreview.cli.calibrate",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="roadpreview",
        description="Predict road-surface anomalies by tracking the vehicle ahead.",
    )
    parser.add_argument("--version", action="version", version=f"roadpreview {__version__}")
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module_name in COMMANDS.values():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name != module_name:
                raise
            continue
        module.add_subparser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = (logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)]
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except RoadPreviewError as exc:
        print(f"roadpreview {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
