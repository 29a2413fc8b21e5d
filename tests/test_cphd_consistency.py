"""Every preset's and built-in scene's CPHD export passes both independent consistency
checkers, sarkit's CphdConsistency (all checks, thorough) and sarpy's cphd_consistency (issue
28), but for the one property of a Nyquist-sampled dechirp receiver that the docs name
(docs/pages/reference/files.md): FX_OSR = S / (S - 1) < 1.1 where the processor images all S
beat bins.  Before: TOAFixed was written as (pulses == 1), while a strip map's TOA1/TOA2 are
constant up to 1e-17 s of rounding: psaltis-jpl and demo failed both checkers."""

import logging

import pytest

sv = pytest.importorskip("sarkit.verification")
spc = pytest.importorskip("sarpy.consistency.cphd_consistency")

from rtsar.app.cli import main  # noqa: E402
from rtsar.scene import load_scene, scene_from_dict  # noqa: E402
from rtsar.sources.formats.phase_history import fx_mapping  # noqa: E402

# FMCW scenes whose range window is every beat bin the sampling holds (fs / K of TOA).
NYQUIST_DECHIRP = {"zhao-insal", "sal-demo", "crouch-spotlight"}


def _failures(checker) -> set:
    checker.check()
    return {
        (name, d["severity"], d["details"])
        for name, v in checker.failures().items()
        for d in v["details"]
        if not d["passed"]
    }


@pytest.mark.parametrize(
    "scene",
    [
        "tiny",
        "psaltis-jpl",
        "psaltis-max",
        "crouch-sal",
        "zhao-insal",
        "crouch-spotlight",
        "demo",
        "sal-demo",
    ],
)
def test_cphd_of_every_preset_and_scene_passes_sarkit_and_sarpy(scene, tmp_path):
    if scene in ("demo", "sal-demo"):
        cfg = load_scene(scene).config
        source = scene
    else:
        cfg = scene_from_dict({"preset": scene, "targets": []}).config
        r = fx_mapping(cfg).srp_range_m
        text = f'preset = "{scene}"\n[[targets]]\nalong_track_m = 0.0\nslant_range_m = {r!r}\n'
        (tmp_path / "s.toml").write_text(text)
        source = str(tmp_path / "s.toml")
    rec, out = tmp_path / "rec.h5", tmp_path / "rec.cphd"
    pulses = cfg.processor.aperture_pulses + 64  # an image of 64 lines
    assert main(["simulate", source, "--pulses", str(pulses), "-o", str(rec)]) == 0
    assert main(["export", str(rec), "--cphd", str(out)]) == 0
    with open(out, "rb") as f:
        sk = _failures(sv.CphdConsistency.from_file(f, thorough=True))
    logging.disable(logging.WARNING)  # sarpy logs every check it runs
    try:
        sp = _failures(spc.CphdConsistency.from_file(str(out), check_signal_data=True))
    finally:
        logging.disable(logging.NOTSET)
    expected = set()
    if scene in NYQUIST_DECHIRP:
        m = fx_mapping(cfg)
        osr = 1.0 / (m.scss_hz * (m.toa2_s - m.toa1_s))
        s = cfg.waveform.samples_per_shot
        assert osr == pytest.approx(s / (s - 1), rel=1e-9)  # every beat bin imaged
        expected = {
            ("check_channel_fx_osr_rtsar_main", "Error", "FX_OSR is at least 1.1"),
            ("check_channel_fx_osr_rtsar_main", "Warning", "FX_OSR is at least 1.2"),
        }
    assert sk == expected and sp == expected
