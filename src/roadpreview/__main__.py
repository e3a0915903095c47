"""``python -m roadpreview``: the command line (`roadpreview.cli.main`)."""

import sys

from roadpreview.cli.main import main

sys.exit(main())
