"""Spatial-amplitude-modulation 3D (INO 3D patent) at Zhao's geometry: height error vs eq. 14.

A thin wrapper: the report is library code, rtsar.app.reports.sam3d (`--help` for its options).
"""

import sys

from rtsar.app.reports.sam3d import main

if __name__ == "__main__":
    sys.exit(main())
