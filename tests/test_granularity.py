"""The live run's granularity (issue 38, goal 1): the chosen block, strips and lens calls are the
documented function of the measured costs (rtsar.stream.granularity), a partial strip goes out
at its deadline (a fake clock), the lens waits for each block's pulses where it is aligned,
the command line's options stay fixed, and the banner says what was chosen and why.  No
verdict here depends on this machine's speed: the costs are given."""

import io
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rtsar.app import bench_latency, live, live_granularity
from rtsar.app.cli import build_parser
from rtsar.app.cli.options import pipeline_settings, processor_changes, strip_lines
from rtsar.app.live_granularity import (
    GranularityRequest,
    block_candidates,
    request_of,
    stages_words,
)
from rtsar.lens.small_calls import TIMED_UP_TO
from rtsar.presets import preset
from rtsar.sources.replay import ReplaySource
from rtsar.stream.granularity import (
    FUSE_BELOW,
    MOST_STRIP_LINES,
    STRIP_DEADLINE_S,
    StageCosts,
    choose_granularity,
    granularity_words,
    lens_call,
    live_correlator,
)
from rtsar.stream.growth import growth_words
from rtsar.stream.pipeline import Pipeline, PipelineSettings
from rtsar.stream.strips import InfoChange, LineBlock, StreamInfo, StripAssembler

ROOT = Path(__file__).resolve().parents[1]
US = 1e-6
# A machine where each block costs 100 µs plus 10 µs a line, a strip 100 µs, a lens call
# 100 µs plus 5 µs a pulse (the shape measured on the development machine: a fixed cost a call).
BLOCKS = (1, 2, 4, 8, 16, 32, 64)  # the candidates of the nonuniform correlator (block_candidates)
COSTS = StageCosts(
    lens_s={b: (100 + 5 * b) * US for b in BLOCKS},
    block_s={b: (100 + 10 * b) * US for b in BLOCKS},
    strip_s=100 * US,
)


def by_hand(rate_hz: float, block: int) -> float:
    """The docstring's utilisation, written out: lens a pulse at the smallest call that keeps
    up + (block + strip) / block lines, times the rate (strips of one block)."""
    keeping_up = [b for b in BLOCKS if (100 + 5 * b) * US <= b / rate_hz]
    calls = keeping_up[0] if keeping_up else BLOCKS[-1]  # none: the least time a pulse
    lens = (100 + 5 * calls) * US / calls
    return rate_hz * (lens + ((100 + 10 * block) * US + 100 * US) / block)


def latency_by_hand(rate_hz: float, block: int, u: float) -> float:
    """The docstring's latency, written out: (B - 1)/2 periods, the block's work S = u B / rate,
    and M/D/1's queueing u S / (2 (1 - u)); infinite at u >= 1."""
    if u >= 1:
        return math.inf
    period = 1 / rate_hz
    work = u * block * period
    return (block - 1) / 2 * period + work + u * work / (2 * (1 - u))


@pytest.mark.parametrize(
    "rate_hz, block",
    [(400, 1), (1500, 1), (2000, 1), (3000, 2), (3500, 2), (4000, 4), (5000, 4), (8000, 32),
     (20000, 32), (40000, 64)],
)  # fmt: skip
def test_the_block_is_the_one_of_least_modelled_latency(rate_hz, block):
    """The documented mapping: the block of least modelled latency, else (none keeps up) the
    largest; a strip per block, a partial one after 1 ms, lines that wait merged up to 64."""
    g = choose_granularity(rate_hz, COSTS, lens_batch=64)
    blocks = BLOCKS
    latency = {b: latency_by_hand(rate_hz, b, by_hand(rate_hz, b)) for b in blocks}
    finite = [b for b in blocks if math.isfinite(latency[b])]
    least = min(finite, key=lambda b: (latency[b], b)) if finite else BLOCKS[-1]
    assert g.block_lines == block == least
    assert g.utilisation == pytest.approx(by_hand(rate_hz, block), rel=1e-12)
    assert g.latency_s == pytest.approx(latency[block], rel=1e-12)
    assert (g.strip_lines, g.strip_most_lines) == (block, MOST_STRIP_LINES)
    assert g.strip_deadline_s == STRIP_DEADLINE_S == 1e-3
    assert g.lens_batch == 64 and g.rate_hz == rate_hz and g.lens_align == 0
    assert ("over this machine's capacity" in g.reason) == (by_hand(rate_hz, block) > 1)
    assert ("the largest" in g.reason) == (not finite)


def test_fixed_strips_longer_than_a_block_are_the_wait_the_model_counts():
    """--strip-lines S: a line waits for its strip, (max(B, S) - 1) / 2 periods, not its
    block's (B - 1) / 2; the strips stay S lines whatever the block."""
    rate_hz, strips = 1500, 8
    g = choose_granularity(rate_hz, COSTS, 64, strip_lines=strips)
    u = {b: rate_hz * ((100 + 5) * US + ((100 + 10 * b) * US + 100 * US / strips * b) / b)
         for b in BLOCKS}  # fmt: skip
    period = 1 / rate_hz
    latency = {}
    for b, ub in u.items():
        work = ub * b * period
        wait = (max(b, strips) - 1) / 2 * period
        latency[b] = wait + work + ub * work / (2 * (1 - ub)) if ub < 1 else math.inf
    assert g.block_lines == min(latency, key=lambda b: (latency[b], b))
    assert g.latency_s == pytest.approx(latency[g.block_lines], rel=1e-12)
    assert g.strip_lines == strips and g.strip_deadline_s is None


