"""Ingest checks: gaps, jumps, duplicates, late shots, NaN/Inf and wrong lengths."""

import numpy as np

from rtsar.sources.base import ShotBatch, join_batches
from rtsar.stream.ingest import Ingest

S = 8


def batch(seq, samples=None):
    seq = np.asarray(seq, np.int64)
    if samples is None:
        samples = (seq[:, None] + 1 + np.zeros((1, S))).astype(np.complex64)  # value = seq + 1
    t = seq * 1e-3
    return ShotBatch(seq, t, t + 10.0, samples)


def stream(ing, batches):
    """Feed batches; return (samples, flagged, first_pulse of each block) of the whole output."""
    blocks = [b for x in batches for b in ing(x)] + ing.flush()
    for a, b in zip(blocks, blocks[1:], strict=False):
        assert b.first_pulse == a.first_pulse + len(a)  # consecutive, whatever came in
    return (
        np.concatenate([b.samples for b in blocks]),
        np.concatenate([b.flagged for b in blocks]),
    )


def test_in_order_stream_passes_unchanged():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    x, f = stream(ing, [batch(range(100, 110)), batch(range(110, 113))])
    np.testing.assert_array_equal(x[:, 0].real, np.arange(101, 114))
    assert not f.any()
    assert ing.counters["pulses_accepted"] == 13 and ing.counters["gap_pulses"] == 0


def test_a_batch_whose_numbers_span_it_but_do_not_rise_by_one_is_not_taken_as_it_came():
    """The fast path takes a batch as it came only where its numbers rise by one each: numbers
    spanning the batch out of order (a swap: 3 2 within 1 … 4) go through the checks, which
    keep each shot in its own slot and drop the late one."""
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    x, f = stream(ing, [batch([0]), batch([1, 3, 2, 4]), batch([5, 6])])
    np.testing.assert_array_equal(x[:, 0].real, [1, 2, 0, 4, 5, 6, 7])  # 2 came after 3: late
    assert ing.counters["late_pulses"] == 1 and ing.counters["gap_pulses"] == 1
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    x, f = stream(ing, [batch([0, 1]), batch([2, 3, 4]), batch([5, 6])])  # rising by one
    np.testing.assert_array_equal(x[:, 0].real, np.arange(1, 8))
    assert not f.any() and ing.counters["pulses_accepted"] == 7


def test_gap_is_zero_filled_and_flagged():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    x, f = stream(ing, [batch([0, 1, 2, 5, 6]), batch([9])])
    np.testing.assert_array_equal(x[:, 0].real, [1, 2, 3, 0, 0, 6, 7, 0, 0, 10])
    np.testing.assert_array_equal(f, [0, 0, 0, 1, 1, 0, 0, 1, 1, 0])
    assert ing.counters["gaps"] == 2 and ing.counters["gap_pulses"] == 4


def test_duplicates_and_late_shots_are_dropped_and_counted():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    x, f = stream(ing, [batch([0, 1, 1, 2, 4, 3, 5, 2])])
    # 1 repeated (duplicate), 3 arrives after its slot was filled (late), 2 again (duplicate).
    np.testing.assert_array_equal(x[:, 0].real, [1, 2, 3, 0, 5, 6])
    c = ing.counters
    assert c["duplicates"] == 2 and c["late_pulses"] == 1 and c["gap_pulses"] == 1
    assert c["pulses_received"] == 8 and c["pulses_accepted"] == 5


def test_large_jump_is_a_discontinuity_that_clears_the_ccd():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=10)
    x, f = stream(ing, [batch([0, 1]), batch([1000, 1001]), batch([5])])
    # Each jump inserts N = 4 zero pulses instead of a million.
    assert len(x) == 2 + 4 + 2 + 4 + 1
    assert ing.counters["discontinuities"] == 2
    np.testing.assert_array_equal(f, [0, 0, 1, 1, 1, 1, 0, 0, 1, 1, 1, 1, 0])


