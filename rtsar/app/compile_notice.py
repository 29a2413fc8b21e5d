"""A line when numba compiles one of rtsar's kernels, so the pause is not taken for a hang.

numba compiles a kernel the first time an installation runs it (``cache=True``: later runs
load it in a fraction of a second).  A correlator's first run can take 10-20 s on a busy
2-core machine, during which a live command said nothing after "measuring the work …".
numba announces each real compilation (not a load from its cache) as a "numba:compile"
event; while ``compile_notice`` is active, the first one of each rtsar module is told.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager


@contextmanager
def compile_notice(say):
    """Within the block, ``say(line)`` once per rtsar module whose kernels numba compiles."""
    try:
        from numba.core import event
    except ImportError:  # no numba: nothing is compiled
        yield
        return
    told: set[str] = set()
    lock = threading.Lock()

    class Notice(event.Listener):
        def on_start(self, ev) -> None:
            func = getattr(ev.data.get("dispatcher"), "py_func", None)
            module = getattr(func, "__module__", None) or ""
            if not module.startswith("rtsar."):
                return
            with lock:
                if module in told:
                    return
                told.add(module)
            say(
                f"numba is compiling {module}'s kernels: the first run of this installation "
                "(seconds, tens of them on a busy machine; cached for later runs) …"
            )

        def on_end(self, ev) -> None:
            pass

    with event.install_listener("numba:compile", Notice()):
        yield
