"""``python -m taskflight``: the ``taskflight`` command (for a checkout without the console script)."""

from taskflight.cli import main

raise SystemExit(main())
