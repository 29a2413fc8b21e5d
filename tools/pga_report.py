"""Phase gradient autofocus on speckle scenes with bright points: the issue-5 figures (Markdown).

A thin wrapper: the report is library code, rtsar.app.reports.pga (`--help` for its options).
"""

import sys

from rtsar.app.reports.pga import main

if __name__ == "__main__":
    sys.exit(main())
