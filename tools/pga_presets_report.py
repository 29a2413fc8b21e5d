"""PGA on zhao-insal (antenna, speckle, the Doppler anchor) and psaltis-jpl (points in noise).

A thin wrapper: the report is library code, rtsar.app.reports.pga_presets (`--help`).
"""

import sys

from rtsar.app.reports.pga_presets import main

if __name__ == "__main__":
    sys.exit(main())
