"""``rtsar prepare``: its command line (the work: rtsar.app.prepare, which loads every kernel
module, so no other command imports it)."""

from __future__ import annotations

from .. import prepare


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "prepare",
        description="Run once after installing (README's first command does): compiles "
        "rtsar's numba kernels into numba's on-disk cache (every correlator, the physical "
        "CCD, the simulator, the resampler; complex64, the presets' precision), each group "
        "in a process of its own, then surveys the OpenCL devices alone (as `rtsar devices` "
        "does at batch 64), kept for later runs.  Without it, the first run of each command "
        "compiles what it uses (16-23 s for the nonuniform correlator on a 2-core machine) "
        "and a machine's first live run probes the devices (about 5 s).  Tens of seconds the "
        "first time, a few after.  Run it as the user, and in the environment, that runs "
        "rtsar: numba keeps its cache beside the modules only where that user can write.  "
        "Exit status 1 if a group failed to compile or a kernel is not in the cache after.",
    )
    prepare.add_arguments(s)
    s.set_defaults(func=prepare.run)
