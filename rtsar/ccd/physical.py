"""The physical shifting CCD: a drop-in correlator that detects intensity like the hardware.

Psaltis & Wagner 1981, "Description of the processor" and the image-quality paragraph after
Table 1.  PhysicalCCD has the interface of rtsar.ccd's correlators (push range-compressed lines,
receive finished complex image lines on the same scale; flush), but between the two it does what
the optical processor does (derivation: rtsar.physical.carrier):

1. each pulse becomes E exposures of intensity on a bias with a spatial carrier (eq. P1);
2. a real, non-negative mask weights every row; the charge register integrates, clips at the
   full well and blooms per exposure (rtsar.physical.register, numba);
3. each packet read out gets the named CCD effects, in the order of the hardware: dark charge and
   fixed pattern, shot noise (Poisson of the packet's charge: a sum of Poisson exposures is
   Poisson), read noise after double-correlated sampling, the ADC;
4. the readout subtracts the bias frame, demodulates the carrier and filters along azimuth
   (eqs. of section 3), scaled by 1 / e_u back to image units.

Counters: pixel_overflows (pixel-exposures over the well), drained_e, bloomed_e, adc_clipped
(samples at an ADC end), saturated_lines (lines whose filter span held a clipped or bloomed
packet); ``last_line_flags`` marks those among the lines of the last push or flush.
"""

from __future__ import annotations

import math

import numpy as np

from ..params import Config
from ..physical.carrier import (
    READOUT_HALF,
    demodulate,
    exposure_intensity,
    make_carrier_plan,
    readout_filter,
)
from ..physical.register import STAT_BLOOMED_E, STAT_DRAINED_E, STAT_OVERFLOWS, ShiftRegister
from ..physical.settings import PhysicalSettings
from .base import Correlator, design_mask