def test_an_aligned_lens_costs_one_call_a_block():
    """Aligned (a correlator with a head block): ingest and the lens are paid once a block of
    B pulses, and the lens waits for them (lens_align = B, none for blocks of 1)."""
    costs = StageCosts(COSTS.lens_s, COSTS.block_s, COSTS.strip_s, 0.0,
                       {b: (50 + b) * US for b in BLOCKS})  # fmt: skip
    for rate_hz in (400, 1600, 3000, 8000):
        g = choose_granularity(rate_hz, costs, 64, aligned=True)
        b = g.block_lines
        per_block = (50 + b + 100 + 5 * b + 100 + 10 * b + 100) * US
        assert g.utilisation == pytest.approx(rate_hz * per_block / b, rel=1e-12)
        assert g.lens_call_pulses == b and g.lens_align == (b if b > 1 else 0)
        u = {k: rate_hz * (50 + k + 100 + 5 * k + 100 + 10 * k + 100) * US / k
             for k in BLOCKS}  # fmt: skip
        latency = {k: latency_by_hand(rate_hz, k, u[k]) for k in u}
        assert b == min(latency, key=lambda k: (latency[k], k))


def test_the_stages_are_fused_where_the_work_takes_at_most_70_percent():
    """The layout of the documented rule: lens and correlator on one thread ("fused") where
    the chosen block's work takes at most 70 % of the stream's time (by hand), else two."""
    seen = set()
    for rate_hz in np.geomspace(100, 1e5, 40):
        g = choose_granularity(rate_hz, COSTS, 64, aligned=True)
        b = g.block_lines
        u = rate_hz * (100 + 5 * b + 100 + 10 * b + 100) * US / b  # lens, block, strip
        assert g.utilisation == pytest.approx(u, rel=1e-12)
        assert g.stages == ("fused" if u <= 0.7 else "split"), (rate_hz, u)
        seen.add(g.stages)
    assert seen == {"fused", "split"}


def test_stages_given_stay_and_the_banner_says_a_chosen_layout(monkeypatch):
    """--stages given: the run keeps it and the line does not claim a choice; not given: the
    line ends with the layout and why."""
    monkeypatch.setattr(live_granularity, "measure_costs", _fake_measure(COSTS))
    cfg = preset("tiny").with_processor(correlator="nonuniform")
    for rate_hz, want in ((400, "fused"), (40000, "split")):
        _, chosen, g, words = GranularityRequest(rate_hz).apply(cfg, PipelineSettings())
        assert chosen.stages == g.stages == want
        share = f"the work takes {g.utilisation:.0%}"
        assert words.endswith(f"; {want} stages (lens and correlator on one thread: {share}, "
                              "at most 70%)" if want == "fused" else
                              f"; split stages (lens and correlator on two threads: {share}, "
                              "over 70%)")  # fmt: skip
        other = "split" if want == "fused" else "fused"  # given: kept against the rule
        fixed = GranularityRequest(rate_hz, stages=other)
        _, kept, _, said = fixed.apply(cfg, PipelineSettings(stages=other))
        assert kept.stages == other and "stages (" not in said


def test_blocks_grow_with_the_rate_never_shrink():
    """Graceful: with the lens aligned (a call a block, the live default), a higher rate never
    gets a smaller block (latency grows before drops).  Not aligned, the lens's own call grows
    with the rate (lens_call), which can make a smaller block the faster one again; there the
    choice keeps up wherever a block does."""
    rates = np.geomspace(10, 1e5, 60)
    chosen = [choose_granularity(r, COSTS, 64, aligned=True).block_lines for r in rates]
    assert chosen == sorted(chosen) and chosen[0] == 1 and chosen[-1] == BLOCKS[-1]
    for r in rates:
        g = choose_granularity(r, COSTS, 64)
        keeps_up = any(by_hand(r, b) < 1 for b in BLOCKS)
        assert (g.utilisation < 1) == keeps_up


def test_the_lens_settles_at_the_smallest_call_that_keeps_up():
    assert lens_call(1000, COSTS.lens_s) == (1, pytest.approx(1000 * 105 * US))
    # at 15 kHz a call of 1 (105 µs) or 2 (110 µs) outlasts its pulses' 67 or 133 µs … of 2
    assert lens_call(15000, COSTS.lens_s)[0] == 2
    # none keeps up: the call of least time a pulse, its share over 1
    slow = {1: 1e-3, 2: 1.5e-3}
    assert lens_call(5000, slow) == (2, pytest.approx(5000 * 0.75e-3))


def test_options_stay_fixed():
    """--strip-lines: strips of exactly that many, no deadline, no merging; one candidate
    block (--partition-lines, the fft correlator's): its reason; strips of a huge block capped."""
    g = choose_granularity(1600, COSTS, 64, strip_lines=8)
    assert (g.strip_lines, g.strip_most_lines, g.strip_deadline_s) == (8, 8, None)
    one = StageCosts(COSTS.lens_s, {4: 140 * US}, COSTS.strip_s)
    g = choose_granularity(1600, one, 64, fixed_block="--partition-lines")
    assert g.block_lines == 4 and g.reason.startswith("the block is fixed (--partition-lines)")
    fft = StageCosts(COSTS.lens_s, {513: 20e-3}, COSTS.strip_s)
    g = choose_granularity(1600, fft, 64, fixed_block="the fft correlator's M - N + 1")
    assert (g.block_lines, g.strip_lines) == (513, MOST_STRIP_LINES)
    with pytest.raises(ValueError, match="rate"):
        choose_granularity(0.0, COSTS, 64)


