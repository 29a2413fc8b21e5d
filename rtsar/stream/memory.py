"""What a configuration will hold in memory, checked against the machine before allocating.

The estimate counts the large buffers: the pipeline's three bounded queues (raw shots, range
lines, image lines; ``queue_pulses`` pulses each) and the shifting CCD's state (the FFT
correlator's blocks and filter, the partitioned correlator's filter spectra and delay line, the
direct register) and, where the correlator's block may change in a live run
(rtsar.stream.growth), the history of its last lines and the two correlators that may be
built beside the one running, all at the largest block.  It is an upper-side estimate, within
a factor of about two; a configuration that would need more than ``MEMORY_FRACTION`` of the
memory available is refused with both figures, instead of failing later half-way into a run.
"""

from __future__ import annotations

import os

import numpy as np

from ..params import Config
from ..samples import precision_dtype

MEMORY_FRACTION = 0.8
GIB = float(1 << 30)


def available_bytes() -> float | None:
    """Memory available to a new allocation (Linux MemAvailable, else physical memory)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return 1024.0 * float(line.split()[1])
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def estimate_bytes(
    config: Config, queue_pulses: int = 0, aux_channels: int = 0, growing: bool = False
) -> float:
    """Bytes of the large buffers of the engine and, with ``queue_pulses``, of the queues;
    ``growing``: with a block that may change (the line history, the correlators built beside
    the one running; ``config`` then with the largest block, rtsar.stream.growth)."""
    p, s = config.processor, config.waveform.samples_per_shot
    item = np.dtype(precision_dtype(p.precision)).itemsize
    n, bins = p.aperture_pulses, p.range_bins
    m = p.fft_length or 1 << max(0, (2 * n - 1).bit_length())
    taps = max(1, p.range_migration_taps + 2) if p.range_migration_taps else 1
    if p.range_migration_taps and p.range_migration_domain == "walk":
        taps = 1.1  # one correlator on the walk's ring, a few % wider (rtsar.ccd.walk_deskew)
    ccd = {
        "direct": 2 * n * bins,
        "fft": 5 * m * bins,
        "partitioned": 6 * n * bins,
        "nonuniform": 8 * n * bins,  # segments padded to whole partitions, their block buffers
    }
    engine = taps * ccd[p.correlator] * item + 4 * p.micro_batch * max(s, bins) * item
    if growing:  # the history (N lines and up to a block more) and two correlators built
        history = n + (m if p.correlator == "fft" else n)  # beside it (a growth's, a shrink's)
        engine += (history * bins + 2 * taps * ccd[p.correlator]) * item
    queues = queue_pulses * ((1 + aux_channels) * s + 2 * bins) * item
    return float(engine + queues)


def check_memory(
    config: Config, queue_pulses: int = 0, aux_channels: int = 0, growing: bool = False
) -> float:
    """The estimate; ValueError when it exceeds MEMORY_FRACTION of the available memory."""
    need = estimate_bytes(config, queue_pulses, aux_channels, growing)
    have = available_bytes()
    if have is not None and need > MEMORY_FRACTION * have:
        p = config.processor
        raise ValueError(
            f"this configuration needs about {need / GIB:.1f} GiB (N = {p.aperture_pulses}, "
            f"{p.range_bins} range bins, {config.waveform.samples_per_shot} samples per shot, "
            f"{p.correlator} correlator, queues of {queue_pulses} pulses); "
            f"{have / GIB:.1f} GiB are available"
        )
    return need
