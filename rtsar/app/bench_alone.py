"""The stages alone, for ``rtsar bench``: one measurement per figure, shared by every table.

The lens table (rtsar.app.bench.bench_lens) and the correlator table record their figures
here; the pipeline section (rtsar.app.bench_pipeline) reuses them for its "lens alone", its
"CCD stage ÷ alone" ratios and its two-core ideals, so the same measurement prints as the same
number wherever it appears, and each line says where it was first reported.  Each figure is
the best of 3 rounds, so one slow moment of a shared machine is not the reference every ratio
divides by; a ratio above 1 is said to be the machine's swing, not a result.
"""

from __future__ import annotations

import numpy as np

from ..analysis.timing import rate_per_s
from ..ccd import make_correlator
from ..ccd.base import design_mask
from ..lens import make_lens
from ..lens.plan import make_plan
from ..params import Config

__all__ = ["ABOVE_ONE", "CorrelatorAlone", "LensAlone", "against_ideal", "lens_alone"]


class CorrelatorAlone:
    """Pulses/s of a correlator alone: the one the pipeline builds from the configuration
    (rtsar.ccd.make_correlator), pushed ``batch`` random lines at a time for ``seconds``.

    One definition, measured once per (preset, correlator, batch) and kept: the bench's
    correlator table and the pipeline's "CCD stage ÷ alone" ratios print the same number for
    the same figure.  ``source`` says where a figure was first reported."""

    def __init__(self, seconds: float = 1.0):
        self.seconds = float(seconds)
        self.rates: dict[tuple[str, str, int], float] = {}
        self.source: dict[tuple[str, str, int], str] = {}

    def rate(self, preset_name: str, cfg: Config, batch: int, where: str = "") -> float:
        key = (preset_name, cfg.processor.correlator, int(batch))
        if key not in self.rates:
            # 3 rounds, each its best: one slow moment of a shared machine does not become
            # the reference every ratio below divides by
            self.rates[key] = max(
                _correlator_alone(cfg, int(batch), self.seconds / 3) for _ in range(3)
            )
            self.source[key] = where
        return self.rates[key]

    def label(self, preset_name: str, cfg: Config, batch: int) -> str:
        """How a figure reads beside a ratio: its correlator, batch, and where it was shown."""
        key = (preset_name, cfg.processor.correlator, int(batch))
        where = self.source.get(key) or "measured here"
        return f"{key[1]} alone, batches of {key[2]}: {self.rates[key]:,.0f} pulses/s, {where}"


class LensAlone:
    """Pulses/s of a lens alone, ``batch`` random shots per call: interleaved rounds, each its
    best (the AO-lens table's definition, rtsar.app.bench.bench_lens).

    One definition, kept per (preset, backend, device, batch): the lens table records its
    figures here (``record``), and the pipeline's "lens alone" and two-core ideals reuse them
    where the pipeline's lens is the same plan on the same backend and device; ``source`` says
    where a figure was first reported."""

    def __init__(self, seconds: float = 1.0, rounds: int = 3):
        self.seconds, self.rounds = float(seconds), int(rounds)
        self.rates: dict[tuple[str, str, str, int], float] = {}
        self.source: dict[tuple[str, str, str, int], str] = {}

    @staticmethod
    def key(preset_name: str, lens, batch: int) -> tuple[str, str, str, int]:
        return (preset_name, lens.backend, getattr(lens, "device_label", ""), int(batch))

    def record(self, key, rate: float, where: str) -> None:
        self.rates.setdefault(key, float(rate))
        self.source.setdefault(key, where)

    def rate(self, preset_name: str, lens, batch: int) -> float:
        key = self.key(preset_name, lens, batch)
        if key not in self.rates:
            rng = np.random.default_rng(0)
            S = lens.plan.samples_per_shot
            x = rng.standard_normal((batch, S)) + 1j * rng.standard_normal((batch, S))
            x = x.astype(np.complex64)
            best = max(
                rate_per_s(lambda: lens.compress(x), batch, self.seconds / self.rounds)
                for _ in range(self.rounds)
            )
            self.record(key, best, "measured here")
        return self.rates[key]


def lens_alone(name: str, cfg: Config, lenses: LensAlone, batch: int = 0) -> dict:
    """The lens the pipeline builds (``--lens auto``'s choice), alone, at ``batch`` pulses a
    call (0: its micro-batch)."""
    batch = batch or cfg.processor.micro_batch
    lens = make_lens(make_plan(cfg), "auto", batch=cfg.processor.micro_batch)
    rate = lenses.rate(name, lens, batch)
    where = lenses.source[LensAlone.key(name, lens, batch)]
    return {"backend": lens.backend, "batch": batch, "pulses_per_s": rate, "source": where}


# Said beside a ratio that a quiet machine keeps at or below 1.
ABOVE_ONE = (
    " (above 1: the machine was slower when the stages were timed alone than in this run; "
    "--repeats 3 measures in rounds)"
)


def against_ideal(run: dict, lens_alone: dict, correlator_alone: float, log) -> None:
    """The run's throughput against its stages' two-core ideal: the lens and the correlator
    each alone on both cores, taking turns, 1/(1/L + 1/C) pulses/s (what a pipeline doing
    nothing but these two stages could reach)."""
    L = lens_alone["pulses_per_s"]
    ideal = 1.0 / (1.0 / L + 1.0 / correlator_alone)
    run["two_core_ideal_pulses_per_s"] = ideal
    run["over_two_core_ideal"] = run["pulses_per_s"] / ideal
    log(
        f"    {run['label']}: {run['over_two_core_ideal']:.2f} of its stages' two-core ideal "
        f"1/(1/{L:,.0f} + 1/{correlator_alone:,.0f}) = {ideal:,.0f} pulses/s"
        + ABOVE_ONE
        * (run["over_two_core_ideal"] > 1.05)
    )


def _correlator_alone(cfg: Config, batch: int, seconds: float) -> float:
    plan = make_plan(cfg)
    p = cfg.processor
    corr = make_correlator(
        p.correlator,
        design_mask(cfg, plan.range_m),
        p.fft_length,
        partition_lines=p.partition_lines,
        tail_block_lines=p.tail_block_lines,
    )
    rng = np.random.default_rng(2)
    shape = (batch, plan.bin_count)
    lines = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
    try:
        return rate_per_s(lambda: corr.push(lines), batch, seconds)
    finally:
        close = getattr(corr, "close", None)
        if close is not None:
            close()