def test_the_candidates_follow_the_correlator():
    p = preset("psaltis-jpl").processor  # fft, N = 512, M = 1024 by default
    # M: the least product of 2, 3 and 5 >= N - 1 + b for b = 1, 2, 4, …, each once, below
    # the configuration's M, then that M; B = M - N + 1.  Written out: 512 = 2^9; 513-518 →
    # 540 = 2^2·3^3·5; 526 → 540; 542 → 576 = 2^6·3^2; 574 → 576; 638 → 640 = 2^7·5;
    # 766 → 768 = 2^8·3; 1022 → 1024, the configuration's.
    assert block_candidates(p) == ([m - 511 for m in (512, 540, 576, 640, 768, 1024)], "")
    assert block_candidates(p, given_fft=4096) == ([3585], "--fft-length")
    rs1 = preset("radarsat1").processor  # N = 716, M = 2048
    # 716 → 720 = 2^4·3^2·5; 717-722 → 720; 723 → 729 = 3^6; 730 → 750 = 2·3·5^3; 746 → 750;
    # 778 → 800 = 2^5·5^2; 842 → 864 = 2^5·3^3; 970 → 972 = 2^2·3^5; 1226 → 1250 = 2·5^4;
    # 1738 → 1800 = 2^3·3^2·5^2; 2762 ≥ 2048: the configuration's M ends the list
    lengths = (720, 729, 750, 800, 864, 972, 1250, 1800, 2048)
    assert block_candidates(rs1) == ([m - 715 for m in lengths], "")
    nonuniform = preset("psaltis-jpl").with_processor(correlator="nonuniform").processor
    assert block_candidates(nonuniform) == ([1, 2, 4, 8, 16, 32, 64], "")
    tiny = preset("tiny").with_processor(correlator="partitioned").processor  # N = 64
    assert block_candidates(tiny)[0][-1] == 64  # at most the aperture
    assert block_candidates(nonuniform, given=4) == ([4], "--partition-lines")


# ---- the strip deadline, on a fake clock ------------------------------------------------------
def _block(first: int, count: int) -> LineBlock:
    z = np.zeros(count)
    return LineBlock(first, np.zeros((count, 2), np.complex64), z, z, np.zeros(count, bool))


@pytest.fixture
def assembler():
    cfg = preset("tiny")
    return StripAssembler(StreamInfo("t", cfg, "test", "numpy", np.arange(2.0), 0.0, 0.0))


def test_a_partial_strip_goes_out_at_its_deadline(assembler):
    """Strips of 16, a deadline D of 2**-10 s (about 1 ms; times in exact binary fractions):
    3 lines come at t = 10 s; nothing is due before 10 s + D, all three are then; the next
    line's wait counts from its own arrival."""
    a, d, q = assembler, 2.0**-10, 2.0**-12  # q: a quarter of the deadline
    a.add(_block(0, 3), now_s=10.0)
    assert a.due(10.0 + 3 * q, 16, 64, d) == 0
    assert a.wait_s(10.0 + q, d) == 3 * q
    assert a.due(10.0 + d, 16, 64, d) == 3
    a.add(_block(3, 1), now_s=10.0 + 2 * q)
    a.take(3, {})
    assert a.due(10.0 + d + q, 16, 64, d) == 0  # the line left waits from 10 s + 2q
    assert a.due(10.0 + d + 2 * q, 16, 64, d) == 1
    assert a.due(99.0, 16, 64, None) == 0  # no deadline: a partial strip waits
    assert a.wait_s(99.0, None) == np.inf


def test_a_new_info_is_the_strips_after_the_lines_before_it(assembler):
    """The correlator's block changed after line 5 (rtsar.stream.growth): the 5 lines before
    go out at once, in strips of at most ``most`` lines, under the old info; the next strips
    under the new one (the new info in the queue of lines: an item of no lines)."""
    a = assembler
    old, new = a.info, replace(a.info, config=a.info.config.with_processor(partition_lines=8))
    assert len(InfoChange(new)) == 0
    a.add(_block(0, 5), now_s=1.0)
    a.add(InfoChange(new), now_s=1.0)
    a.add(_block(5, 8), now_s=1.0)
    assert a.due(1.0, 16, 16, None) == 5  # at once, though strips hold 16
    assert a.due(1.0, 16, 3, None) == 5 and a.due(1.0, 2, 2, None) == 2  # at most max(lines, most)
    strip, _ = a.take(2, {})
    assert (strip.first_line, len(strip.lines), a.info) == (0, 2, old)
    assert a.due(1.0, 16, 16, None) == 3
    strip, _ = a.take(3, {})
    assert (strip.first_line, len(strip.lines), a.info) == (2, 3, old)  # the strip's own info
    assert a.due(1.0, 16, 16, None) == 0 and a.info is new  # then the new one's turn
    assert a.due(1.0, 8, 8, None) == 8
    a.take(8, {})
    a.add(InfoChange(old))  # nothing held: at once
    assert a.held == 0 and a.info is old


