"""Simulator cost per pulse with and without each effect, measured in one run.

A thin wrapper: the report is library code, rtsar.app.reports.sim_cost (`--help` for its options).
"""

import sys

from rtsar.app.reports.sim_cost import main

if __name__ == "__main__":
    sys.exit(main())
