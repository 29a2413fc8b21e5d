"""Agreement of the fast stages with their float64 NumPy references, per preset (relative rms).

A thin wrapper: the report is library code, rtsar.app.reports.agreement (`--help` for its options).
"""

import sys

from rtsar.app.reports.agreement import main

if __name__ == "__main__":
    sys.exit(main())
