"""The ``rtsar`` console script: the command's modules are imported inside :func:`main`, so a
Ctrl-C during that second of imports ends in one line (exit 130), not a traceback."""

from __future__ import annotations

import sys


def main(argv=None) -> int:
    try:
        from .cli import main as cli_main
    except KeyboardInterrupt:
        print("\nrtsar: interrupted", file=sys.stderr)
        return 130
    return cli_main(argv)
