"""Entry point of the ``roadpreview`` command (also ``python -m roadpreview``).

Each sub-command lives in its own module of this package exposing
``add_subparser(subparsers)``; the module sets ``func`` on its parser. Heavy
imports happen inside the command functions, so ``roadpreview --help`` is fast.

Conventions every sub-command gets from here, without its module doing anything:
``-v``/``-q`` before or after the command name, ``--help`` listing each option's
default and the exit codes, and errors as one line ``roadpreview CMD: error: ...``
(a `RoadPreviewError` or a file-system error: exit 1; a usage error: exit 2; SIGINT or
SIGTERM: 130, see `EXIT_CODES`).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence
from typing import Any

from roadpreview import __version__
from roadpreview.errors import RoadPreviewError

#: command name -> module (in the order ``--help`` lists them)
COMMANDS: dict[str, str] = {
    "demo": "roadpreview.cli.demo",
    "simulate": "roadpreview.cli.simulate",
    "replay": "roadpreview.cli.replay",
    "batch": "roadpreview.cli.batch",
    "run": "roadpreview.cli.run",
    "bench": "roadpreview.cli.bench",
    "evaluate": "roadpreview.cli.evaluate",
    "calibrate": "roadpreview.cli.calibrate",
}

#: the exit codes, as ``--help`` shows them
EXIT_CODES = """exit codes:
  0    done
  1    error: bad input, configuration or file system (one line on stderr)
  2    usage error (unknown option, missing argument)
  130  interrupted by SIGINT (Ctrl-C) or SIGTERM: the outputs hold what was processed"""

#: the logger of progress lines when stderr is not a terminal (shown unless -q)
PROGRESS_LOGGER = "roadpreview.progress"


class HelpFormatter(argparse.HelpFormatter):
    """Descriptions wrapped paragraph by paragraph (a paragraph whose lines are indented,
    like the exit codes, is kept as written), and ``(default: X)`` after every option that
    has a default worth showing (not None, not a flag's False, not an empty list)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = []
        for para in text.split("\n\n"):
            lines = para.splitlines()
            if len(lines) > 1 and all(ln.startswith(" ") for ln in lines[1:]):
                paragraphs.append("\n".join(indent + ln for ln in lines))
            else:
                paragraphs.append(super()._fill_text(para, width, indent))
        return "\n\n".join(paragraphs)

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if (
            "%(default)" in text
            or not action.option_strings
            or isinstance(action, argparse._CountAction)
            or default is None
            or default is False
            or default is argparse.SUPPRESS
            or default == []
        ):
            return text
        return f"{text} (default: %(default)s)"


def _add_verbosity(p: argparse.ArgumentParser, *, command: bool) -> None:
    """``-v``/``-q``. Before the command they count into ``verbose``/``quiet``; after it into
    ``verbose_cmd``/``quiet_cmd`` (left unset when not given), summed in `main`: a
    sub-parser's defaults would otherwise overwrite what was given before the command."""
    suffix = "_cmd" if command else ""
    default: Any = argparse.SUPPRESS if command else 0
    p.add_argument(
        "-v",
        "--verbose",
        action="count",
        dest="verbose" + suffix,
        default=default,
        help="more log output: -v info, -vv debug (before or after the command)",
    )
    p.add_argument(
        "-q",
        "--quiet",
        action="count",
        dest="quiet" + suffix,
        default=default,
        help="errors only: no progress, no warnings (before or after the command)",
    )


class CommandParser(argparse.ArgumentParser):
    """The parser of every sub-command: the shared help format, the exit codes in the
    epilog and ``-v``/``-q``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        epilog = kwargs.get("epilog")
        kwargs["epilog"] = f"{epilog}\n\n{EXIT_CODES}" if epilog else EXIT_CODES
        super().__init__(*args, **kwargs)
        _add_verbosity(self, command=True)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="roadpreview",
        description="Predict road-surface anomalies by tracking the vehicle ahead.",
        formatter_class=HelpFormatter,
        epilog=f"'roadpreview COMMAND --help' describes a command.\n\n{EXIT_CODES}",
    )
    parser.add_argument("--version", action="version", version=f"roadpreview {__version__}")
    _add_verbosity(parser, command=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=CommandParser)
    for module_name in COMMANDS.values():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name != module_name:
                raise
            continue
        module.add_subparser(sub)
    return parser


def verbosity(args: argparse.Namespace) -> int:
    """-1 with ``-q``, else the number of ``-v`` (before and after the command)."""
    if getattr(args, "quiet", 0) or getattr(args, "quiet_cmd", 0):
        return -1
    return int(getattr(args, "verbose", 0)) + int(getattr(args, "verbose_cmd", 0))


def setup_logging(level: int) -> None:
    """Log format and level for ``verbosity`` ``level``; progress lines stay on unless -q."""
    root = {-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO}.get(level, logging.DEBUG)
    logging.basicConfig(format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logging.getLogger().setLevel(root)
    progress = logging.getLogger(PROGRESS_LOGGER)
    progress.setLevel(logging.ERROR if level < 0 else min(root, logging.INFO))


def describe_os_error(exc: OSError) -> str:
    """``exc`` as one line: what failed and on which path."""
    what = exc.strerror or str(exc)
    paths = [str(p) for p in (exc.filename, exc.filename2) if p is not None]
    return f"{' -> '.join(paths)}: {what}" if paths else what


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    args.verbosity = verbosity(args)
    setup_logging(args.verbosity)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except RoadPreviewError as exc:
        print(f"roadpreview {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a missing folder, a full disk, no permission: not a traceback
        print(f"roadpreview {args.command}: error: {describe_os_error(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"roadpreview {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
