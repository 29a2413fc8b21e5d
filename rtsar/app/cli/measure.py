"""Measuring commands: ``devices``, ``bench``, ``tradeoff``, ``table1`` (each declares its own
options)."""

from __future__ import annotations

from .. import bench, devices, table1, tradeoff


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "devices",
        help="every OpenCL device: does it build the lens, is it right, how fast; the default",
        description="Lists every OpenCL device the loader sees (pyopencl's PoCL, the system's "
        "drivers, drivers installed with pip such as Intel's CPU runtime, GPUs).  Each is "
        "probed in a process of its own: the lens kernel of --preset built, 8 pulses compared "
        "with the float64 reference, pulses/s timed at each batch size; the NumPy lens of the "
        "same plan beside them.  Says which device runs the lens by default (the fastest that "
        "builds, on psaltis-max at batch 64) and why a device is refused.  About 1-2 s a "
        "device.  Exit status 1 where no device can run the lens.",
    )
    devices.add_arguments(s)
    s.set_defaults(func=devices.run)

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
