"""``python -m rtsar``: the ``rtsar`` command."""

import sys

from .app.entry import main

sys.exit(main())