def test_the_deadline_counts_from_the_oldest_line_held(assembler):
    """A line that came later does not restart the wait of the lines before it: with blocks at
    t and t + D/2, all the lines held are due at t + D (a steady trickle of lines would
    otherwise hold a partial strip for ever)."""
    a, d = assembler, 2.0**-10
    a.add(_block(0, 2), now_s=10.0)
    a.add(_block(2, 1), now_s=10.0 + d / 2)
    assert a.due(10.0 + d / 2, 16, 64, d) == 0
    assert a.wait_s(10.0 + d / 2, d) == d / 2
    assert a.due(10.0 + d, 16, 64, d) == 3


def test_lines_that_wait_go_out_together(assembler):
    """A backlog (held >= strip_lines) goes out as one strip of up to ``most`` lines; with
    ``most`` at most strip_lines, strips of exactly strip_lines (as before)."""
    a = assembler
    a.add(_block(0, 100), now_s=0.0)
    assert a.due(0.0, 1, 64, 1e-3) == 64
    assert a.due(0.0, 16, 0, None) == 16
    strip, _ = a.take(64, {})
    assert (strip.first_line, len(strip.lines)) == (0, 64)
    assert a.due(0.0, 16, 64, None) == 36


# ---- the choice applied: the command line, the run, its banner ---------------------------------
def _fake_measure(costs):
    def measure(
        config, settings, rate_hz, blocks, copies=1, physical=None, request=None, source_s=0.0
    ):
        block_s = {b: costs.block_s[b] for b in blocks}
        return StageCosts(costs.lens_s, block_s, costs.strip_s, source_s)

    return measure


def test_the_run_gets_the_documented_choice_of_the_measured_costs(monkeypatch):
    """The request applied (measurement replaced by given costs): the configuration's head
    block, the pipeline's strips and its lens's alignment are choose_granularity's (aligned:
    the nonuniform correlator has a head block), and the line says it."""
    monkeypatch.setattr(live_granularity, "measure_costs", _fake_measure(COSTS))
    cfg = preset("tiny").with_processor(correlator="nonuniform")
    for rate_hz, block in ((1500, 1), (3000, 2), (8000, 8), (20000, 16)):
        new_cfg, settings, g, words = GranularityRequest(rate_hz).apply(cfg, PipelineSettings())
        micro = cfg.processor.micro_batch
        assert g == choose_granularity(rate_hz, COSTS, micro, aligned=True)
        assert new_cfg.processor.partition_lines == g.block_lines == block
        assert (settings.strip_lines, settings.strip_most_lines) == (block, MOST_STRIP_LINES)
        assert settings.strip_deadline_s == STRIP_DEADLINE_S
        assert settings.lens_align == (block if block > 1 else 0)
        # the lens holds for a block's pulses two blocks' time at the run's rate, not the PRF's
        assert settings.lens_hold_s == pytest.approx(2 * block / rate_hz if block > 1 else 0)
        assert settings.stages == g.stages  # --stages not given: the run's layout is chosen
        # and the block may grow, through the larger candidates (rtsar.stream.growth)
        larger = tuple(b for b in block_candidates(cfg.processor)[0] if b >= block)
        assert settings.grow_blocks == larger and settings.grow_rate_hz == rate_hz
        assert words == granularity_words(g, COSTS) + f"; {growth_words(larger)}" + (
            f"; {g.stages} stages ({stages_words(g)})"
        )


def test_the_fft_correlator_s_transform_length_is_the_documented_choice(monkeypatch):
    """fft: the candidates are M - N + 1 for the products of 2, 3 and 5 above N
    (block_candidates); the run gets choose_granularity's block as its transform length
    M = B + N - 1, and the lens aligned on its blocks (overlap-save releases every B pulses),
    in calls of at most the lens batch.  Before, the fft correlator kept the configuration's
    M whatever the rate (RADARSAT-1: blocks of 1,333 lines, 0.5-0.8 s of latency at every
    rate)."""
    cfg = preset("radarsat1")
    n, micro = 716, cfg.processor.micro_batch
    blocks = block_candidates(cfg.processor)[0]
    costs = StageCosts(  # a block's transforms 40 µs a row of M; the lens 50 µs a pulse
        lens_s={b: 50 * US * b for b in blocks},
        block_s={b: 40 * US * (b + n - 1) for b in blocks},
        strip_s=1e-3,
        ingest_s={b: 3 * US * b for b in blocks},
    )
    monkeypatch.setattr(live_granularity, "measure_costs", _fake_measure(costs))
    chosen = set()
    for rate_hz in (50.0, 314.0, 1257.0, 1885.0, 4000.0, 9000.0):
        request = GranularityRequest(rate_hz, correlator="fft")  # --correlator fft: fft kept
        new_cfg, settings, g, words = request.apply(cfg, PipelineSettings())
        # aligned: ingest and the lens a block; strips of the block's lines, at most 64
        u = {b: rate_hz * (53 * US + 40 * US * (b + n - 1) / b + 1e-3 / min(b, 64)) for b in blocks}
        latency = {b: latency_by_hand(rate_hz, b, u[b]) for b in blocks}
        want = min(blocks, key=lambda b: (latency[b], b))
        if not math.isfinite(latency[want]):
            want = blocks[-1]
        assert g.block_lines == want, rate_hz
        assert new_cfg.processor.fft_length == want + n - 1
        assert settings.lens_align == want and g.lens_call_pulses == min(want, micro)
        whole = "each block's pulses together" if want <= micro else "a block's last call"
        assert whole in words and words.endswith(f"; fft transform length M = {want + n - 1}")
        chosen.add(want)
    assert len(chosen) >= 3  # the choice follows the rate
    assert block_candidates(cfg.processor, given_fft=1024)[1] == "--fft-length"


