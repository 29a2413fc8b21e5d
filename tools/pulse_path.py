"""One pulse's path through the live pipeline's own stages, part by part, against the
granularity's figures (issue 38).

A thin wrapper: the report is library code, rtsar.app.reports.pulse_path (`--help` for its
options).
"""

import sys

from rtsar.app.reports.pulse_path import main

if __name__ == "__main__":
    sys.exit(main())
