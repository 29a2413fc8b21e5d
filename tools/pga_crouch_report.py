"""PGA at crouch-sal (N = 2048): a retro and points 20 and 26 dB weaker under a piston error.

A thin wrapper: the report is library code, rtsar.app.reports.pga_crouch (`--help`).
"""

import sys

from rtsar.app.reports.pga_crouch import main

if __name__ == "__main__":
    sys.exit(main())
