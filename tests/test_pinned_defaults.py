"""The defaults the docs state, pinned (issue 39, item 2): each figure is read from the pages
that state it and compared with the code's default and with what the code then does.

Each of these was changed in the code once and every test still passed: the queues' capacity
(8 apertures of pulses), the status line's cadence (twice a second on a terminal, every 5 s
otherwise), the endpoint (tcp://127.0.0.1:5555), the strips (16 lines) and the longest gap
zero-filled (one aperture).
"""

import io
import os
import re
import subprocess
import sys
import types
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from test_pipeline import Collect  # the in-process sink that keeps every strip

from rtsar.app import live
from rtsar.app.cli import build_parser
from rtsar.app.cli.options import pipeline_settings
from rtsar.presets import preset
from rtsar.sources.replay import ReplaySource
from rtsar.stream.granularity import MOST_STRIP_LINES
from rtsar.stream.pipeline import Pipeline, PipelineSettings

ROOT = Path(__file__).resolve().parents[1]
PAGES = ROOT / "docs" / "pages"
NUMBER_WORDS = {"one": 1, "two": 2, "three": 3, "four": 4, "once": 1, "twice": 2}


def page_text(relative: str) -> str:
    """A page's text with every run of white space one space (a figure may span lines)."""
    return " ".join((ROOT / relative).read_text(encoding="utf-8").split())


def stated(pattern: str, *pages: str) -> list[str]:
    """The figure (the pattern's group) at every place the pages state it: at least one each."""
    found = []
    for page in pages:
        here = re.findall(pattern, page_text(page))
        assert here, f"{page} no longer states {pattern!r}: the test must read its figure"
        found += here
    return found


def one_figure(pattern: str, *pages: str) -> str:
    """The figure the pages state, the same wherever they state it."""
    figures = set(stated(pattern, *pages))
    assert len(figures) == 1, f"the pages disagree on {pattern!r}: {sorted(figures)}"
    return figures.pop()


def number(text: str) -> float:
    return float(NUMBER_WORDS.get(text, text))


def default_settings() -> PipelineSettings:
    """The pipeline settings of ``rtsar run`` and of ``rtsar replay REC.h5`` with no option but
    the NumPy lens (no OpenCL survey here): the same for both commands."""
    run, replay = (
        pipeline_settings(build_parser(argv[0]).parse_args([*argv, "--lens", "numpy"]))
        for argv in (["run"], ["replay", "rec.h5"])
    )
    assert run == replay
    return run


def replay_of(cfg, seq) -> ReplaySource:
    """Zero shots numbered ``seq``, replayed as fast as the pipeline takes them."""
    seq = np.asarray(seq, np.int64)
    shots = np.zeros((len(seq), cfg.waveform.samples_per_shot), np.complex64)
    prf = cfg.geometry.prf_hz
    return ReplaySource(shots, seq, seq / prf, prf, "max", 16)


@pytest.fixture(scope="module")
def cfg():
    return preset("tiny")


def test_queue_capacity_is_the_documented_apertures_of_pulses(cfg):
    """docs/pages/guide/live.md: "bounded queues (capacity 8 apertures of pulses each)"."""
    apertures = int(
        one_figure(r"capacity (\d+) apertures of pulses each", "docs/pages/guide/live.md")
    )
    n = cfg.processor.aperture_pulses
    settings = default_settings()
    assert settings.queue_pulses == 0 and PipelineSettings().queue_pulses == 0  # 0: the default
    pipe = Pipeline(cfg, replay_of(cfg, range(4)), [Collect()], settings)
    for queue in (pipe.q_shots, pipe.q_lines, pipe.q_image):
        held = 0
        while queue.put([0], block=False):  # one pulse at a time, until the queue refuses
            held += 1
        assert held == apertures * n, queue.name


def _cadence(run_with_stream, tty: bool):
    """``(seconds between the pipeline's stats, show)`` of a run whose output is (not) a
    terminal: ``show`` is the status callback run_stream hands the pipeline."""
    seen = {}

    class Spy(Pipeline):
        def __init__(self, *args, **kw):
            seen.update(kw)
            super().__init__(*args, **kw)

    stream = type("Terminal" if tty else "Pipe", (io.StringIO,), {"isatty": lambda self: tty})()
    run_with_stream(Spy, stream)
    return seen["stats_every_s"], seen["on_stats"], stream


def _lines_written(show, stream, clock, call_every_s: float, seconds: float) -> int:
    """Status lines ``show`` writes when called every ``call_every_s`` for ``seconds``, on
    ``clock`` (the test's own: the verdict does not depend on this machine's load), from an
    hour after the clock's last reading."""
    start = clock[0] + 3600.0
    status = {
        "counters": {"pulses_processed": 10},
        "elapsed_s": 1.0,
        "pulse_rate_hz": 10.0,
        "latency_recent_median_ms": 1.0,
        "latency_recent_p99_ms": 2.0,
    }
    before = stream.getvalue()
    calls = round(seconds / call_every_s)
    for k in range(calls):
        clock[0] = start + k * call_every_s
        show(status)
    written = stream.getvalue()[len(before) :]
    return written.count("\r") if stream.isatty() else written.count("\n")