def test_nonfinite_and_wrong_length_pulses_are_zeroed_and_flagged():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    good = batch(range(4))
    good.samples[1, 3] = np.nan
    good.samples[2, 0] = np.inf
    x, f = stream(ing, [good, batch(range(4, 6), np.ones((2, S + 1), np.complex64))])
    assert np.isfinite(x).all()
    np.testing.assert_array_equal(f, [0, 1, 1, 0, 1, 1])
    assert not x[[1, 2, 4, 5]].any()
    assert ing.counters["nonfinite_pulses"] == 2 and ing.counters["wrong_length_pulses"] == 2


def test_random_link_faults_keep_every_surviving_shot_in_its_slot(rng):
    # Whatever is lost, repeated or reordered, a shot that is accepted sits at index seq - seq0.
    seq = np.arange(2000)
    keep = seq[rng.random(len(seq)) > 0.05]
    dup = rng.choice(keep, 40)
    arrived = np.concatenate([keep, dup])
    order = np.argsort(np.concatenate([keep, dup + rng.integers(1, 5, len(dup))]), kind="stable")
    arrived = arrived[order]
    ing = Ingest(S, aperture_pulses=16, max_gap_pulses=64)
    chunks = np.split(arrived, np.sort(rng.choice(len(arrived), 50, replace=False)))
    x, f = stream(ing, [batch(c) for c in chunks if len(c)])
    val = x[:, 0].real.astype(int)
    ok = val > 0
    np.testing.assert_array_equal(val[ok] - 1, np.flatnonzero(ok))  # value = slot + 1
    assert (f == ~ok).all()
    c = ing.counters
    assert c["pulses_accepted"] + c["duplicates"] + c["late_pulses"] == len(arrived)
    assert c["pulses_accepted"] + c["gap_pulses"] == len(x)


def with_aux(seq, bad_aux_row=None):
    b = batch(seq)
    ref = -b.samples  # the auxiliary channel: minus the main one, so pairing errors show
    if bad_aux_row is not None:
        ref = ref.copy()
        ref[bad_aux_row, 3] = np.nan
    return ShotBatch(b.seq, b.timestamp_s, b.arrival_s, b.samples, {"ref": ref})


def test_aux_channel_travels_with_its_pulse_through_gaps_and_duplicates():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    blocks = [blk for x in (with_aux([0, 1, 4, 4, 5]), with_aux([6, 3])) for blk in ing(x)]
    main = np.concatenate([b.samples for b in blocks])
    ref = np.concatenate([b.aux["ref"] for b in blocks])
    np.testing.assert_array_equal(ref, -main)  # same pulse in both channels, zeros in gaps
    np.testing.assert_array_equal(main[:, 0].real, [1, 2, 0, 0, 5, 6, 7])
    assert ing.counters["duplicates"] == 1 and ing.counters["late_pulses"] == 1


def test_bad_aux_channel_zeroes_the_whole_pulse():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    (blk,) = ing(with_aux([0, 1, 2], bad_aux_row=1))
    assert ing.counters["nonfinite_pulses"] == 1
    np.testing.assert_array_equal(blk.flagged, [False, True, False])
    assert not blk.samples[1].any() and not blk.aux["ref"][1].any()
    assert np.isfinite(blk.aux["ref"]).all()
    # A later batch without the channel cannot be paired: zeroed and counted, never a crash.
    (blk2,) = ing(batch([3, 4]))
    assert ing.counters["wrong_length_pulses"] == 2 and blk2.flagged.all()


def accounted(ing):
    c = ing.counters
    held = 0 if ing._candidate is None else 1
    lost = c["duplicates"] + c["late_pulses"] + c["stray_pulses"]
    return c["pulses_received"] == c["pulses_accepted"] + lost + held


def test_one_frame_far_ahead_is_a_stray_not_an_outage():
    # One shot numbered a minute ahead in a run: before, ingest filled the whole jump with zero
    # pulses and then dropped the run's next shots as duplicates.
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=4)
    x, f = stream(ing, [batch([0, 1, 2]), batch([600_000]), batch(range(3, 10))])
    np.testing.assert_array_equal(x[:, 0].real, np.arange(1, 11))  # every intact shot, in place
    assert not f.any()
    c = ing.counters
    assert c["stray_pulses"] == 1 and c["gap_pulses"] == 0 and c["discontinuities"] == 0
    assert accounted(ing)


