"""Point-target acceptance table for every preset: measured vs theory (Markdown).

A thin wrapper: the report is library code, rtsar.app.reports.focus (`--help` for its options).
"""

import sys

from rtsar.app.reports.focus import main

if __name__ == "__main__":
    sys.exit(main())
