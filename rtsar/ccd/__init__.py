"""The shifting CCD with mask: azimuth compression (Psaltis & Wagner 1981, eq. 5).

``base`` (the Correlator interface, the mask design and the float64 reference), one module per
implementation (``direct``: the numba shift register; ``fft``: overlap-save blocks;
``partitioned``: partitioned overlap-save; ``nonuniform``: non-uniformly partitioned
overlap-save; ``migration``: range-migration taps across range
bins; ``physical``: the paper's intensity-detecting CCD), and here the two factories.
"""

from __future__ import annotations

import numpy as np

from ..lens.plan import next_pow2
from ..params import Config, Processor
from .base import Correlator, aperture_offsets_m, correlate_reference, design_mask
from .fft import FFTCorrelator
from .migration import (
    FFTMigrationCorrelator,
    MigrationCorrelator,
    MigrationMask,
    design_migration_mask,
)

__all__ = [
    "CORRELATORS",
    "Correlator",
    "FFTCorrelator",
    "aperture_offsets_m",
    "correlate_reference",
    "design_mask",
    "first_line_pulses",
    "make_ccd",
    "make_correlator",
    "processor_correlator",
]

CORRELATORS = Processor.CORRELATORS


def make_correlator(
    kind: str,
    mask: np.ndarray | MigrationMask,
    fft_length: int | None = None,
    *,
    partition_lines: int = 16,
    precision: str = "complex64",
    tail_block_lines: int = 128,
) -> Correlator:
    """The correlator named by ``Processor.correlator`` (one of CORRELATORS).

    ``mask`` is a 2-D mask[k, r] (design_mask) or a rtsar.ccd.migration.MigrationMask (from
    design_migration_mask, ``Processor.range_migration_taps`` > 0): then, for "fft", one
    overlap-save correlator that filters each block with every range tap
    (rtsar.ccd.migration.FFTMigrationCorrelator), and for the other kinds one correlator per range
    tap, summed (rtsar.ccd.migration.MigrationCorrelator).
    """
    if kind not in CORRELATORS:
        raise ValueError(f"correlator must be one of {CORRELATORS}, got {kind!r}")
    if isinstance(mask, MigrationMask):
        if kind == "fft":
            return FFTMigrationCorrelator(mask, fft_length, precision)
        taps = [
            make_correlator(
                kind,
                m,
                fft_length,
                partition_lines=partition_lines,
                precision=precision,
                tail_block_lines=tail_block_lines,
            )
            for m in mask.tap_masks()
        ]
        return MigrationCorrelator(mask, taps)
    # The numba correlators are imported when asked for: numba takes ~0.4 s to load, and the
    # FFT correlator (SciPy's FFT) does without it.
    if kind == "direct":
        from .direct import DirectCorrelator

        return DirectCorrelator(mask, precision)
    if kind == "fft":
        return FFTCorrelator(mask, fft_length, precision)
    if kind == "nonuniform":
        from .nonuniform import NonUniformCorrelator

        return NonUniformCorrelator(mask, partition_lines, tail_block_lines, precision)
    from .partitioned import PartitionedCorrelator

    return PartitionedCorrelator(mask, partition_lines, precision)


def make_ccd(config: Config, range_m: np.ndarray, physical=None) -> Correlator:
    """The shifting CCD a configuration asks for: the ideal correlator of
    ``Processor.correlator`` with the per-bin mask (or the range-migration mask when
    ``Processor.range_migration_taps`` > 0), or, with ``physical`` (a
    rtsar.physical.PhysicalSettings), the paper's intensity-detecting CCD."""
    if physical is not None:
        # Imported here: its numba kernels load only when physical mode is asked for.
        from .physical import PhysicalCCD

        return PhysicalCCD(config, range_m, physical)
    p = config.processor
    if p.range_migration_taps and p.range_migration_domain == "doppler":
        from .doppler_migration import DopplerMigrationCorrelator  # numba: when asked for

        return DopplerMigrationCorrelator(
            config, range_m, p.range_migration_taps, p.fft_length, p.precision
        )
    if p.range_migration_taps and p.range_migration_domain == "walk":
        from .walk_deskew import WalkDeskewCorrelator  # numba: when asked for

        return WalkDeskewCorrelator(
            config,
            range_m,
            p.range_migration_taps,
            p.partition_lines,
            p.tail_block_lines,
            p.precision,
        )
    if p.range_migration_taps:
        mask = design_migration_mask(config, range_m)
    else:
        mask = design_mask(config, range_m)
    return processor_correlator(p, mask)


def first_line_pulses(p: Processor) -> int:
    """Pulses in before the first image line leaves the correlator ``p`` asks for: line 0 needs
    the N pulses of its aperture, and lines leave in blocks (fft: M - N + 1 lines, M the FFT
    length; partitioned and nonuniform: partition_lines; direct: one)."""
    n = p.aperture_pulses
    if p.correlator == "fft":
        block = (p.fft_length or next_pow2(2 * n)) - n + 1
    elif p.correlator in ("partitioned", "nonuniform"):
        block = min(p.partition_lines, n)
    else:
        block = 1
    return -(-n // block) * block


def processor_correlator(p: Processor, mask) -> Correlator:
    """make_correlator with the settings of ``p`` (correlator kind, blocks, precision)."""
    return make_correlator(
        p.correlator,
        mask,
        p.fft_length,
        partition_lines=p.partition_lines,
        precision=p.precision,
        tail_block_lines=p.tail_block_lines,
    )


def __getattr__(name: str):
    """The numba correlators' classes load on first use (``from rtsar.ccd import
    DirectCorrelator`` still works): numba takes ~0.4 s to import."""
    if name == "DirectCorrelator":
        from .direct import DirectCorrelator

        return DirectCorrelator
    if name == "NonUniformCorrelator":
        from .nonuniform import NonUniformCorrelator

        return NonUniformCorrelator
    if name == "PartitionedCorrelator":
        from .partitioned import PartitionedCorrelator

        return PartitionedCorrelator
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
