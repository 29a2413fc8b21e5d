"""Measuring commands: ``bench``, ``tradeoff``, ``table1`` (each declares its own options)."""

from __future__ import annotations

from .. import bench, table1, tradeoff


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "bench",
        help="throughput of the lens and correlators, and the live pipeline, in one run",
        description="Not a test: measures pulses/s of the AO lens (OpenCL vs the same plan on "
        "NumPy's and SciPy's FFT, and one bare FFT of the batch) and of the correlators, and "
        "the live pipeline end to end (real-time factor, drops, latency; threads and two "
        "swath processes), in one run, as ratios.  About 5 minutes on 2 cores (--preset P: "
        "about half).",
    )
    bench.add_arguments(s)
    s.set_defaults(func=bench.run_bench)

    s = sub.add_parser(
        "tradeoff",
        help="what accuracy costs in time: every processor knob, quality against cost",
        description="Varies each processor knob alone from the preset's defaults (precision, "
        "correlator mode and block, micro-batch, aperture, windows, lens, mask per range bin, "
        "range migration, physical CCD) and each correction on scenes whose targets stress it; "
        "measures image error against a float64 reference, IRW/PSLR/ISLR/position of point "
        "targets, pulses/s and the line latency at the PRF, in one run.  Writes JSON, Markdown "
        "and a Pareto plot (PNG).  Not a test: about 4 minutes on 2 cores (--quick: about a "
        "minute).",
    )
    tradeoff.add_arguments(s)
    s.set_defaults(func=tradeoff.run)

    s = sub.add_parser(
        "table1",
        help="Psaltis & Wagner's Table 1 regenerated from the physical-mode emulation",
        description="Builds Table 1 of Psaltis & Wagner (1981) from the physical CCD/AO-cell "
        "emulation: range resolution and cells (halved with the carrier in range), azimuth "
        "resolution L/N (N halved with the carrier in azimuth), and the dynamic range measured "
        "on emulated images (largest undistorted point target / noise floor of an empty scene), "
        "beside the paper's values.  About 20–35 s on 2 cores.",
    )
    table1.add_arguments(s)
    s.set_defaults(func=table1.run)
