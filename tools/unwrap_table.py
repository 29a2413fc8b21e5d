"""Phase-unwrapping methods compared on the same interferograms: error against truth and time.


A thin wrapper: the report is library code, rtsar.app.reports.unwrap_table
(`--help` for its options).
"""

import sys

from rtsar.app.reports.unwrap_table import main

if __name__ == "__main__":
    sys.exit(main())
