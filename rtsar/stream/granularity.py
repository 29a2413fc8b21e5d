"""A live run's granularity: the lines of a correlator block and of a strip, the pulses of a
lens call, chosen from the measured cost of each at the run's own rate (issue 38).

A line's latency (rtsar.stream.pipeline) is mostly the wait for the lines released with it:
lines leave the correlator in blocks of B (rtsar.ccd: the head block of the partitioned and
nonuniform correlators) and go out in strips, so a line waits on average (B - 1) / 2 pulse
periods before any work is done on it.  A small block waits less and costs more: each block
pays a fixed cost (a push's kernel calls, a strip's header and message) that a large one
shares among more lines, and work that nears the stream's time makes the blocks queue.  So
the block is the one of least modelled latency at the rate the source delivers (the wait for
the block, its work, and the wait behind the blocks before it: ``modelled_latency_s``), and a
strip is one block (``choose_granularity``).

Where the correlator has a head block, the lens waits for the pulses that complete a block
and takes them in one call (``aligned``): the block's lines cannot leave before its last pulse
anyway, so this costs them no latency, and ingest, the lens call and the queue hop are paid
once a block, not once a pulse (psaltis-jpl at its PRF, blocks of 2, 2-core Zen 3: median
1.5-1.9 ms aligned against 3.2-4.0 ms not, one run each of two rounds).

Where the work measured takes at most FUSE_BELOW of the stream's time, ingest, the lens and
the correlator run on one thread (``stages`` "fused"): a block then needs no hand-over to a
second thread, whose wake-up on a busy machine was the run's slowest part; above it, on two
(the lens computes the next block while the correlator takes this one), as a run near
capacity needs (psaltis-jpl, 2-core Zen 3, alternating 5 s runs, median / p99: at its PRF
1.49-1.64 / 3.95-5.15 ms fused against 1.62-2.54 / 7.00-8.08 split; psaltis-max at 50 % of
its PRF 5.5-6.2 / 12-18 ms against 6.1-8.3 / 23-25; psaltis-max at its PRF, 96-142 %
utilisation, fused dropped 15-16 thousand of 50 thousand shots, split none).

Costs are seconds per call, measured on this machine at the start of the run
(rtsar.app.live_granularity: each part of a block's path in turn, as the pipeline runs them);
the choice is a pure function of them, so a test checks the rule, not the machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..ccd.migration import MOST_CURVATURE_BINS, walk_leaves_bins

STRIP_DEADLINE_S = 1e-3  # a partial strip waits at most this long for its other lines
MOST_STRIP_LINES = 64  # lines that wait (a backlog) go out together, at most this many a strip
FUSE_BELOW = 0.7  # at most this share of the stream's time: lens and correlator on one thread


@dataclass(frozen=True)
class StageCosts:
    """Seconds of work per call.

    ``lens_s``: pulses in one lens call → seconds a call; ``block_s``: lines in one correlator
    block (the candidates) → seconds to push one block (with the line timing); ``strip_s``:
    seconds to cut one strip, record its latency and publish it (any size: the header
    dominates); ``source_s``: seconds of the source's own work a pulse in this process (a
    simulated scene's synthesis; 0 for a link or a recording); ``ingest_s``: pulses in one
    call → seconds of ingest's checks (none given: not counted); ``lens_cpu_below``: the lens
    was timed with its calls of fewer pulses on the CPU's FFT (rtsar.lens.small_calls; 1:
    none), chosen from ``lens_route_s``: pulses a call → (wall, CPU seconds a call on the
    OpenCL lens, the same on SciPy's FFT).
    """

    lens_s: dict[int, float]
    block_s: dict[int, float]
    strip_s: float
    source_s: float = 0.0
    ingest_s: dict[int, float] = field(default_factory=dict)
    lens_cpu_below: int = 1
    lens_route_s: dict[int, tuple[float, float, float, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class Granularity:
    """What a live run releases together, and why (``reason``, said on the banner)."""

    block_lines: int  # the correlator's block: its lines leave together
    strip_lines: int  # a strip is published once it holds this many lines …
    strip_most_lines: int  # … with every line then waiting, up to this many
    strip_deadline_s: float | None  # a partial strip goes out once a line waited this long
    lens_batch: int  # most pulses a lens call takes (when behind)
    lens_call_pulses: int  # pulses a lens call takes while keeping up (the model's)
    lens_align: int  # > 1: the lens waits for the pulses that complete a block (aligned) …
    lens_hold_s: float  # … at most two blocks' time at the rate (a silence: then what came)
    utilisation: float  # modelled share of the stream's time the work measured takes
    latency_s: float  # modelled mean latency of a line (modelled_latency_s)
    rate_hz: float  # the pulse rate it was chosen for
    reason: str
    stages: str = "split"  # "fused" where utilisation <= FUSE_BELOW (module docstring)


def lens_call(rate_hz: float, lens_s: dict[int, float]) -> tuple[int, float]:
    """(pulses a lens call takes while keeping up, the lens's share of the stream's time).

    The lens takes every pulse waiting: while a call of b pulses takes less than the b pulse
    periods in which the next b arrive (``lens_s[b] <= b / rate_hz``), it keeps up at b pulses
    a call; the smallest such b is where it settles, its share ``rate_hz * lens_s[b] / b``.
    When no b keeps up, the b of least time a pulse (a share over 1: it cannot keep up).
    """
    sizes = sorted(lens_s)
    keeping_up = [b for b in sizes if lens_s[b] <= b / rate_hz]
    b = keeping_up[0] if keeping_up else min(sizes, key=lambda s: lens_s[s] / s)
    return b, rate_hz * lens_s[b] / b


def utilisation(
    rate_hz: float, costs: StageCosts, block: int, strip_lines: int, aligned: bool = False
) -> float:
    """Share of the stream's time the work measured takes with blocks of ``block`` lines and
    strips of ``strip_lines``: rate · (ingest and lens a pulse + block / block lines + strip /
    strip lines + the source a pulse).  The lens: ``aligned``, one call of ``block`` pulses a
    block; else lens_call's.  The source counts: a simulated scene's synthesis shares the
    cores and Python's lock with the stages (left out, the demo chose blocks of 2 and ran at
    1,340-1,555 pulses/s of its 1,600)."""
    if aligned:
        calls, lens_share = block, rate_hz * costs.lens_s[block] / block
    else:
        calls, lens_share = lens_call(rate_hz, costs.lens_s)
    ingest_share = rate_hz * costs.ingest_s.get(calls, 0.0) / calls
    per_line_s = costs.block_s[block] / block + costs.strip_s / strip_lines + costs.source_s
    return lens_share + ingest_share + rate_hz * per_line_s


def auto_strip_lines(block: int) -> int:
    """A strip per block (at most MOST_STRIP_LINES lines): lines never wait for a strip to
    fill beyond the wait for their block."""
    return min(block, MOST_STRIP_LINES)


def modelled_latency_s(rate_hz: float, u: float, block: int, strip_lines: int) -> float:
    """A line's mean latency with blocks of ``block`` lines whose work takes the share ``u``
    of the stream's time: the wait for the other lines of its block (or strip, the larger),
    (B - 1) / 2 pulse periods; the block's work, S = u · B / rate; and the wait behind the
    blocks before it, u · S / (2 (1 - u)) (Pollaczek-Khinchine for work of fixed length, the
    M/D/1 queue: the pulses come on time but the threads that share the cores and Python's
    lock do not run on time).  Infinite where u ≥ 1 (the queue grows without bound)."""
    if not u < 1:
        return math.inf
    work_s = u * block / rate_hz
    return (max(block, strip_lines) - 1) / 2 / rate_hz + work_s + u * work_s / (2 * (1 - u))


def choose_granularity(
    rate_hz: float,
    costs: StageCosts,
    lens_batch: int,
    strip_lines: int | None = None,
    fixed_block: str = "",
    aligned: bool = False,
) -> Granularity:
    """The granularity of a run at ``rate_hz`` pulses/s whose work costs ``costs``.

    The rule: of the candidate blocks (the keys of ``costs.block_s``), the B of least
    modelled latency (``modelled_latency_s`` of its utilisation, ``utilisation``, strips of
    auto_strip_lines(B)), the smaller on a tie; where every B's work exceeds the stream's
    time, the largest (a block's fixed cost shared by the most lines: latency grows with the
    rate, larger blocks before any drop).  Strips: one per block, lines that wait (a backlog)
    going out together up to MOST_STRIP_LINES, a partial strip after STRIP_DEADLINE_S;
    ``strip_lines`` given (the command line's): strips of exactly that many, no deadline (as
    before auto).  The lens takes every pulse waiting up to ``lens_batch`` (lens_call: how
    many while keeping up); ``aligned`` (a correlator with a head block, module docstring):
    the lens waits for each block's pulses, one call a block.  ``fixed_block``: why there is
    one candidate only (said as the reason), or "".  Its ``stages``: "fused" where the chosen
    block's utilisation is at most FUSE_BELOW, else "split" (the run's, unless --stages).
    """
    if not rate_hz > 0:
        raise ValueError(f"rate must be > 0 pulses/s, got {rate_hz!r}")
    if not costs.block_s or not costs.lens_s:
        raise ValueError("costs need at least one block and one lens call measured")
    blocks = sorted(costs.block_s)

    def strips(b: int) -> int:
        return strip_lines if strip_lines else auto_strip_lines(b)

    u = {b: utilisation(rate_hz, costs, b, strips(b), aligned) for b in blocks}
    latency = {b: modelled_latency_s(rate_hz, u[b], b, strips(b)) for b in blocks}
    block = min(blocks, key=lambda b: (latency[b], b))
    if fixed_block:
        reason = f"the block is fixed ({fixed_block})"
    elif math.isfinite(latency[block]):
        reason = (
            f"the block ({candidate_words(blocks)} lines) of least modelled latency, "
            f"{latency[block] * 1e3:.2f} ms"
        )
    else:
        block = blocks[-1]
        reason = f"no block of {blocks[0]}-{blocks[-1]} lines keeps up: the largest"
    if u[block] > 1:
        reason += "; over this machine's capacity at this rate: expect drops"
    calls = min(block, lens_batch) if aligned else lens_call(rate_hz, costs.lens_s)[0]
    s = strips(block)
    return Granularity(
        block_lines=block,
        strip_lines=s,
        strip_most_lines=s if strip_lines else max(s, MOST_STRIP_LINES),
        strip_deadline_s=None if strip_lines else STRIP_DEADLINE_S,
        lens_batch=int(lens_batch),
        lens_call_pulses=calls,
        lens_align=block if aligned and block > 1 else 0,
        lens_hold_s=2 * block / rate_hz if aligned and block > 1 else 0.0,
        utilisation=u[block],
        latency_s=latency[block],
        rate_hz=float(rate_hz),
        reason=reason,
        stages="fused" if u[block] <= FUSE_BELOW else "split",
    )


LIVE_CORRELATOR = "nonuniform"  # a live run's, where the configuration names fft (below)


def live_correlator(
    config, given: str | None = None, fft_length: int | None = None, physical=None
) -> tuple[object, str]:
    """(the configuration a live run correlates with, the banner's words for the change, or
    "" where there is none).

    The fft correlator, every preset's and the fastest over a whole recording (`rtsar
    process`), releases its lines in overlap-save blocks of M - N + 1: live runs at the PRF
    of psaltis-jpl chose blocks of 29 lines and a line waited 15.1-19.5 ms (median; p99
    24.6-41.1 ms) where the nonuniform correlator, which computes the same correlation with a
    head block from 1 line, gave 1.6-2.0 ms (5.6-19.1 ms); psaltis-max at 25 % of its PRF,
    blocks of 29 against 4, 15.7-16.3 ms (p99 24.2-31.3) against 2.1-2.2 ms (5.2-5.8)
    (2-core Xeon, 2026-11-29, three alternated rounds of 5 s, 0 dropped: ``python
    tools/ab_latency.py psaltis-jpl --rounds 3 --seconds 5 --without correlator``, and
    ``psaltis-max --rate 0.25``).  So where the command line names no correlator (``given``:
    --correlator) and no transform length (``fft_length``: --fft-length), a live run runs
    LIVE_CORRELATOR in fft's place; not the emulated CCD (``physical``), nor with
    time-domain range-migration taps: fft shares its transforms among them where
    nonuniform runs a correlator a tap (8 taps, each correlator alone: psaltis-jpl 26.4
    against 4.7 thousand pulses/s, a cold review's figures), so a run that keeps up on fft
    could fall behind.  A squinted beam's Doppler-domain read (fft's alone: RADARSAT-1) gives
    way to LIVE_CORRELATOR on the walk's ring (rtsar.ccd.walk_deskew) where the curvature the
    ring leaves out is at most a bin (walk_keeps_focus): RADARSAT-1's lines leave in head
    blocks, not in the overlap-save blocks of hundreds of lines that held them ~80 ms."""
    p = config.processor
    taps = bool(p.range_migration_taps)
    if given or fft_length or physical is not None or p.correlator != "fft":
        return config, ""
    domain = migration_domain_for(config, LIVE_CORRELATOR)
    if taps and domain == "walk":
        words = (
            f"correlator {LIVE_CORRELATOR} with the range walk taken out before it, not the "
            "configuration's fft with the Doppler-domain read: a live run's where the command "
            "line names no correlator (fft's overlap-save blocks hold a line for up to M - N + 1 "
            "pulses; the walk's ring leaves the aperture's curvature out, rtsar.ccd.walk_deskew; "
            "--correlator fft keeps fft)"
        )
        return config.with_processor(
            correlator=LIVE_CORRELATOR, range_migration_domain=domain
        ), words
    if taps:
        return config, ""
    words = (
        f"correlator {LIVE_CORRELATOR}, not the configuration's fft: a live run's where the "
        "command line names none (fft's overlap-save blocks hold a line for up to M - N + 1 "
        f"pulses; {LIVE_CORRELATOR} computes the same correlation and releases lines in head "
        "blocks from 1 line; --correlator fft keeps fft)"
    )
    return config.with_processor(correlator=LIVE_CORRELATOR), words


def walk_keeps_focus(config) -> bool:
    """Whether the walk's ring leaves out at most MOST_CURVATURE_BINS of curvature on
    ``config``'s plan (rtsar.ccd.walk_deskew refuses more): where it would not, a live run keeps
    fft's Doppler-domain read and --correlator nonuniform takes the time domain."""
    return walk_leaves_bins(config) <= MOST_CURVATURE_BINS


def migration_domain_for(config, correlator: str) -> str:
    """The range-migration domain ``correlator`` takes in place of the configuration's where
    that one is another kind's (--correlator): the Doppler-domain read is fft's, the walk's
    ring nonuniform's (what a live run chooses for a squinted beam, live_correlator); another
    kind reads in the time domain (the exact 2-D mask, a correlator a bin offset)."""
    domain = config.processor.range_migration_domain
    if domain == "doppler" and correlator != "fft":
        walk = correlator == LIVE_CORRELATOR and config.geometry.squinted
        return "walk" if walk and walk_keeps_focus(config) else "time"
    if domain == "walk" and correlator != "nonuniform":
        return "doppler" if correlator == "fft" else "time"
    return domain


def migration_words(p) -> str:
    """The banner's words for Processor ``p``'s range-migration taps and where they read."""
    where = {"time": "through the exact 2-D mask", "doppler": "in each block's azimuth spectrum"}
    read = where.get(p.range_migration_domain, "on the walk's ring, curvature left out")
    return f"; range migration {p.range_migration_taps} taps, read {read}"


def candidate_words(blocks: list[int]) -> str:
    """The candidate blocks in words: "1, 2, 4, …" for the doubling series from 1 (the head
    blocks), else each ("309 or 1,333": the fft correlator's M - N + 1)."""
    if blocks[0] == 1 and len(blocks) > 3 and all(b == 1 << k for k, b in enumerate(blocks)):
        return "1, 2, 4, …"
    words = [f"{b:,}" for b in blocks]
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " or " + words[-1]


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:,.0f} µs"


def granularity_words(g: Granularity, costs: StageCosts) -> str:
    """The banner's line: what was chosen, for which rate, and why (the costs it read)."""

    def lines(n: int) -> str:
        return f"{n} line{'s' if n != 1 else ''}"

    strips = f"strips of {lines(g.strip_lines)}"
    if g.strip_most_lines > g.strip_lines:
        strips += f" (lines that wait go out together, up to {g.strip_most_lines})"
    if g.strip_deadline_s is not None:
        strips += f", a partial strip after {g.strip_deadline_s * 1e3:g} ms"
    calls = f"{g.lens_call_pulses} pulse{'s' if g.lens_call_pulses != 1 else ''}"
    if g.lens_align:
        whole = g.lens_call_pulses == g.block_lines
        calls += (
            ", each block's pulses together"
            if whole
            else ", a block's last call ending on its last pulse"
        )
    key = g.block_lines if g.lens_align else g.lens_call_pulses  # aligned: costs a block
    per = "a call" if key == g.lens_call_pulses else "a block"
    ingest = costs.ingest_s.get(key)
    return (
        f"granularity: correlator blocks of {lines(g.block_lines)}, {strips}, lens calls of "
        f"{calls} (up to {g.lens_batch} when behind), for {g.rate_hz:,.0f} pulses/s: "
        f"{g.reason}; the work measured takes {g.utilisation:.0%} of the time ("
        + (f"ingest {_us(ingest)} {per}, " if ingest is not None else "")
        + f"lens {_us(costs.lens_s[key])} {per}, correlator "
        f"{_us(costs.block_s[g.block_lines])} a block, strip {_us(costs.strip_s)}"
        + (f", the source {_us(costs.source_s)} a pulse)" if costs.source_s else ")")
    )
