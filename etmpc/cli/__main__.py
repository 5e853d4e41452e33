"""``python -m etmpc.cli``: the ``etmpc`` command."""

import sys

from etmpc.cli import main

sys.exit(main())