def test_a_hopeless_block_is_timed_on_its_warm_calls_only():
    """path_costs_s at a rate where the warm calls already take HOPELESS_SHARE of the stream's
    time stops there (its model is infinite whatever the rounds); at a rate it may keep up
    with, every round is timed.  Counted on the lens's calls, one a block."""
    from rtsar.lens import make_lens, make_plan

    cfg = preset("tiny").with_processor(correlator="nonuniform")
    plan = make_plan(cfg)
    lens = make_lens(plan, "numpy")
    calls = []

    class Counting:
        def compress(self, samples):
            calls.append(len(samples))
            return lens.compress(samples)

    rng = np.random.default_rng(0)

    def noise(rows, cols):
        return (rng.standard_normal((rows, cols)) + 0j).astype(np.complex64)

    g = live_granularity
    for rate_hz, want in ((1e9, g.PATH_WARM_CALLS), (1.0, g.PATH_WARM_CALLS + 3 * 8)):
        calls.clear()
        parts = g.path_costs_s(cfg, plan, Counting(), 1, noise, 64, rate_hz)
        assert len(calls) == want and all(0 < x < 1 for x in parts)


def test_an_fft_block_s_path_is_timed_without_transforming_its_fill():
    """fft (tiny, N = 64): each candidate M's path timed as the pipeline runs it, the fill of
    zeros skipped (skip_zeros), every part a positive figure; the pushes each release their
    block's lines (a strip timed each round)."""
    from rtsar.lens import make_lens, make_plan

    cfg = preset("tiny")
    plan = make_plan(cfg)
    lens = make_lens(plan, "numpy")
    rng = np.random.default_rng(1)

    def noise(rows, cols):
        return (rng.standard_normal((rows, cols)) + 0j).astype(np.complex64)

    for block in block_candidates(cfg.processor)[0]:  # 1, 9, 17, 33, 65
        parts = live_granularity.path_costs_s(cfg, plan, lens, block, noise, 64, 1.0)
        assert all(0 < x < 1 for x in parts), (block, parts)


def test_a_bad_fft_length_on_the_command_line_names_the_option_and_the_aperture():
    args = build_parser("process").parse_args(["process", "r.h5", "-o", "i.h5"])
    for m, rule, nearest in (
        (98, "a product of 2, 3 and 5", 100),
        (30, "at least the aperture, N = 64", 64),
    ):
        args.fft_length = m
        with pytest.raises(
            ValueError, match=rf"--fft-length {m}: must be {rule} \(.* up: {nearest}\)"
        ):
            processor_changes(args, preset("tiny"))
    args.fft_length = 90
    assert processor_changes(args, preset("tiny")).processor.fft_length == 90


def test_each_block_s_path_is_measured_part_by_part_until_past_the_least():
    """The measurement itself (tiny preset, NumPy lens): with a head block, each candidate's
    path is timed (ingest, lens, correlator at that block; one strip), smallest first, and
    the measuring stops at the first block that models worse than a smaller one."""
    cfg = preset("tiny").with_processor(correlator="nonuniform")
    settings = PipelineSettings(lens_backend="numpy")
    candidates = [1, 2, 4, 8, 16]
    costs = live_granularity.measure_costs(cfg, settings, 2000.0, candidates)
    blocks = sorted(costs.block_s)
    assert blocks == candidates[: len(blocks)]
    assert set(costs.lens_s) == set(costs.ingest_s) == set(blocks)
    figures = [*costs.block_s.values(), *costs.lens_s.values(), *costs.ingest_s.values()]
    assert all(0 < x < 1 for x in [*figures, costs.strip_s])

    # Where the measuring stopped, by the docstring's rule written out: the first block whose
    # modelled latency is finite and above a smaller block's (or none: every candidate).
    rate = 2000.0

    def latency(b: int) -> float:
        u = rate * (costs.ingest_s[b] + costs.lens_s[b] + costs.block_s[b] + costs.strip_s) / b
        return latency_by_hand(rate, b, u)

    stop = next(
        (k for k in range(1, len(candidates))
         if candidates[k] in costs.block_s and math.isfinite(latency(candidates[k]))
         and latency(candidates[k]) > min(latency(b) for b in candidates[:k])),
        len(candidates) - 1,
    )  # fmt: skip
    assert blocks == candidates[: stop + 1]


