"""Chirp defects and their corrections: the figures issue 5 asks for, as a Markdown table.

A thin wrapper: the report is library code, rtsar.app.reports.chirp (`--help` for its options).
"""

import sys

from rtsar.app.reports.chirp import main

if __name__ == "__main__":
    sys.exit(main())
