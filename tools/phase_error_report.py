"""Platform phase errors and their corrections: the figures of the closing note (Markdown).


A thin wrapper: the report is library code, rtsar.app.reports.phase_error
(`--help` for its options).
"""

import sys

from rtsar.app.reports.phase_error import main

if __name__ == "__main__":
    sys.exit(main())