def test_the_source_s_own_work_counts_against_the_target():
    """A simulated source's synthesis shares the machine with the stages: its seconds a pulse
    add rate · source_s to every block's utilisation, so a block that fits alone may not
    (the demo chose blocks of 2 without it and fell behind its PRF: 1,340-1,555 of 1,600)."""
    from dataclasses import replace

    alone = choose_granularity(2000, COSTS, 64)
    with_source = replace(COSTS, source_s=150 * US)  # 30 % of the time at 2,000 pulses/s
    g = choose_granularity(2000, with_source, 64)
    assert alone.block_lines == 1 and g.block_lines > alone.block_lines
    u = {b: by_hand(2000, b) + 0.3 for b in BLOCKS}
    latency = {b: latency_by_hand(2000, b, u[b]) for b in u}
    assert g.block_lines == min(latency, key=lambda b: (latency[b], b))
    assert g.utilisation == pytest.approx(u[g.block_lines], rel=1e-12)
    assert granularity_words(g, with_source).endswith(", the source 150 µs a pulse)")


def test_a_simulated_source_measures_its_synthesis_without_advancing_its_stream():
    from rtsar.scene import load_scene
    from rtsar.sources.sim import SimSource

    fresh = next(iter(SimSource(load_scene("demo"), pulses=64)))
    src = SimSource(load_scene("demo"), pulses=64)
    cost = src.cost_per_pulse_s(places=2, shots=4)
    assert 0 < cost < 1 and np.isfinite(cost)
    first = next(iter(src))
    np.testing.assert_array_equal(first.samples, fresh.samples)


def test_a_live_run_counts_its_simulated_source(monkeypatch, tmp_path):
    """run_stream hands the source's measured cost to the choice."""
    seen = {}

    def apply(self, config, settings, physical=None, height=None, say=None, source_s=0.0):
        seen["source_s"] = source_s
        return config, settings, None, "granularity: (stand-in)"

    monkeypatch.setattr(GranularityRequest, "apply", apply)
    cfg = preset("tiny").with_processor(correlator="nonuniform")
    shots = np.zeros((200, cfg.waveform.samples_per_shot), np.complex64)
    seq = np.arange(200)
    source = ReplaySource(shots, seq, seq / 500.0, 500.0, "max", 16)
    source.cost_per_pulse_s = lambda: 123e-6
    endpoint = "ipc://" + str(tmp_path / "pub")
    settings = PipelineSettings(lens_backend="numpy")
    assert live.run_stream(cfg, source, settings, endpoint, "drop", stream=io.StringIO(),
                           granularity=GranularityRequest(500.0)) == 0  # fmt: skip
    assert seen["source_s"] == 123e-6


def test_the_banner_words():
    g = choose_granularity(1500, COSTS, 64)
    assert granularity_words(g, COSTS) == (
        "granularity: correlator blocks of 1 line, strips of 1 line (lines that wait go out "
        "together, up to 64), a partial strip after 1 ms, lens calls of 1 pulse (up to 64 when "
        "behind), for 1,500 pulses/s: the block (1, 2, 4, … lines) of least modelled latency, "
        "0.46 ms; the work measured takes 47% of the time (lens 105 µs a call, correlator "
        "110 µs a block, strip 100 µs)"
    )
    ingest = {b: 60 * US for b in BLOCKS}
    aligned = StageCosts(COSTS.lens_s, COSTS.block_s, COSTS.strip_s, 0.0, ingest)
    g = choose_granularity(4000, aligned, 64, aligned=True)
    assert g.block_lines == 4 and granularity_words(g, aligned).startswith(
        "granularity: correlator blocks of 4 lines, strips of 4 lines (lines that wait go out "
        "together, up to 64), a partial strip after 1 ms, lens calls of 4 pulses, each block's "
        "pulses together (up to 64 when behind), for 4,000 pulses/s: the block (1, 2, 4, … "
        "lines) of least modelled latency, "
    )
    assert "of the time (ingest 60 µs a call, lens 120 µs a call, correlator 140 µs a block" in (
        granularity_words(g, aligned)
    )


def _args(*argv):
    args = build_parser("replay").parse_args(["replay", "rec.h5", *argv])
    strip_lines(args, 1600.0)
    return args


def test_the_command_line_fixes_what_it_names():
    """Neither --strip-lines nor --partition-lines: both chosen; each given stays; no rate
    (--rate max) or swath workers: no choice; the pipeline's fixed default stays 16."""
    assert request_of(_args(), 1600.0) == GranularityRequest(1600.0, None, None)
    assert request_of(_args("--strip-lines", "8"), 1600.0).strip_lines == 8
    assert request_of(_args("--strip-ms", "5"), 1600.0).strip_lines == 8
    assert request_of(_args("--partition-lines", "4"), 1600.0).block_lines == 4
    assert request_of(_args(), None) is None
    assert request_of(_args("--stages", "split"), 1600.0).stages == "split"
    assert pipeline_settings(_args()).stages == "split"  # chosen by a live run at a rate only
    assert request_of(_args("--swath-workers", "2"), 1600.0) is None
    assert pipeline_settings(_args()).strip_lines == PipelineSettings().strip_lines == 16
    cfg = processor_changes(_args("--partition-lines", "4"), preset("tiny"))
    assert cfg.processor.partition_lines == 4