def test_a_counter_reset_is_a_restart_at_once_and_loses_nothing():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=16)
    x, f = stream(ing, [batch(range(1000, 1010)), batch(range(0, 5))])
    assert ing.counters["discontinuities"] == 1 and ing.counters["duplicates"] == 0
    assert len(x) == 10 + 4 + 5  # N = 4 zero pulses clear the CCD between the two runs
    np.testing.assert_array_equal(x[-5:, 0].real, np.arange(1, 6))
    np.testing.assert_array_equal(f, [0] * 10 + [1] * 4 + [0] * 5)
    assert accounted(ing)


def test_zero_fill_is_bounded_by_the_gap_bound():
    # A run resuming 50 pulses later with a bound of 8: a restart (N zeros), not 50 zeros.
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=8)
    x, _ = stream(ing, [batch(range(0, 10)), batch(range(60, 70))])
    assert ing.counters["gap_pulses"] == 4 and ing.counters["discontinuities"] == 1
    assert len(x) == 10 + 4 + 10 and accounted(ing)


def test_a_stray_old_frame_does_not_restart_the_count():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=4, memory_pulses=16)
    x, f = stream(ing, [batch(range(100, 140)), batch([3]), batch(range(140, 150))])
    np.testing.assert_array_equal(x[:, 0].real, np.arange(101, 151))
    assert ing.counters["stray_pulses"] == 1 and ing.counters["discontinuities"] == 0
    assert accounted(ing)


def test_a_held_candidate_at_the_end_of_a_stream_is_kept():
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=4)
    blocks = ing(batch([0, 1, 500]))
    assert ing._candidate is not None and accounted(ing)
    blocks += ing.flush()
    assert sum(len(b) for b in blocks) == 2 + 4 + 1 and ing.counters["discontinuities"] == 1
    assert accounted(ing)


def timed(seq, t0_s):
    """A batch whose instrument clock goes on from ``t0_s`` whatever the numbers say."""
    seq = np.asarray(seq, np.int64)
    t = t0_s + np.arange(len(seq)) * 1e-3
    samples = (seq[:, None] + 1 + np.zeros((1, S))).astype(np.complex64)
    return ShotBatch(seq, t, t + 10.0, samples)


def test_a_counter_reset_within_the_remembered_shots_is_a_restart_not_duplicates():
    """Issue 29: a counter reset to a number within the last 4N shots dropped the new shots as
    duplicates, without a restart (a step back of 100 dropped 100 shots).  Their clock says they
    are new shots: the first is a restart candidate, confirmed by the next, and every shot of
    the new run is kept."""
    n = 16
    ing = Ingest(S, aperture_pulses=n, max_gap_pulses=n)  # remembers 4N = 64 shots
    before = timed(range(0, 200), 0.0)
    after = timed(range(100, 160), 0.2)  # a step back of 100, the clock going on
    x, f = stream(ing, [before, after])
    c = ing.counters
    assert c["discontinuities"] == 1 and c["duplicates"] == 0 and c["stray_pulses"] == 0
    assert len(x) == 200 + n + 60  # every shot, N zero pulses between the two runs
    np.testing.assert_array_equal(x[-60:, 0].real, np.arange(101, 161))
    assert accounted(ing)
    # A step back of a single shot (a reset to the last number) too.
    ing = Ingest(S, aperture_pulses=n, max_gap_pulses=n)
    x, _ = stream(ing, [timed(range(0, 50), 0.0), timed(range(49, 60), 0.05)])
    assert ing.counters["discontinuities"] == 1 and ing.counters["duplicates"] == 0
    assert len(x) == 50 + n + 11 and accounted(ing)


def test_repeated_shots_are_still_duplicates_and_a_clockless_stream_keeps_the_old_rule():
    """A repeat carries its original's time (not newer): dropped as before, even a burst of
    repeats that goes on counting; without a clock (NaN times) a step back reads as repeats."""
    n = 16
    ing = Ingest(S, aperture_pulses=n, max_gap_pulses=n)
    first = batch(range(0, 100))
    repeat = batch(range(90, 100))  # the last ten again, their own times
    x, _ = stream(ing, [first, repeat, batch(range(100, 110))])
    c = ing.counters
    assert c["duplicates"] == 10 and c["discontinuities"] == 0 and len(x) == 110
    ing = Ingest(S, aperture_pulses=n, max_gap_pulses=n)
    clockless = [
        ShotBatch(b.seq, np.full(len(b), np.nan), b.arrival_s, b.samples)
        for b in (timed(range(0, 100), 0.0), timed(range(90, 100), 0.1))
    ]
    stream(ing, clockless)
    assert ing.counters["duplicates"] == 10 and ing.counters["discontinuities"] == 0


