"""A lens call's time alone and beside a busy core: what a live run's other threads cost the
AO lens (issue 38).

A thin wrapper: the report is library code, rtsar.app.reports.lens_load (`--help` for its
options).
"""

import sys

from rtsar.app.reports.lens_load import main

if __name__ == "__main__":
    sys.exit(main())