def test_a_live_run_says_its_granularity_and_runs_with_it(monkeypatch, tmp_path):
    """run_stream with a request: the banner's granularity line, and the pipeline built with
    the chosen configuration and strips (the measurement itself runs: tiny preset)."""
    seen = {}

    class Spy(Pipeline):
        def __init__(self, config, source, sinks, settings, *args, **kw):
            seen["block"], seen["settings"] = config.processor.partition_lines, settings
            super().__init__(config, source, sinks, settings, *args, **kw)

    monkeypatch.setattr(live, "Pipeline", Spy)
    cfg = preset("tiny").with_processor(correlator="nonuniform")
    shots = np.zeros((300, cfg.waveform.samples_per_shot), np.complex64)
    seq = np.arange(300)
    source = ReplaySource(shots, seq, seq / 500.0, 500.0, "max", 16)
    stream = io.StringIO()
    settings = PipelineSettings(lens_backend="numpy")
    request = GranularityRequest(500.0)
    endpoint = "ipc://" + str(tmp_path / "pub")
    assert live.run_stream(cfg, source, settings, endpoint, "drop", stream=stream,
                           granularity=request) == 0  # fmt: skip
    said = [line for line in stream.getvalue().splitlines() if "granularity: " in line]
    assert len(said) == 1 and said[0].startswith("rtsar: granularity: correlator blocks of ")
    block = seen["block"]
    assert f"blocks of {block} line" in said[0] and block in BLOCKS
    s = seen["settings"]
    assert f"; {s.stages} stages (lens and correlator on " in said[0]  # the layout it ran
    assert f", {s.stages} stages, strips of {block} line" in stream.getvalue()
    assert (s.strip_lines, s.strip_most_lines, s.strip_deadline_s) == (
        block,
        MOST_STRIP_LINES,
        STRIP_DEADLINE_S,
    )


# ---- rtsar bench: latency against the offered rate ----------------------------------------------
def test_bench_runs_each_offered_rate_the_capacity_allows_with_its_granularity(monkeypatch):
    """25/50/100/150 % of the PRF, those up to the capacity; each run with the granularity
    chosen for its own rate (measurement replaced by given costs), its goal read from its rate."""
    monkeypatch.setattr(live_granularity, "measure_costs", _fake_measure(COSTS))
    cfg = preset("tiny").with_processor(correlator="nonuniform")  # PRF 500 Hz
    runs, said = [], []

    def stream_run(c, shots, seconds, rate, settings):
        runs.append((rate, c.processor.partition_lines, settings.strip_lines))
        median = {0.25: 1.0, 0.5: 9.0}[rate]  # the goal at 250 Hz: 1 ms + 4 ms
        return {"kept_fraction": 1.0, "dropped_pulses": 0, "latency_median_ms": median,
                "latency_p99_ms": 2.5 * median}  # fmt: skip

    rows = bench_latency.latency_against_rate(cfg, None, 1.0, 0.8, said.append, stream_run)
    expect = [choose_granularity(500 * f, COSTS, 16).block_lines for f in (0.25, 0.5)]
    assert runs == [(0.25, expect[0], expect[0]), (0.5, expect[1], expect[1])]
    assert [r["offered_hz"] for r in rows] == [125.0, 250.0]
    assert [r["meets_goal"] for r in rows] == [True, False]  # 9 ms > 1 + 4 ms
    assert rows[1]["goal_parts"] == {"median": False, "p99": True, "dropped": True}
    assert any(line.endswith("(goal: median <= 9.00 ms met, p99 <= 3x the median (3.00 ms) met, "
                             "0 dropped met)") for line in said)  # fmt: skip
    assert sum("over the capacity measured (0.80x)" in line for line in said) == 2
    assert bench_latency.goal_median_ms(1600.0) == 1.625


def test_bench_names_the_part_of_the_goal_a_row_misses():
    """A row whose median meets the goal and whose p99 does not (bench at 2026-11-29, 800 Hz:
    0.56 / 2.20 ms) said 'goal median <= 2.25 ms: not met', as if the median had missed."""
    row = {"offered_hz": 800.0, "latency_median_ms": 0.56, "latency_p99_ms": 2.20, "dropped": 0}
    assert bench_latency.goal_parts(row) == {"median": True, "p99": False, "dropped": True}
    assert not bench_latency.meets_goal(row)
    words = bench_latency.goal_words(row)
    assert "median <= 2.25 ms met" in words and "(1.68 ms) not met" in words
    assert words.endswith("0 dropped met")
    late = dict(row, latency_median_ms=3.0, latency_p99_ms=4.0, dropped=5)
    assert bench_latency.goal_parts(late) == {"median": False, "p99": True, "dropped": False}
    assert "median <= 2.25 ms not met" in bench_latency.goal_words(late)


def test_the_figures_live_md_states_are_the_code_s():
    """docs/pages/guide/live.md states the deadline (1 ms) and the most lines a strip merges
    (64), the constants the rule uses, and its latency model (the test above writes it out)."""
    text = " ".join((ROOT / "docs/pages/guide/live.md").read_text().split())
    deadline = re.search(r"partial strip goes out once its oldest line has waited (\d+) ms", text)
    most = re.search(r"go out together, up to (\d+) a strip", text)
    assert "(B − 1)/(2r) + S + u·S/(2(1 − u))" in text
    fuse = re.search(r"chooses it where the work it measures \(below\) takes at most (\d+) %", text)
    assert int(fuse.group(1)) / 100 == FUSE_BELOW
    assert int(deadline.group(1)) * 1e-3 == STRIP_DEADLINE_S
    assert int(most.group(1)) == MOST_STRIP_LINES
    small = re.search(r"of each candidate block of up to (\d+) pulses both on the OpenCL", text)
    assert int(small.group(1)) == TIMED_UP_TO


