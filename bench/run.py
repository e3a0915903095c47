"""Run one benchmark (or ``all``) and print its table: ``python bench/run.py pitch``."""

from __future__ import annotations

import sys

from roadpreview.cli.main import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
