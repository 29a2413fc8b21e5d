"""Every OpenCL device that builds the lens, side by side: the lens alone and the live pipeline.

A thin wrapper: the report is library code, rtsar.app.reports.devices (`--help` for its options).
"""

import sys

from rtsar.app.reports.devices import main

if __name__ == "__main__":
    sys.exit(main())
