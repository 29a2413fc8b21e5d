"""The streaming engine: AO lens (range) then shifting CCD (azimuth), micro-batch by micro-batch.

Shots go in as they arrive; finished image lines come out as soon as the CCD completes them.
The same object serves live streams and recordings (``rtsar process`` runs a recording through it
as fast as possible), so batch results are streaming results.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from .ccd import design_mask, make_correlator
from .lens_plan import LensPlan, NumpyLens, make_plan
from .migration import design_migration_mask
from .params import Config

LENS_BACKENDS = ("opencl", "numpy")


def make_lens(
    plan: LensPlan,
    backend: str = "opencl",
    device: str | None = None,
    precision: str = "complex64",
):
    """The AO lens on OpenCL (default) or NumPy's FFT, in ``precision`` (Processor.precision)."""
    if backend == "opencl":
        from .lens import AOLens  # imported here: pyopencl is only needed for this backend

        return AOLens(plan, device=device, precision=precision)
    if backend == "numpy":
        return NumpyLens(plan, precision=precision)
    raise ValueError(f"lens backend must be one of {LENS_BACKENDS}, got {backend!r}")


@dataclass
class Lines:
    """Finished image lines and where they sit: image[line, range_bin]."""

    first_line: int  # index of lines[0] in the image (0 = first full aperture)
    lines: np.ndarray  # complex64[count, range_bins] (complex128 with that precision)


class StreamProcessor:
    """Range compression + azimuth correlation of a shot stream, with fixed memory.

    ``Processor.precision`` sets the sample type of lens and correlator (complex128 shots are
    processed in double end to end); ``Processor.range_migration_taps`` > 0 builds the
    range-migration correlator of rtsar.migration.

    ``corrections`` (an rtsar.corrections.CorrectionChain) runs its raw stages on the shots and
    its line stages between lens and CCD; ``physical`` (rtsar.physical.PhysicalSettings) puts the
    AO cell before the lens and the physical CCD in place of the ideal correlator.
    """

    def __init__(
        self,
        config: Config,
        lens_backend: str = "opencl",
        device: str | None = None,
        start_along_track_m: float = 0.0,
        corrections=None,
        physical=None,
    ):
        self.config = config
        self.plan = make_plan(config)
        p = config.processor
        self.lens = make_lens(self.plan, lens_backend, device, p.precision)
        if p.range_migration_taps:
            self.mask = design_migration_mask(config, self.plan.range_m)
        else:
            self.mask = design_mask(config, self.plan.range_m)
        self.corrections = corrections
        self.ao_cell = None
        if physical is not None:
            from .physical import AOCell, PhysicalCCD  # numba kernels: only when asked for

            self.ao_cell = AOCell(config, physical)
            self.correlator = PhysicalCCD(config, self.plan.range_m, physical)
        else:
            self.correlator = make_correlator(
                p.correlator,
                self.mask,
                p.fft_length,
                partition_lines=p.partition_lines,
                precision=p.precision,
            )
        self.start_along_track_m = float(start_along_track_m)
        self.lines_out = 0
        self.pulses_in = 0
        self.nonfinite_pulses = 0  # pulses holding NaN/Inf, zeroed so azimuth timing holds

    @property
    def range_m(self) -> np.ndarray:
        return self.plan.range_m

    def azimuth_m(self, first_line: int, count: int) -> np.ndarray:
        """Along-track position of image lines: the centre of each line's aperture."""
        n = self.config.processor.aperture_pulses
        step = self.config.geometry.along_track_step_m
        j = first_line + np.arange(count)
        return self.start_along_track_m + (j + 0.5 * (n - 1)) * step

    def _emit(self, lines: np.ndarray) -> Lines:
        out = Lines(self.lines_out, lines)
        self.lines_out += len(lines)
        return out

    def compress(self, shots: np.ndarray) -> np.ndarray:
        """The AO lens (after the AO cell's limits in physical mode): shots → range lines."""
        if self.ao_cell is not None:
            shots = self.ao_cell.apply(shots)
        return self.lens.compress(shots)

    def push(self, shots: np.ndarray, aux: dict | None = None) -> Lines:
        """Process a micro-batch of shots [pulse, sample]; return the lines it completed.

        A pulse holding NaN or Inf is replaced by zeros (the azimuth timing is kept) and counted
        in ``nonfinite_pulses``; it never reaches the image.  ``aux``: the auxiliary channels of
        the same shots, for the corrections that use them.
        """
        shots = np.asarray(shots)
        if shots.ndim == 2 and shots.size:
            bad = ~np.isfinite(shots).all(axis=1)
            if bad.any():
                shots = shots.copy()
                shots[bad] = 0
                self.nonfinite_pulses += int(bad.sum())
        self.pulses_in += len(shots)
        aux = aux or {}
        if self.corrections:
            shots = self.corrections.raw(shots, aux)
        compressed = self.compress(shots)
        if self.corrections:
            compressed = self.corrections.lines(compressed, aux)
        return self._emit(self.correlator.push(compressed))

    def flush(self) -> Lines:
        """At the end of a stream: emit the lines still held by the corrections and the CCD."""
        parts = []
        if self.corrections and self.corrections.line_stages:
            held = self.corrections.flush(self.plan.bin_count)
            if len(held):
                parts.append(self.correlator.push(held))
        parts.append(self.correlator.flush())
        return self._emit(np.concatenate(parts) if len(parts) > 1 else parts[0])


def focus_batches(
    config: Config,
    batches: Iterable,
    lens_backend: str = "opencl",
    start_along_track_m: float = 0.0,
    corrections=None,
    physical=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run micro-batches of shots through the engine, flush → (image, azimuth_m, range_m).

    A batch is a shots array, or a (shots, aux) pair when corrections need auxiliary channels.
    """
    eng = StreamProcessor(
        config,
        lens_backend,
        start_along_track_m=start_along_track_m,
        corrections=corrections,
        physical=physical,
    )
    parts = [
        eng.push(*batch).lines if isinstance(batch, tuple) else eng.push(batch).lines
        for batch in batches
    ]
    parts.append(eng.flush().lines)
    image = np.concatenate(parts)
    return image, eng.azimuth_m(0, len(image)), eng.range_m


def process_block(
    config: Config,
    shots: np.ndarray,
    lens_backend: str = "opencl",
    start_along_track_m: float = 0.0,
    aux: dict | None = None,
    corrections=None,
    physical=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Convenience: run a whole array of shots through the engine → (image, azimuth_m, range_m)."""
    b = config.processor.micro_batch
    aux = aux or {}
    batches = (
        (shots[i : i + b], {k: v[i : i + b] for k, v in aux.items()})
        for i in range(0, len(shots), b)
    )
    return focus_batches(config, batches, lens_backend, start_along_track_m, corrections, physical)