@pytest.mark.parametrize("tty", [True, False], ids=["terminal", "not-a-terminal"])
def test_the_status_line_comes_as_often_as_the_docs_say(cfg, tmp_path, monkeypatch, tty):
    """README and docs/pages/guide/start.md: the status line "twice a second (every 5 s when the
    output is not a terminal)": the lines written when the pipeline's stats come at its own
    cadence, and when they come far more often (the status line throttles itself)."""
    per_second = {
        number(w)
        for w in stated(r"counters? (\w+) a second", "README.md", "docs/pages/guide/start.md")
    }
    assert len(per_second) == 1, per_second
    every_s = number(
        one_figure(
            r"every (\d+(?:\.\d+)?) s when the output is not a terminal",
            "docs/pages/guide/start.md",
        )
    )
    period_s = 1.0 / per_second.pop() if tty else every_s

    def run(spy, stream):
        monkeypatch.setattr(live, "Pipeline", spy)
        source = replay_of(cfg, range(200))
        settings = default_settings()
        endpoint = "ipc://" + str(tmp_path / "pub")
        assert live.run_stream(cfg, source, settings, endpoint, "drop", stream=stream) == 0

    stats_every_s, show, stream = _cadence(run, tty)
    clock = [1e6]
    monkeypatch.setattr(live, "time", types.SimpleNamespace(perf_counter=lambda: clock[0]))
    seconds = 20.0 * period_s
    at_its_cadence = _lines_written(show, stream, clock, stats_every_s, seconds)
    often = _lines_written(show, stream, clock, period_s / 64, seconds)
    assert at_its_cadence == often == round(seconds / period_s), (stats_every_s, period_s)


def test_the_default_endpoint_is_the_documented_one():
    """README, start.md and live.md: strips are published on tcp://127.0.0.1:5555 unless
    --endpoint (or RTSAR_ENDPOINT) says otherwise: every command's parser, in a process
    without RTSAR_ENDPOINT (this session sets its own, conftest.py)."""
    said = one_figure(
        r"(?:publishes the (?:focused )?strips on `|Strips go to |ZeroMQ PUB \()(tcp://[\d.]+:\d+)",
        "README.md",
        "docs/pages/guide/start.md",
        "docs/pages/guide/live.md",
    )
    code = (
        "from rtsar.app.cli import build_parser\n"
        "for argv in (['run'], ['replay', 'r.h5'], ['demo'], ['subscribe', '-o', 'i.h5'],"
        " ['view']):\n"
        "    print(argv[0], build_parser(argv[0]).parse_args(argv).endpoint)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "RTSAR_ENDPOINT"}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.returncode == 0, done.stderr
    got = dict(line.split() for line in done.stdout.splitlines())
    assert got == dict.fromkeys(["run", "replay", "demo", "subscribe", "view"], said)


def test_strips_have_the_documented_number_of_lines(cfg):
    """performance.md: strips of 16 lines, the options' default; README's and live.md's
    diagrams: 1 to MOST_STRIP_LINES lines, as a live run's rate allows (they said 16, where a
    new user's live banners said 1 or 4).  The strips a replay publishes with the options'
    defaults: none longer, and whole ones of that length (a strip is cut short only when no
    line came for a strip's time)."""
    lines = int(one_figure(r"its strip \((\d+) lines\)", "docs/pages/reference/performance.md"))
    pages = ("README.md", "docs/pages/guide/live.md")
    assert int(one_figure(r"1-(\d+) lines\s+├─► rtsar subscribe", *pages)) == MOST_STRIP_LINES
    settings = default_settings()
    assert settings.strip_lines == PipelineSettings().strip_lines == lines
    sink = Collect()
    Pipeline(cfg, replay_of(cfg, range(400)), [sink], settings).run()
    sizes = Counter(len(s.lines) for s in sink.strips)
    assert max(sizes) == lines and sizes[lines] >= 1, sizes
    assert sum(n * k for n, k in sizes.items()) == sink.final["counters"]["lines_out"]


def test_the_longest_gap_zero_filled_is_the_documented_apertures(cfg):
    """live.md: gaps are zero-filled "up to --max-gap-pulses, default one aperture N"
    (faults.md: "default N"): a gap of that many missing shots is filled, one more is a
    restart of the count (a discontinuity)."""
    word = one_figure(r"`--max-gap-pulses`, default (\w+) aperture", "docs/pages/guide/live.md")
    assert (
        one_figure(r"`--max-gap-pulses` \(default (\w+)\)", "docs/pages/reference/faults.md") == "N"
    )
    n = cfg.processor.aperture_pulses
    longest = int(number(word)) * n
    settings = default_settings()
    assert settings.max_gap_pulses == 0 and PipelineSettings().max_gap_pulses == 0  # 0: default
    seq = np.r_[0:100, 100 + longest : 300, 300 + longest + 1 : 500]
    sink = Collect()
    Pipeline(cfg, replay_of(cfg, seq), [sink], settings).run()
    c = sink.final["counters"]
    # the gap filled, and the restart's N zero pulses (clearing the CCD) counted with them
    assert (c["gaps"], c["discontinuities"], c["gap_pulses"]) == (1, 1, longest + n), c
