"""The streaming engine: AO lens (range) then shifting CCD (azimuth), micro-batch by micro-batch.

Shots go in as they arrive; finished image lines come out as soon as the CCD completes them.
The same object serves live streams and recordings (``rtsar process`` runs a recording through it
as fast as possible), so batch results are streaming results.  Its two halves are separate
methods so that the threaded pipeline (rtsar.stream.pipeline) can run them in two threads:

* :meth:`StreamProcessor.range_stage`: the raw corrections (they see the auxiliary channels),
  the AO cell's limits in physical mode, the AO lens, and the line corrections (which may hold
  pulses back: PGA holds a block);
* :meth:`StreamProcessor.azimuth_stage`: the shifting CCD (Psaltis & Wagner 1981, eq. 5).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..ccd import make_ccd
from ..ccd.base import line_azimuth_m
from ..lens import make_lens, make_plan
from ..lens.numpy_lens import NumpyLens
from ..lens.small_calls import SmallCallsOnCPU
from ..params import Config
from ..physical.aocell import AOCell
from ..samples import zero_nonfinite_rows
from .memory import check_memory
from .settings import PipelineSettings


@dataclass
class Lines:
    """Finished image lines and where they sit: image[line, range_bin]."""

    first_line: int  # index of lines[0] in the image (0 = first full aperture)
    lines: np.ndarray  # complex64[count, range_bins] (complex128 with that precision)


class StreamProcessor:
    """Range compression + azimuth correlation of a shot stream, with fixed memory.

    ``Processor.precision`` sets the sample type of lens and correlator (complex128 shots are
    processed in double end to end); ``Processor.range_migration_taps`` > 0 builds the
    range-migration correlator of rtsar.ccd.migration.

    ``corrections`` (an rtsar.focus.chain.CorrectionChain) runs its raw stages on the shots and
    its line stages between lens and CCD; ``physical`` (rtsar.physical.PhysicalSettings) puts the
    AO cell before the lens and the physical CCD in place of the ideal correlator.
    ``azimuth`` False builds no correlator (the range half alone: a swath coordinator, whose
    workers correlate).  ``live``: a live run's settings, from its granularity: an OpenCL lens's
    calls of fewer than ``lens_cpu_below`` pulses run on SciPy's FFT (--lens hybrid:
    rtsar.lens.small_calls).
    """

    def __init__(
        self,
        config: Config,
        lens_backend: str = "auto",
        device: str | None = None,
        start_along_track_m: float = 0.0,
        corrections=None,
        physical=None,
        azimuth: bool = True,
        live: PipelineSettings | None = None,
    ):
        self.config = config
        check_memory(config)
        self.plan = make_plan(config)
        p = config.processor  # --lens auto decides by the configured batch: one choice a config
        self.lens = make_lens(self.plan, lens_backend, device, p.precision, p.micro_batch)
        below = live.lens_cpu_below if live is not None else 0
        if below > 1 and self.lens.backend == "opencl":  # a live run's choice
            cpu = NumpyLens(self.plan, "scipy", p.precision)
            self.lens = SmallCallsOnCPU(self.lens, cpu, below)
        self.dtype = self.lens.dtype
        self.corrections = corrections
        self.ao_cell = None
        if physical is not None:
            self.ao_cell = AOCell(config, physical)
        self.correlator = make_ccd(config, self.plan.range_m, physical) if azimuth else None
        self.start_along_track_m = float(start_along_track_m)
        self.lines_out = 0
        self.pulses_in = 0
        self.nonfinite_pulses = 0  # pulses holding NaN/Inf, zeroed so azimuth timing holds

    @property
    def range_m(self) -> np.ndarray:
        return self.plan.range_m

    def azimuth_m(self, first_line: int, count: int) -> np.ndarray:
        """Along-track position of image lines: the centre of each line's aperture."""
        return line_azimuth_m(self.config, self.start_along_track_m, first_line, count)

    # ---- the two halves -----------------------------------------------------------------
    def compress(self, shots: np.ndarray, zero: bool = False) -> np.ndarray:
        """The AO lens (after the AO cell's limits in physical mode): shots → range lines.

        ``zero``: the shots are known to be zeros (ingest's gap fill): zero lines, no launch.
        """
        if zero:
            return np.zeros((len(shots), self.plan.bin_count), self.dtype)
        if self.ao_cell is not None:
            shots = self.ao_cell.apply(shots)
        return self.lens.compress(shots)

    def range_stage(self, shots: np.ndarray, aux: dict, zero: bool = False) -> np.ndarray:
        """Raw corrections → AO lens → line corrections; returns the range lines released.

        A line correction may hold pulses back (PGA holds a block), so fewer lines than shots
        may come out; they come out in pulse order and the rest follow at :meth:`flush_range`.
        """
        chain = self.corrections
        if chain:
            shots = chain.raw(shots, aux)
        lines = self.compress(shots, zero)
        if chain and chain.line_stages:
            lines = chain.lines(lines, aux)
        return lines

    def range_submit(self, shots: np.ndarray, aux: dict, zero: bool = False):
        """:meth:`range_stage` with the AO lens working in the background where it can (an
        OpenCL lens, no correction, no AO cell): returns a callable that gives the lines."""
        plain = not (zero or self.corrections or self.ao_cell is not None)
        if plain and hasattr(self.lens, "submit"):
            return self.lens.submit(shots).wait
        lines = self.range_stage(shots, aux, zero)
        return lambda: lines

    def flush_range(self) -> np.ndarray:
        """At the end of a stream: the range lines the line corrections still hold."""
        if self.corrections and self.corrections.line_stages:
            return self.corrections.flush(self.plan.bin_count)
        return np.zeros((0, self.plan.bin_count), self.dtype)

    def azimuth_stage(self, lines: np.ndarray) -> Lines:
        """The shifting CCD: range lines in, the image lines they completed out."""
        return self._emit(self.correlator.push(lines))

    def flush_azimuth(self) -> Lines:
        """At the end of a stream: the lines the CCD still holds."""
        return self._emit(self.correlator.flush())

    def _emit(self, lines: np.ndarray) -> Lines:
        out = Lines(self.lines_out, lines)
        self.lines_out += len(lines)
        return out

    # ---- both halves, one call ------------------------------------------------------------
    def push(self, shots: np.ndarray, aux: dict | None = None) -> Lines:
        """Process a micro-batch of shots [pulse, sample]; return the lines it completed.

        A pulse holding NaN or Inf is replaced by zeros (the azimuth timing is kept) and counted
        in ``nonfinite_pulses``; it never reaches the image.  ``aux``: the auxiliary channels of
        the same shots, for the corrections that use them.
        """
        shots = np.asarray(shots)
        if shots.ndim == 2 and shots.size:
            shots, bad = zero_nonfinite_rows(shots)
            self.nonfinite_pulses += int(bad.sum())
        self.pulses_in += len(shots)
        return self.azimuth_stage(self.range_stage(shots, aux or {}))

    def flush(self) -> Lines:
        """At the end of a stream: emit the lines still held by the corrections and the CCD."""
        held = self.flush_range()
        parts = [self.correlator.push(held)] if len(held) else []
        parts.append(self.correlator.flush())
        return self._emit(np.concatenate(parts) if len(parts) > 1 else parts[0])


