"""``python -m afa``: see :mod:`afa.cli`."""

import sys

from afa.cli import main

sys.exit(main(prog="python -m afa"))
