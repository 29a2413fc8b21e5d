"""The last lines of a live run (rtsar/app/live.py): losses and what was done about them are
"counted:"; late releases of a busy simulator, which lose nothing, are "noted:" with what
they are (the walkthrough read "counted: late releases 1118" on runs that kept their PRF and
dropped nothing, as an alarm)."""

import io

import numpy as np

from rtsar.app import live
from rtsar.presets import preset
from rtsar.sources.replay import ReplaySource
from rtsar.stream.pipeline import PipelineSettings


def summary(tmp_path, extra: dict) -> str:
    cfg = preset("tiny")
    seq = np.arange(200, dtype=np.int64)
    shots = np.zeros((len(seq), cfg.waveform.samples_per_shot), np.complex64)
    prf = cfg.geometry.prf_hz
    source = ReplaySource(shots, seq, seq / prf, prf, "max", 16)
    source.counters.update(extra)
    stream = io.StringIO()
    settings = PipelineSettings(lens_backend="numpy")
    endpoint = "ipc://" + str(tmp_path / "pub")
    assert live.run_stream(cfg, source, settings, endpoint, "drop", stream=stream) == 0
    return stream.getvalue()


def test_late_releases_are_noted_with_what_they_are_not_counted_as_a_loss(tmp_path):
    out = summary(tmp_path, {"late_releases": 3})
    assert "noted: late releases 3, chunks of simulated shots sent over 1 ms" in out
    assert "no shot lost" in out and "counted:" not in out


def test_a_loss_beside_them_is_still_counted(tmp_path):
    out = summary(tmp_path, {"late_releases": 3, "header_crc_errors": 2})
    assert (
        "counted: header CRC errors 2" in out
        and "late releases" not in out.split("counted:")[1].splitlines()[0]
    )
    assert "noted: late releases 3" in out


def test_the_end_s_status_line_is_not_printed_twice(tmp_path):
    """Not on a terminal, a status line every 5 s and one at the end: where a line was just
    printed (under 1 s before the end), the end's would repeat it (a walkthrough saw
    `t= 6.0 s …` twice before the `done:` line)."""
    cfg = preset("tiny")  # 500 pulses/s: 600 shots at the real rate, 1.2 s
    seq = np.arange(600, dtype=np.int64)
    shots = np.zeros((len(seq), cfg.waveform.samples_per_shot), np.complex64)
    prf = cfg.geometry.prf_hz
    source = ReplaySource(shots, seq, seq / prf, prf, "real", 16)
    stream = io.StringIO()
    settings = PipelineSettings(lens_backend="numpy")
    endpoint = "ipc://" + str(tmp_path / "pub")
    assert live.run_stream(cfg, source, settings, endpoint, "drop", stream=stream) == 0
    status = [line for line in stream.getvalue().splitlines() if line.startswith("t=")]
    # the first stats message (after 1 s) prints; the end's, about 0.2 s later, does not
    assert len(status) == 1, status
    assert "done: 600 pulses" in stream.getvalue()
