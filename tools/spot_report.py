"""Spotlight, bistatic and projective SAL: the issue-15 figures and docs/pages/figures/spot_*.png.

A thin wrapper: the report is library code, rtsar.app.reports.spot (`--help` for its options).
"""

import sys

from rtsar.app.reports.spot import main

if __name__ == "__main__":
    sys.exit(main())