def focus_batches(
    config: Config,
    batches: Iterable,
    lens_backend: str = "auto",
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
    lens_backend: str = "auto",
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


def focus_channels(
    config: Config,
    main: np.ndarray,
    aux: dict,
    names: Iterable[str],
    lens_backend: str = "numpy",
    start_along_track_m: float = 0.0,
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """Focus the main channel and the auxiliary channels ``names``, each with its own engine.

    Returns ([main image, image of each named channel], azimuth_m, range_m), each
    image[azimuth, range] (e.g. S0, S1, S2 of the spatial-amplitude-modulation 3D method).
    """
    names = list(names)
    missing = [c for c in names if c not in aux]
    if missing:
        raise ValueError(f"auxiliary channels {missing} missing (have {sorted(aux) or 'none'})")
    images = []
    for shots in (main, *(aux[c] for c in names)):
        image, azimuth_m, range_m = process_block(config, shots, lens_backend, start_along_track_m)
        images.append(image)
    return images, azimuth_m, range_m


def brightest_point(
    config: Config, batches, start_along_track_m: float = 0.0, lens_backend: str = "numpy"
) -> tuple[float, float]:
    """(along-track, slant range) in metres of the brightest pixel of the image that ``batches``
    (shots [pulse, sample], in order) focus to, uncorrected; bounded memory (one line block at
    a time).  ``--correct pra`` takes it as the retro-reflector when neither the command nor the
    scene gives one (Crouch's retro is the scene's brightest point)."""
    eng = StreamProcessor(config, lens_backend, None, start_along_track_m)
    best, where = -1.0, (0, 0)

    def look(out: Lines) -> None:
        nonlocal best, where
        if len(out.lines):
            mag = np.abs(out.lines)
            k = int(np.argmax(mag))
            if mag.flat[k] > best:
                best = float(mag.flat[k])
                where = (out.first_line + k // mag.shape[1], k % mag.shape[1])

    for shots in batches:
        look(eng.push(shots))
    look(eng.flush())
    if best <= 0:
        raise ValueError("no bright point to take as the retro-reflector: the image is empty")
    line, col = where
    return float(eng.azimuth_m(line, 1)[0]), float(eng.range_m[col])
