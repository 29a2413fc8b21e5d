"""The ``rtsar`` console script: the command's modules are imported inside :func:`main`, so a
Ctrl-C during that second of imports ends in one line (exit 130), not a traceback (the
command's own module too, imported while its parser is built)."""

from __future__ import annotations

import sys


def main(argv=None) -> int:
    try:
        from .cli import main as cli_main

        return cli_main(argv)
    except KeyboardInterrupt:  # before the command ran (it says its own otherwise)
        print("\nrtsar: interrupted", file=sys.stderr)
        return 130
