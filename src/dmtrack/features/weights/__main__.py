"""``python -m dmtrack.features.weights``: see :mod:`dmtrack.features.weights.cli`."""

from dmtrack.features.weights.cli import main

raise SystemExit(main())
