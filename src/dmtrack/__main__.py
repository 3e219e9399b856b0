"""``python -m dmtrack`` = the ``dmtrack`` command (e.g. where the console script is not on PATH)."""

import sys

from dmtrack.cli import main

sys.exit(main())
