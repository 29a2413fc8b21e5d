"""What swath processes cost, and where they would pay: a model from measured per-pulse costs.

A thin wrapper: the report is library code, rtsar.app.reports.swath_model (`--help` for its
options).
"""

import sys

from rtsar.app.reports.swath_model import main

if __name__ == "__main__":
    sys.exit(main())
