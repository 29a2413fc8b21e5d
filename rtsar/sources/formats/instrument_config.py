"""An instrument file's parameters as an rtsar configuration, and its Doppler centroid.

rtsar.sources.formats.instrument_file reads what a user wrote (the published parameters of a
real acquisition, e.g. ``../shared/data/radarsat1/instrument.toml``); this module turns them
into the Config every other command reads from a recording:

* waveform: the pulsed chirp with its sign (``down_chirp``) and the instrument's fixed receive
  window (``window_start_s``, counted from the pulse centre), every echo centred inside the
  window kept (rtsar.lens.plan);
* geometry: λ = c / f0, the step V / PRF, the squint of ``doppler_centroid_hz`` (the file's, or
  estimated from the data by rtsar.analysis.doppler_centroid), ``antenna_length_m`` (the file's,
  or the one whose Doppler bandwidth 2V/D is DEFAULT_BANDWIDTH_OF_PRF of the PRF);
* processor: the aperture λR/(D d) at mid-swath, plus the rows the squinted beam's centre
  moves across the swath (rtsar.ccd.base.squint_aperture_pulses), the overlap-save correlator
  with its range-migration taps read in each block's azimuth spectrum
  (rtsar.ccd.doppler_migration).
"""

from __future__ import annotations

import math
from dataclasses import replace

from ...ccd.migration import taps_for_band
from ...lens.plan import next_pow2, range_axis_m
from ...params import C_M_PER_S, Config, Geometry, Processor, PulsedChirp
from .instrument_file import InstrumentFile

#: Doppler bandwidth processed when the file gives no antenna length, as a fraction of the PRF
#: (strip-map radars sample their Doppler band at 1.2 to 1.5 times its width).
DEFAULT_BANDWIDTH_OF_PRF = 0.75


def instrument_config(
    inst: InstrumentFile, doppler_centroid_hz: float, micro_batch: int = 64
) -> Config:
    """The Config of an instrument file with the Doppler centroid given (absolute, Hz)."""
    wf = _waveform(inst)
    v = inst.effective_velocity_m_per_s
    step_m = v / inst.prf_hz
    lam = C_M_PER_S / inst.carrier_hz
    antenna_m = inst.antenna_length_m or 2.0 * v / (DEFAULT_BANDWIDTH_OF_PRF * inst.prf_hz)
    centre_m = 0.5 * C_M_PER_S * (inst.window_start_s + 0.5 * wf.receive_window_s)
    geometry = Geometry(
        wavelength_m=lam,
        slant_range_m=centre_m,
        along_track_step_m=step_m,
        prf_hz=inst.prf_hz,
        antenna_length_m=antenna_m,
        doppler_centroid_hz=float(doppler_centroid_hz),
    )
    rows = max(2, round(lam * centre_m / (antenna_m * step_m)))
    first = Config(wf, geometry, _processor(rows, wf, micro_batch))
    # The beam centre moves across the swath with a squint: the CCD holds those rows too.
    axis = range_axis_m(first)
    drift = abs(geometry.beam_centre_offset_m(float(axis[-1] - axis[0]))) / step_m
    n = rows + (math.ceil(drift) + 1 if geometry.squinted else 0)
    geometry = replace(geometry, slant_range_m=float(axis[len(axis) // 2]))
    return Config(wf, geometry, _processor(n, wf, micro_batch))


def _waveform(inst: InstrumentFile) -> PulsedChirp:
    rate = inst.chirp_rate_hz_per_s
    return PulsedChirp(
        bandwidth_hz=abs(rate) * inst.pulse_length_s,
        pulse_duration_s=inst.pulse_length_s,
        sample_rate_hz=inst.sample_rate_hz,
        receive_window_s=inst.shape[1] / inst.sample_rate_hz,
        down_chirp=rate < 0,
        window_start_s=inst.window_start_s,
    )


def _processor(rows: int, wf: PulsedChirp, micro_batch: int) -> Processor:
    return Processor(
        aperture_pulses=rows,
        range_bins=wf.samples_per_shot,
        range_window="taylor",
        azimuth_window="taylor",
        correlator="fft",
        fft_length=next_pow2(2 * rows),
        micro_batch=micro_batch,
        # a radar's samples often cover the chirp band only 1.1x over: taps for the band's edge
        range_migration_taps=taps_for_band(wf.bandwidth_hz / wf.sample_rate_hz),
        range_migration_domain="doppler",
    )
