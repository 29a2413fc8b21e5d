"""``python -m rtsar``: the ``rtsar`` command."""

import sys

from .app.cli import main

sys.exit(main())
