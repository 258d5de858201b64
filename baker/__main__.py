"""``python -m baker``: the ``baker`` command (``baker.cli.main.entry``)."""

import sys

from baker.cli.main import entry

sys.exit(entry())