def test_each_path_timing_publishes_on_a_name_never_bound_before(monkeypatch):
    """A closed socket's inproc name is released later by ZeroMQ's I/O thread: CI (53c0161)
    failed twice on "cannot bind inproc://rtsar-granularity-…: Address already in use", the
    name being the id of an object freed by the timing before (17 names for 20 timings)."""
    from rtsar.lens import make_lens, make_plan

    cfg = preset("tiny").with_processor(correlator="nonuniform")
    plan = make_plan(cfg)
    lens = make_lens(plan, "numpy")
    rng = np.random.default_rng(2)
    names = []

    class Recording(live_granularity.ZmqPublisher):
        def __init__(self, endpoint, *args, **kwargs):
            names.append(endpoint)
            super().__init__(endpoint, *args, **kwargs)

    def noise(rows, cols):
        return (rng.standard_normal((rows, cols)) + 0j).astype(np.complex64)

    monkeypatch.setattr(live_granularity, "ZmqPublisher", Recording)
    for _ in range(20):  # hopeless: the warm calls only
        live_granularity.path_costs_s(cfg, plan, lens, 1, noise, 64, 1e9)
    assert len(names) == 20 and len(set(names)) == 20


def test_a_live_run_of_an_fft_configuration_runs_the_nonuniform_correlator(monkeypatch):
    """Every preset names the fft correlator (the fastest over a whole recording), whose lines
    leave in overlap-save blocks of M - N + 1: a live run at psaltis-jpl's PRF chose blocks of
    29 lines, 19.5 ms a line (median) against 1.5 ms nonuniform.  Where the command line names
    no correlator, a live run correlates with the nonuniform one and says so on a line of its
    own; --correlator, --fft-length, the emulated CCD and the Doppler-domain migration (fft's
    alone: RADARSAT-1) keep the configuration's."""
    monkeypatch.setattr(live_granularity, "measure_costs", _fake_measure(COSTS))
    cfg = preset("psaltis-jpl")
    assert cfg.processor.correlator == "fft"
    new_cfg, settings, g, words = GranularityRequest(1600.0).apply(cfg, PipelineSettings())
    assert new_cfg.processor.correlator == "nonuniform"
    assert new_cfg.processor.partition_lines == g.block_lines == settings.strip_lines
    said, rest = words.split("\n")
    assert said.startswith("correlator nonuniform, not the configuration's fft: ")
    assert "--correlator fft keeps fft" in said and rest.startswith("granularity: correlator")
    # what keeps fft: the command line's --correlator / --fft-length, the physical CCD, the
    # time-domain taps (RADARSAT-1's Doppler-domain taps take the walk: tests/test_walk_deskew)
    kept = [
        live_correlator(cfg, given="fft"),
        live_correlator(cfg, fft_length=1024),
        live_correlator(cfg, physical=object()),
        live_correlator(cfg.with_processor(range_migration_taps=8)),  # time domain: a tap each
    ]
    assert all(c.processor.correlator == "fft" and w == "" for c, w in kept)
    assert live_correlator(cfg.with_processor(correlator="partitioned"))[1] == ""
    # the command line's --correlator reaches the request (rtsar run, replay)
    assert request_of(_args(), 1600.0).correlator is None
    assert request_of(_args("--correlator", "fft"), 1600.0).correlator == "fft"
    any_block = StageCosts({b: (100 + 5 * b) * US for b in range(1, 1025)},
                           {b: (100 + 10 * b) * US for b in range(1, 1025)}, 100 * US)  # fmt: skip
    monkeypatch.setattr(live_granularity, "measure_costs", _fake_measure(any_block))
    fft, _, _, words = GranularityRequest(1600.0, correlator="fft").apply(cfg, PipelineSettings())
    assert fft.processor.correlator == "fft" and words.startswith("granularity: correlator ")


def test_a_live_run_of_an_fft_preset_says_and_writes_the_nonuniform_correlator(tmp_path):
    """run_stream of the tiny preset (fft) with a request, measured for real: the switch on a
    banner line of its own before the granularity's, the run's line names the nonuniform
    correlator, and so does the image file (-o) it wrote."""
    from rtsar.sinks.image_file import read_image

    cfg = preset("tiny")
    shots = np.zeros((300, cfg.waveform.samples_per_shot), np.complex64)
    seq = np.arange(300)
    source = ReplaySource(shots, seq, seq / 500.0, 500.0, "max", 16)
    stream, out = io.StringIO(), tmp_path / "img.h5"
    settings = PipelineSettings(lens_backend="numpy")
    endpoint, request = "ipc://" + str(tmp_path / "pub"), GranularityRequest(500.0)
    assert live.run_stream(cfg, source, settings, endpoint, "drop", output=str(out),
                           stream=stream, granularity=request) == 0  # fmt: skip
    lines = stream.getvalue().splitlines()
    at = [k for k, line in enumerate(lines) if line.startswith("rtsar: correlator nonuniform")]
    assert len(at) == 1 and lines[at[0] + 1].startswith("rtsar: granularity: correlator blocks")
    assert any(", nonuniform correlator, " in line for line in lines)
    assert read_image(out)[3]["correlator"] == "nonuniform"