def test_shots_the_source_marks_are_zeroed_flagged_and_counted():
    """A recording's zero pulses (ShotBatch.flagged: pulse_flags of `run --record`) are flagged
    like ingest's own, so a replay flags the lines the live run flagged (it flagged none)."""
    ing = Ingest(S, aperture_pulses=4, max_gap_pulses=4)
    x = batch(np.arange(6))
    marked = np.array([0, 1, 0, 0, 1, 0], bool)
    given = x.samples.copy()
    x = ShotBatch(x.seq, x.timestamp_s, x.arrival_s, x.samples, flagged=marked)
    samples, flagged = stream(ing, [x])
    np.testing.assert_array_equal(flagged, marked)
    assert not samples[marked].any()
    np.testing.assert_array_equal(samples[~marked], given[~marked])
    np.testing.assert_array_equal(x.samples, given)  # the source's array is not written
    assert ing.counters["marked_pulses"] == 2 and ing.counters["nonfinite_pulses"] == 0


def test_a_recordings_flagged_lines_at_once_equal_the_streamed_ones():
    """rtsar process flags lines from the whole pulse_flags (RecordedFlags); the live run
    flagged them pulse block by pulse block (LineTiming): the same lines, in any blocks."""
    from rtsar.stream.ingest import PulseBlock
    from rtsar.stream.timing import LineTiming, RecordedFlags

    rng = np.random.default_rng(5)
    n, pulses = 16, 400
    marked = rng.random(pulses) < 0.01
    marked[:2] = marked[-3:] = True  # at both ends too
    timing = LineTiming(n, 4096)
    streamed = []
    for first in range(0, pulses, 7):
        m = marked[first : first + 7]
        k = len(m)
        timing.record(PulseBlock(first, np.zeros((k, 1)), np.zeros(k), m, {}))
        if first + k >= n:  # lines whose aperture has fully arrived
            lo, hi = max(first + k - n - 6, 0), first + k - n + 1
            lo = max(lo, len(streamed))
            streamed += list(timing.lines(lo, np.zeros((hi - lo, 1))).flagged)
    at_once = RecordedFlags(marked, n, pulses)
    for first in range(0, len(streamed), 50):  # other blocks than the streamed ones
        at_once.add(first, min(50, len(streamed) - first))
    want = [j for j in range(len(streamed)) if streamed[j]]
    got = [j for a, c in at_once.runs for j in range(a, a + c)]
    assert got == want and at_once.lines == len(want) > 0
    # marked as the shots are read (process's zeroed NaN/Inf shots), each before its lines
    as_read, as_read_done = RecordedFlags(None, n, pulses), 0
    for first in range(0, pulses, 30):
        as_read.mark(first, marked[first : first + 30])
        lines_done = min(max(first + 30 - n + 1, 0), len(streamed))
        if lines_done > as_read_done:
            as_read.add(as_read_done, lines_done - as_read_done)
            as_read_done = lines_done
    assert as_read.runs == at_once.runs and as_read.lines == at_once.lines
    naive = [j for j in range(pulses - n + 1) if marked[j : j + n].any()]
    assert want == naive


