"""InSAL at Zhao's geometry: ridge and drawing pin height maps, unwrappers, stream continuity.

A thin wrapper: the report is library code, rtsar.app.reports.insal (`--help` for its options).
"""

import sys

from rtsar.app.reports.insal import main

if __name__ == "__main__":
    sys.exit(main())
