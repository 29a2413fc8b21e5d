"""``python -m rtsar.scene.warm SCENE.toml``: compile the simulator's kernels for that scene
into numba's cache, in a process of its own (rtsar.sources.sim.SimSource ``warm_from``).

The first live run of an installation compiled the simulator's kernels (1.8 s here) and then
the correlator's (2.1 s for the partitioned one), one after the other in one interpreter; in
this process the first happens on the other core while the live command compiles the second.
"""

from __future__ import annotations

import sys

from . import Simulator, load_scene


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        sys.stderr.write("usage: python -m rtsar.scene.warm SCENE.toml\n")
        return 2
    Simulator(load_scene(argv[0])).prepare()
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