def test_batches_taken_together_are_checked_as_one_with_the_same_verdicts(rng):
    """join_batches (the pipeline's ingest of what it takes at once): the same pulses (every
    field), flags and counters as the batches one by one, through a gap and its late shots,
    repeats, a stray, a counter reset, NaN and marked shots, NaN times and a clock that steps
    back (the newest time once read the last shot of each batch: a batch ending on a NaN time
    or on a step back made a repeat a reset, or a reset a repeat); a batch of other channels
    stays alone."""
    seq = np.concatenate(
        [
            np.arange(0, 200),  # 0-199
            np.arange(205, 300),  # 200-294: a gap of 5 before them
            [201, 203],  # 295-296: late (their slots were zero-filled)
            np.arange(290, 320),  # 297-326: repeats of 290-299, then on
            [9000],  # 327: a stray
            np.arange(320, 400),  # 328-407
            np.arange(0, 150),  # 408-557: the counter reset (the clock goes on)
            [140, 141, 142],  # 558-560: repeats of the new run
        ]
    )
    t = np.arange(len(seq)) * 1e-3
    t[295:297] = t[199]  # the late shots: taken before the newest
    t[297:307] = t[285:295]  # the repeats: the times they first had
    t[[399, 431]] = np.nan  # no time for these shots
    t[440:445] -= 0.2  # a step back of the clock
    t[558:] = t[548:551]  # the last repeats: the times they first had
    samples = (np.arange(len(seq))[:, None] + 1 + np.zeros((1, S))).astype(np.complex64)
    samples[[7, 333], 2] = np.nan
    marked = np.zeros(len(seq), bool)
    marked[[50, 51, 420]] = True
    whole = ShotBatch(seq, t, t + 10.0, samples, {"ref": -samples}, marked)
    cuts = np.sort(rng.choice(np.arange(1, len(seq)), 150, replace=False))
    cuts = np.union1d(cuts, [400, 432, 445])  # batches that end on a NaN time, a step back
    parts, start = [], 0
    for end in [*cuts, len(seq)]:
        one = whole.split(end - start)
        parts.append(one[0])
        whole, start = one[1], end
    for p in parts[::3]:
        p.flagged = None  # unmarked batches among marked ones

    def fields(ing, batches):
        blocks = [b for x in batches for b in ing(x)] + ing.flush()
        names = ("samples", "arrival_s", "flagged", "seq", "time_s", "inserted")
        got = {k: np.concatenate([getattr(b, k) for b in blocks]) for k in names}
        got["ref"] = np.concatenate([b.aux["ref"] for b in blocks])
        got["first_pulse"] = [b.first_pulse for b in blocks][:1]
        return got

    one_by_one, joined = Ingest(S, 16, 64), Ingest(S, 16, 64)
    a = fields(one_by_one, parts)
    taken = [join_batches(parts[i : i + 7]) for i in range(0, len(parts), 7)]
    assert all(len(x) == 1 for x in taken)  # the same channels: one batch a take
    b = fields(joined, [x for group in taken for x in group])
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    assert one_by_one.counters == joined.counters
    c = joined.counters
    assert c["late_pulses"] == 2 and c["duplicates"] and c["stray_pulses"] == 1
    assert c["discontinuities"] == 1 and c["nonfinite_pulses"] and c["marked_pulses"]

    other = batch([1000, 1001])  # no "ref" channel: not joined with its neighbours
    assert [len(x) for x in join_batches([parts[0], other, parts[1], parts[2]])] == [
        len(parts[0]),
        2,
        len(parts[1]) + len(parts[2]),
    ]


def test_the_newest_time_does_not_depend_on_where_a_batch_ends():
    """A batch ending on a shot without a time, or on a clock that stepped back: the shot that
    follows is judged against the newest time of every shot accepted, one batch or two."""
    cases = [  # (numbers, times) of three batches, the last a repeat of shot 1
        ([[0, 1], [2, 3], [1]], [[0.0, 0.002], [0.003, np.nan], [0.0025]]),
        ([[0, 1], [2], [1]], [[0.0, 0.005], [0.002], [0.004]]),
    ]
    for numbers, times in cases:
        parts = [
            ShotBatch(np.array(n), np.array(t), np.array(t) + 10.0, np.ones((len(n), S), "c8"))
            for n, t in zip(numbers, times, strict=True)
        ]
        one_by_one, joined = Ingest(S, 4, 16), Ingest(S, 4, 16)
        a = stream(one_by_one, parts)
        b = stream(joined, [*join_batches(parts[:2]), parts[2]])
        assert one_by_one.counters == joined.counters, (numbers, times)
        assert joined.counters["duplicates"] == 1  # not newer than shot 2: a repeat
        np.testing.assert_array_equal(a[0], b[0])
