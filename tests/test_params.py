"""Parameter validation and the preset figures quoted by the papers."""

import math

import pytest

from rtsar.params import (
    C_M_PER_S,
    Config,
    FMCWChirp,
    Geometry,
    Processor,
    PulsedChirp,
    config_from_dict,
)
from rtsar.presets import PRESETS, preset


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_build_and_round_trip(name):
    cfg = preset(name)
    assert config_from_dict(cfg.to_dict()) == cfg


def test_psaltis_presets_match_table_1():
    jpl, mx = preset("psaltis-jpl"), preset("psaltis-max")
    # Psaltis eq. 6: c/2B with B = 40 MHz is about 4 m ("ρ ≈ 4 m").
    assert jpl.waveform.range_resolution_m == pytest.approx(C_M_PER_S / 80e6)
    assert 3.5 < jpl.waveform.range_resolution_m < 4.0
    # 512 x 320 CCD, 10 µs AO aperture, L ≈ 15 km and ρA = L/N ≈ 30 m (eq. 7).
    assert (jpl.processor.aperture_pulses, jpl.processor.range_bins) == (512, 320)
    assert jpl.waveform.receive_window_s == pytest.approx(10e-6)
    assert jpl.geometry.illuminated_length_m == pytest.approx(15e3, rel=0.01)
    assert jpl.azimuth_resolution_m() == pytest.approx(jpl.geometry.illuminated_length_m / 512)
    # Maximum possible: 1200 range cells, ρR < 1 m, ρA ~ 15 m.
    assert mx.processor.range_bins == 1200 and mx.waveform.range_resolution_m < 1.0
    assert mx.azimuth_resolution_m() == pytest.approx(mx.geometry.illuminated_length_m / 512)
    assert 14 < mx.azimuth_resolution_m() < 16


def test_sal_presets_match_the_papers():
    cr, zh = preset("crouch-sal"), preset("zhao-insal")
    assert cr.waveform.chirp_rate_hz_per_s == pytest.approx(10e12)  # 3 THz / 300 ms
    assert cr.waveform.range_resolution_m == pytest.approx(50e-6, rel=0.01)  # Crouch: 50 µm
    assert cr.synthetic_aperture_m == pytest.approx(2048 * 10e-6)
    assert zh.synthetic_aperture_m == pytest.approx(8e-3)
    assert zh.azimuth_resolution_m() == pytest.approx(233e-6, rel=0.01)  # Zhao: 233 µm
    assert zh.waveform.range_resolution_m == pytest.approx(170e-6, rel=0.01)  # Zhao: 170 µm
    assert zh.geometry.illuminated_length_m == pytest.approx(9.3e-3, rel=0.01)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(bandwidth_hz=-1.0), "bandwidth_hz"),
        (dict(sample_rate_hz=10e6), "sample_rate_hz"),
        (dict(pulse_duration_s=20e-6), "shorter"),
        (dict(receive_window_s=math.nan), "receive_window_s"),
    ],
)
def test_pulsed_validation(kwargs, match):
    base = dict(
        bandwidth_hz=40e6, pulse_duration_s=3e-6, sample_rate_hz=48e6, receive_window_s=1e-5
    )
    with pytest.raises(ValueError, match=match):
        PulsedChirp(**{**base, **kwargs})


def test_processor_and_geometry_validation():
    with pytest.raises(ValueError, match="range_oversampling"):
        Processor(aperture_pulses=64, range_bins=64, range_oversampling=3)
    with pytest.raises(ValueError, match="azimuth_window"):
        Processor(aperture_pulses=64, range_bins=64, azimuth_window="kaiser")
    for m in (98, 60):  # 2·7²: not a product of 2, 3 and 5; below N
        with pytest.raises(ValueError, match="fft_length must be >= aperture_pulses and a product"):
            Processor(aperture_pulses=64, range_bins=64, fft_length=m)
    assert Processor(aperture_pulses=64, range_bins=64, fft_length=100).fft_length == 100
    with pytest.raises(ValueError, match="platform_height_m"):
        Geometry(1.0, 100.0, 0.1, 100.0, 0.2, platform_height_m=200.0)
    with pytest.raises(ValueError, match="FMCW"):
        FMCWChirp(bandwidth_hz=1e9, chirp_duration_s=1e-3, sample_rate_hz=1e3, reference_range_m=1)


def test_aliased_aperture_is_refused():
    cfg = preset("tiny")
    with pytest.raises(ValueError, match="aliased"):
        Config(cfg.waveform, cfg.geometry, Processor(aperture_pulses=4096, range_bins=64))


def test_unknown_preset_lists_names():
    with pytest.raises(ValueError, match="psaltis-jpl"):
        preset("nope")


def test_partition_lines_is_a_power_of_two_up_to_the_aperture():
    base = dict(aperture_pulses=64, range_bins=8, correlator="partitioned")
    assert Processor(**base).partition_lines == 16
    assert Processor(**base, partition_lines=1).partition_lines == 1
    assert Processor(**base, partition_lines=64).partition_lines == 64  # L = N: one partition
    for bad in (0, -16, 3, 24, 2.0, None):
        with pytest.raises(ValueError, match="partition_lines must be a power of two"):
            Processor(**base, partition_lines=bad)
    with pytest.raises(ValueError, match="partition_lines 128 exceeds aperture_pulses 64"):
        Processor(**base, partition_lines=128)
    # Only the partitioned correlator uses the knob: a short aperture with the default is fine.
    assert Processor(aperture_pulses=8, range_bins=8, correlator="fft").partition_lines == 16
    with pytest.raises(ValueError, match="partition_lines 16 exceeds aperture_pulses 8"):
        Processor(aperture_pulses=8, range_bins=8, correlator="partitioned")
    with pytest.raises(ValueError, match="'direct', 'fft', 'partitioned'"):
        Processor(aperture_pulses=64, range_bins=8, correlator="shift-register")
    cfg = preset("psaltis-max").with_processor(correlator="partitioned", partition_lines=32)
    assert config_from_dict(cfg.to_dict()) == cfg


def test_precision_and_range_migration_knobs_round_trip():
    cfg = preset("crouch-sal").with_processor(precision="complex128", range_migration_taps=4)
    back = config_from_dict(cfg.to_dict())
    assert back == cfg
    assert (back.processor.precision, back.processor.range_migration_taps) == ("complex128", 4)
    assert preset("tiny").processor.range_migration_taps == 0  # off by default
    with pytest.raises(ValueError, match="precision must be one of"):
        Processor(aperture_pulses=64, range_bins=8, precision="complex32")
    with pytest.raises(ValueError, match="range_migration_taps"):
        Processor(aperture_pulses=64, range_bins=8, range_migration_taps=-2)