class PhysicalCCD(Correlator):
    """The shifting CCD with a real mask, intensity detection on a bias and a spatial carrier.

    Parameters
    ----------
    config : Config
        Processor configuration: N = aperture_pulses pulses integrated, B = range_bins cells.
    range_m : np.ndarray
        Slant range of each range bin (the lens plan's axis), for the mask (design_mask).
    settings : PhysicalSettings, optional
        Carrier, well, bias, scale and the opt-in effects (default: every effect off).

    The CCD is ``ccd_rows`` = E·N rows by ``ccd_columns`` = K·B columns (carrier in range: E = 1,
    K = 2; in azimuth: E = 2, K = 1).  Line i covers pulses i … i+N-1 like the ideal correlators
    and leaves ``latency_pulses`` pulses later than theirs (the readout filter).
    """

    def __init__(
        self, config: Config, range_m: np.ndarray, settings: PhysicalSettings | None = None
    ):
        self.settings = settings = settings or PhysicalSettings()
        proc = config.processor
        if getattr(proc, "range_migration_taps", 0):
            raise ValueError("the physical CCD has a 2-D mask: set range_migration_taps = 0")
        mask = design_mask(config, range_m)
        if proc.precision == "complex64":
            super().__init__(mask)
        else:
            super().__init__(mask, proc.precision)
        self._out_dtype = np.dtype(getattr(self, "dtype", np.complex64))
        self.plan = plan = make_carrier_plan(mask, settings.carrier)
        self.ccd_rows, self.ccd_columns = plan.ccd_rows, plan.ccd_columns
        self.rows_per_pulse = plan.exposures_per_pulse
        self.columns_per_range_cell = plan.columns_per_cell
        self.range_cells = plan.cells
        self.pulses_integrated = plan.pulses
        # Line i needs packet E·i + 3, read out after exposure E·i + R + 2: pulse i + N + ⌊2/E⌋.
        self.latency_pulses = 1 + (READOUT_HALF - 1) // plan.exposures_per_pulse

        well, bf = settings.full_well_e, settings.bias_fraction
        t_sum = plan.transmittance.sum(axis=0)
        self.beta = math.sqrt(bf * well / float(t_sum.max()))
        self.electrons_per_unit = (1.0 - bf) * well / settings.full_scale_amplitude
        e, n = plan.exposures_per_pulse, plan.pulses
        self.gamma = 2.0 * self.electrons_per_unit * plan.mask_peak / (self.beta * e * n)
        self.bias_e = self.beta**2 * t_sum  # the bias frame C[c], eq. (P3)

        seeds = np.random.SeedSequence([settings.seed, 0x50C0]).spawn(2)
        self._rng = np.random.default_rng(seeds[0])
        transmittance = plan.transmittance
        self._dark_e = np.zeros(plan.ccd_columns)
        self._dark_nominal_e = 0.0
        fpn = settings.ccd_effect("fixed_pattern")
        if fpn is not None:
            pattern = np.random.default_rng(seeds[1])
            shape = transmittance.shape
            gain = np.maximum(1.0 + fpn.gain_rms * pattern.standard_normal(shape), 0.0)
            transmittance = transmittance * gain
            dark = np.maximum(fpn.dark_e + fpn.dark_rms_e * pattern.standard_normal(shape), 0.0)
            self._dark_e = dark.sum(axis=0)
            self._dark_nominal_e = fpn.dark_e * plan.ccd_rows
        self._shot = settings.ccd_effect("shot_noise") is not None
        read = settings.ccd_effect("read_noise")
        self._read_sigma = 0.0 if read is None else read.sigma_e
        self._adc = settings.ccd_effect("quantization")
        bloom = settings.ccd_effect("blooming") is not None
        self.register = ShiftRegister(transmittance, well, bloom, prefill_e=self.beta**2)

        # Demodulated packets kept for the filter: z of packets _z_first … (≤ 2·READOUT_HALF).
        self._z = np.zeros((0, plan.cells), np.complex128)
        self._z_flags = np.zeros(0, bool)
        self._z_first = -READOUT_HALF
        self._next_line = 0
        self._flushed_through = -1
        self.adc_clipped = 0
        self.saturated_lines = 0
        self.last_line_flags = np.zeros(0, bool)
        self.keep_raw = False
        self.last_raw_e = None  # charge read out (e-, after the ADC) when keep_raw is set

    # ---- counters ---------------------------------------------------------------------------
    @property
    def pixel_overflows(self) -> int:
        return int(self.register.stats[:, STAT_OVERFLOWS].sum())

    @property
    def drained_e(self) -> float:
        return float(self.register.stats[:, STAT_DRAINED_E].sum())

    @property
    def bloomed_e(self) -> float:
        return float(self.register.stats[:, STAT_BLOOMED_E].sum())

    def counters(self) -> dict:
        return {
            "pulses_in": self.pulses_in,
            "lines_out": self.lines_out,
            "pixel_overflows": self.pixel_overflows,
            "drained_e": self.drained_e,
            "bloomed_e": self.bloomed_e,
            "adc_clipped": self.adc_clipped,
            "saturated_lines": self.saturated_lines,
        }

    def describe(self) -> dict:
        """What the emulated device is and what its readout does (for reports)."""
        p = self.plan
        return {
            "carrier": p.carrier,
            "ccd_rows": self.ccd_rows,
            "ccd_columns": self.ccd_columns,
            "rows_per_pulse": self.rows_per_pulse,
            "columns_per_range_cell": self.columns_per_range_cell,
            "range_cells": self.range_cells,
            "pulses_integrated": self.pulses_integrated,
            "bias_e": float(self.bias_e.max()),
            "electrons_per_unit": self.electrons_per_unit,
            "latency_pulses": self.latency_pulses,
            "readout": (
                "bias frame subtracted; "
                + (
                    "I/Q from the 2 columns of each cell (reference a quarter fringe apart)"
                    if p.carrier == "range"
                    else "carrier demodulated across packets (2 exposures per pulse)"
                )
                + "; derotated; FIR [-3 4 11 8 11 4 -3]/32 along azimuth"
            ),
        }

    # ---- the stream -------------------------------------------------------------------------
    def _read(self, charge: np.ndarray) -> np.ndarray:
        """CCD effects on packets read out (e-), then the bias frame subtracted."""
        q = charge + self._dark_e
        if self._shot:
            q = self._rng.poisson(np.maximum(q, 0.0)).astype(np.float64)
        if self._read_sigma:
            q = q + self._read_sigma * self._rng.standard_normal(q.shape)
        if self._adc is not None:
            full = self._adc.full_scale_e or self.settings.full_well_e
            top = 2**self._adc.bits - 1
            lsb = full / top
            code = np.rint(q / lsb)
            clipped = (code < 0) | (code > top)
            self.adc_clipped += int(clipped.sum())
            q = np.clip(code, 0, top) * lsb
        if self.keep_raw:
            self.last_raw_e = q
        return q - (self.bias_e + self._dark_nominal_e)

    def _lines_from(self, z, flags, z_first, stop_line):
        """Filter demodulated packets (z[0] is packet z_first) and pick the aligned lines."""
        zf = readout_filter(z)
        e = self.plan.exposures_per_pulse
        centre = z_first + READOUT_HALF + np.arange(len(zf))  # packet index of each output
        first = max(self._next_line, self._flushed_through + 1)
        pick = (centre % e == 0) & (centre // e >= first) & (centre // e <= stop_line)
        idx = np.flatnonzero(pick)
        line_flags = np.zeros(len(idx), bool)
        if len(idx):
            span = np.lib.stride_tricks.sliding_window_view(flags, 2 * READOUT_HALF + 1)
            line_flags = span[idx].any(axis=1)
        out = (zf[idx] / self.electrons_per_unit).astype(self._out_dtype)
        return out, line_flags, (int(centre[idx[-1]] // e) if len(idx) else None)

    def _demodulate_packets(self, charge, pflags, first_packet):
        """Read packets, demodulate; drop those before the first one the filter needs."""
        skip = max(0, -READOUT_HALF - first_packet)
        charge, pflags = charge[skip:], pflags[skip:]
        if not len(charge):
            return self._z, self._z_flags, self._z_first
        z_new = demodulate(self._read(charge), first_packet + skip, self.plan)
        z = np.concatenate([self._z, z_new])
        flags = np.concatenate([self._z_flags, pflags.any(axis=1)])
        z_first = self._z_first if len(self._z) else first_packet + skip
        return z, flags, z_first

    def _emit(self, out, line_flags):
        self.last_line_flags = line_flags
        self.saturated_lines += int(line_flags.sum())
        self.lines_out += len(out)
        return out

    def push(self, lines: np.ndarray) -> np.ndarray:
        lines = np.asarray(lines)
        if lines.ndim != 2 or lines.shape[1] != self.range_bins:
            raise ValueError(f"lines must be [pulses, {self.range_bins}], got {lines.shape}")
        if not np.all(np.isfinite(lines)):
            raise ValueError("lines hold NaN or Inf: the physical CCD cannot expose them")
        if not len(lines):
            return np.zeros((0, self.range_bins), self._out_dtype)
        reg = self.register
        first_exposure = reg.exposures
        intensity = exposure_intensity(lines, self.plan, first_exposure, self.beta, self.gamma)
        charge, pflags = reg.expose(intensity)
        self.pulses_in += len(lines)
        first_packet = first_exposure - (reg.rows - 1)
        z, flags, z_first = self._demodulate_packets(charge, pflags, first_packet)
        out, line_flags, last = self._lines_from(z, flags, z_first, self.pulses_in - self.aperture)
        if last is not None:
            self._next_line = last + 1
        keep = min(len(z), 2 * READOUT_HALF)
        self._z, self._z_flags = z[len(z) - keep :], flags[len(z) - keep :]
        self._z_first = z_first + len(z) - keep
        return self._emit(out, line_flags)

    def flush(self) -> np.ndarray:
        """Lines whose pulses have all arrived but whose readout filter still waits.

        The missing packets are made by exposing a copy of the register to the reference alone
        (the radar has stopped; the CCD keeps clocking): the lines are exact up to the signal
        those packets would have held.  The register itself is untouched, so a later push
        continues the stream; lines given here are not given again.
        """
        last_line = self.pulses_in - self.aperture
        if last_line < max(self._next_line, self._flushed_through + 1):
            return np.zeros((0, self.range_bins), self._out_dtype)
        reg = self.register.copy()
        first_exposure = reg.exposures
        intensity = np.full((READOUT_HALF, reg.columns), self.beta**2)
        charge, pflags = reg.expose(intensity)
        first_packet = first_exposure - (reg.rows - 1)
        z, flags, z_first = self._demodulate_packets(charge, pflags, first_packet)
        out, line_flags, last = self._lines_from(z, flags, z_first, last_line)
        if last is not None:
            self._flushed_through = last
        return self._emit(out, line_flags)
