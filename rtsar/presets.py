"""The instruments of the source papers as configurations (docs/pages/reference/conventions.md)."""

from __future__ import annotations

from dataclasses import replace

from .params import Config, FMCWChirp, Geometry, Processor, PulsedChirp


def _psaltis_jpl() -> Config:
    # Experimental processor of Psaltis & Wagner (Table 1): 40 MHz chirp, 10 µs AO aperture,
    # 512 x 320 CCD, L ≈ 15 km illuminated.  L-band (JPL), 20 km slant range, 250 m/s.
    # D = 2·step (Nyquist in azimuth, Crouch eq. 4.10) makes ρA = λR/(2Nd) = L/N (Psaltis eq. 7).
    return Config(
        PulsedChirp(
            bandwidth_hz=40e6, pulse_duration_s=3.2e-6, sample_rate_hz=48e6, receive_window_s=10e-6
        ),
        Geometry(
            wavelength_m=0.235,
            slant_range_m=20e3,
            along_track_step_m=0.15625,
            prf_hz=1600.0,
            antenna_length_m=0.3125,
        ),
        Processor(aperture_pulses=512, range_bins=320),
    )


def _psaltis_max() -> Config:
    # "Maximum possible" column of Table 1: 1200 range cells, ρR < 1 m, ρA ~ 15 m, N = 512.
    # X-band, 15 km, PRF 10 kHz, 300 m/s; D = 2·step so ρA = L/N ≈ 15.3 m.
    return Config(
        PulsedChirp(
            bandwidth_hz=200e6, pulse_duration_s=2e-6, sample_rate_hz=240e6, receive_window_s=7.5e-6
        ),
        Geometry(
            wavelength_m=0.03125,
            slant_range_m=15e3,
            along_track_step_m=0.03,
            prf_hz=10e3,
            antenna_length_m=0.06,
        ),
        Processor(aperture_pulses=512, range_bins=1200),
    )


def _radarsat1() -> Config:
    # RADARSAT-1 fine beam as in Cumming & Wong's Vancouver block (../shared/data/radarsat1,
    # the processor `rtsar import` makes of its instrument.toml with a 15 m antenna): C band, a
    # 30.1 MHz down-chirp of 41.75 µs sampled at 32.317 MHz in a fixed 2048-sample window
    # opening 6.5956 ms after the pulse centre, PRF 1256.98 Hz, 7062 m/s, the Doppler centroid
    # -6900 Hz (1.58° of squint: the echo walks 195 m/s, 22 range cells across the 668-pulse
    # aperture).  The CCD holds the aperture plus the 47 rows the squinted beam's centre moves
    # across the 2048 bins.  16 range-migration taps (the samples are only 1.07x the chirp
    # band: rtsar.ccd.migration.taps_for_band; 8 taps widen the Taylor range response 2.0 %,
    # 16 taps 0.6 %), read in each block's azimuth spectrum (rtsar.ccd.doppler_migration):
    # 16 multiply-adds a sample where the time-domain taps need 39 spectral ones for the walk.
    return Config(
        PulsedChirp(
            bandwidth_hz=0.72135e12 * 41.75e-6,
            pulse_duration_s=41.75e-6,
            sample_rate_hz=32.317e6,
            receive_window_s=2048 / 32.317e6,
            down_chirp=True,
            window_start_s=6.5956e-3,
        ),
        Geometry(
            wavelength_m=299_792_458.0 / 5.3e9,
            slant_range_m=993_030.0,
            along_track_step_m=7062.0 / 1256.98,
            prf_hz=1256.98,
            antenna_length_m=15.0,
            doppler_centroid_hz=-6900.0,
        ),
        Processor(
            aperture_pulses=716,
            range_bins=2048,
            range_window="taylor",
            azimuth_window="taylor",
            fft_length=2048,
            range_migration_taps=16,
            range_migration_domain="doppler",
        ),
    )


def _crouch_sal() -> Config:
    # Crouch (2012) stripmap SAL: 1.55 µm, 3 THz over 300 ms, 10 µm steps, 2048 shots in the
    # aperture, ≈1.5 m range, 10 µm fibre aperture.  The LO is delayed to 1.5 m so the beat
    # band is 3.4 kHz wide: 1024 complex samples per shot, a 51 mm unambiguous range window.
    return Config(
        FMCWChirp(
            bandwidth_hz=3e12,
            chirp_duration_s=0.3,
            sample_rate_hz=1024 / 0.3,
            reference_range_m=1.5,
        ),
        Geometry(
            wavelength_m=1.55e-6,
            slant_range_m=1.5,
            along_track_step_m=10e-6,
            prf_hz=2.0,
            antenna_length_m=10e-6,
        ),
        Processor(aperture_pulses=2048, range_bins=512),
    )


def _crouch_spotlight() -> Config:
    # Crouch (2012) ch. 9 spotlight bench: the crouch-sal chirp (3 THz over 300 ms, 1024
    # samples), the Tx/Rx station on a 4.6 m arc about the scene centre, ~100 µm real aperture,
    # ~50 µm steps (D/2): alias-free cross-range extent λR/(2·step) = 7.1 cm over a ~3 cm spot;
    # the LO delayed to the centre.  The sweep is the spotlight scene's (rtsar.spot: 5° by
    # default, 8030 shots, ρ = λ/2Δθ = 8.9 µm).  The processor only matters to a strip-map run
    # of this instrument: a 1.28 cm aperture (ρA = 279 µm, curvature 0.03 cell).
    sal = _crouch_sal()
    return Config(
        replace(sal.waveform, reference_range_m=4.6),
        replace(sal.geometry, slant_range_m=4.6, along_track_step_m=50e-6, antenna_length_m=100e-6),
        Processor(aperture_pulses=256, range_bins=1024),
    )


def _zhao_insal() -> Config:
    # Zhao et al. (2014): 1550 nm, 2.4 m, 8 mm synthetic aperture (233 µm azimuth resolution),
    # 100 ms of chirp giving 170 µm range resolution (B ≈ 0.88 THz), 0.4 mm real apertures.
    return Config(
        FMCWChirp(
            bandwidth_hz=0.8817e12,
            chirp_duration_s=0.1,
            sample_rate_hz=2560.0,
            reference_range_m=2.4,
        ),
        Geometry(
            wavelength_m=1.55e-6,
            slant_range_m=2.4,
            along_track_step_m=50e-6,
            prf_hz=5.0,
            antenna_length_m=0.4e-3,
        ),
        Processor(aperture_pulses=160, range_bins=256),
    )


def _tiny() -> Config:
    # A small, fast variant of psaltis-jpl for tests and quick looks.
    return Config(
        PulsedChirp(
            bandwidth_hz=40e6, pulse_duration_s=2.0e-6, sample_rate_hz=48e6, receive_window_s=4.0e-6
        ),
        Geometry(
            wavelength_m=0.235,
            slant_range_m=2e3,
            along_track_step_m=0.5,
            prf_hz=500.0,
            antenna_length_m=1.0,
        ),
        Processor(aperture_pulses=64, range_bins=64, micro_batch=16),
    )


PRESETS = {
    "psaltis-jpl": _psaltis_jpl,
    "psaltis-max": _psaltis_max,
    "crouch-sal": _crouch_sal,
    "crouch-spotlight": _crouch_spotlight,
    "zhao-insal": _zhao_insal,
    "tiny": _tiny,
    "radarsat1": _radarsat1,
}


def preset(name: str) -> Config:
    """Return the named preset (see PRESETS); raises ValueError listing the names."""
    try:
        return PRESETS[name]()
    except KeyError:
        raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}") from None
