"""Child processes that run a module of this rtsar, whatever folder the command started in.

``python -m MODULE`` puts the current folder first on the import path, so a child started from
a clone of the repository imported the clone's ``rtsar/``, not the installed one its parent
runs: README's first command, run from the clone, had ``rtsar prepare``'s groups compile the
clone's kernels into the clone's folders, then found none in the installed package's cache
(exit status 1), and a live run's warming process did the same.  ``module_argv`` starts the
module with the folder that holds this package first on the path instead (as ``-m`` would
from there), the current folder left as it is for the paths the child is given.
"""

from __future__ import annotations

import sys
from pathlib import Path

PACKAGE_PARENT = str(Path(__file__).resolve().parents[1])  # the folder holding rtsar/

_BOOT = (
    "import os, runpy, sys\n"
    "here = ('', '.', os.getcwd())\n"
    "sys.path[:] = [sys.argv[1]] + [p for p in sys.path if p not in here]\n"
    "module = sys.argv[2]\n"
    "del sys.argv[1:3]\n"
    "runpy.run_module(module, run_name='__main__', alter_sys=True)\n"
)


def module_argv(module: str, *args: str) -> list[str]:
    """The command line that runs ``module`` of this rtsar as ``python -m`` would (its
    ``__main__`` block, ``sys.argv[1:]`` = ``args``) in a new interpreter."""
    return [sys.executable, "-c", _BOOT, PACKAGE_PARENT, module, *args]
