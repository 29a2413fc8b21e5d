"""A paced source that falls behind catches up in large releases (rtsar.sources.pacing), and a
paced replay reads its file in blocks, not once a release (rtsar.sources.replay.ReadAhead).

Before these, a source released one small chunk at a time however late it was: at the demo's
1,600 Hz (chunks of 1 pulse) a simulator or replay that lost the interpreter for a while paid
its per-release cost for every late shot and never caught up (measured: 1,154-1,426 pulses/s
of 1,600, latency 0.4-2.5 s; with --record 890 pulses/s).  And a pacing thread's sleeps end
within TIMER_SLACK_NS of their time, not Linux's default 50 µs.
"""

from __future__ import annotations

import ctypes
import sys
import threading
import time

import numpy as np
import pytest

from rtsar.sources.pacing import (
    CATCH_UP_MOST,
    TIGHT_FROM_S,
    TIMER_SLACK_NS,
    Pacer,
    next_release,
)
from rtsar.sources.replay import READ_AHEAD_PULSES, ReadAhead, ReplaySource


def test_on_time_the_chunk_late_every_shot_due_up_to_the_cap():
    pacer = Pacer(1000.0, t0=100.0)
    assert pacer.behind(0, now=99.0) == 0
    assert pacer.behind(0, now=100.0) == 1  # shot 0 is due at t0
    assert pacer.behind(5, now=100.0095) == 5  # shots 5 … 9 due by 9.5 ms
    assert next_release(_frozen(pacer, 99.0), 0, chunk=2, left=50) == 2
    assert next_release(_frozen(pacer, 100.0095), 5, chunk=2, left=50) == 5
    assert next_release(_frozen(pacer, 100.0095), 5, chunk=2, left=3) == 3  # the end
    assert next_release(_frozen(pacer, 101.0), 0, chunk=2, left=10_000) == CATCH_UP_MOST


def _frozen(pacer: Pacer, now: float) -> Pacer:
    """The pacer with its clock stopped at ``now`` (next_release reads the clock)."""

    class Frozen(Pacer):
        def behind(self, n: int, now_s: float | None = None) -> int:
            return Pacer.behind(self, n, now)

    return Frozen(pacer.rate_hz, pacer.t0)


class CountingShots:
    """A recording's shots that count the reads made of them (a file's cost is per read)."""

    def __init__(self, shots: np.ndarray):
        self.shots, self.reads = shots, 0

    def __len__(self) -> int:
        return len(self.shots)

    def __getitem__(self, key):
        self.reads += 1
        return self.shots[key]


def _replay(total: int, prf_hz: float) -> tuple[ReplaySource, CountingShots]:
    rng = np.random.default_rng(3)
    shots = (rng.standard_normal((total, 8)) + 1j * rng.standard_normal((total, 8))).astype(
        np.complex64
    )
    counting = CountingShots(shots)
    idx = np.arange(total)
    return ReplaySource(counting, idx, idx / prf_hz, prf_hz, "real"), counting


def test_a_late_replay_catches_up_in_large_releases_with_every_shot_in_order():
    prf = 2000.0  # chunks of 2 on time
    source, counting = _replay(400, prf)
    sizes, got = [], []
    for k, batch in enumerate(source):
        sizes.append(len(batch))
        got.append(batch.samples)
        if k == 0:
            time.sleep(0.06)  # the consumer stalls: 120 shots fall due meanwhile
    np.testing.assert_array_equal(np.concatenate(got), counting.shots)
    assert max(sizes) == CATCH_UP_MOST  # it caught up, not at 2 shots a release
    assert len(sizes) < 400 / 2  # fewer releases than on-time chunks alone would make
    assert counting.reads <= 400 / READ_AHEAD_PULSES + 4  # blocks read, not one a release


def test_read_ahead_gives_the_same_pulses_as_slicing_the_file():
    rng = np.random.default_rng(5)
    shots = rng.standard_normal((300, 4)) + 1j * rng.standard_normal((300, 4))
    aux = {"rx1": rng.standard_normal((300, 4)) + 0j}
    ahead = ReadAhead(shots, aux, block=64)
    p = 0
    for n in [1, 1, 3, 70, 2, 64, 64, 1, 94]:
        s, a = ahead.take(p, n)
        assert s.dtype == np.complex64 and a["rx1"].dtype == np.complex64
        np.testing.assert_array_equal(s, shots[p : p + n].astype(np.complex64))
        np.testing.assert_array_equal(a["rx1"], aux["rx1"][p : p + n].astype(np.complex64))
        p += n
    assert p == 300


@pytest.mark.parametrize("chunk", [1, 4])
def test_a_simulated_source_that_falls_behind_catches_up(chunk):
    from rtsar.scene.files import load_scene
    from rtsar.scene.model import DEMO_SCENE
    from rtsar.sources.sim import SimSource

    source = SimSource(load_scene(DEMO_SCENE), pulses=600, chunk=chunk)  # 1,600 Hz
    source.prepare()
    sizes, seq = [], []
    for k, batch in enumerate(source):
        sizes.append(len(batch))
        seq.append(batch.seq)
        if k == 0:
            time.sleep(0.08)  # ~128 pulses at 1,600 Hz fall due
    np.testing.assert_array_equal(np.concatenate(seq), np.arange(600))
    assert max(sizes) > 8 * chunk


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="timer slack is Linux's")
def test_a_pacing_thread_sleeps_tight_and_no_other_thread_does():
    """The thread that waits on a Pacer of a shot every TIGHT_FROM_S or more gets
    TIMER_SLACK_NS of timer slack (Linux's default is 50 µs: every release up to that late);
    a faster pacer's thread keeps the default (its late wake-ups merge releases), and so
    does every other thread."""
    libc = ctypes.CDLL(None)
    get, put = 30, 29  # PR_GET_TIMERSLACK, PR_SET_TIMERSLACK
    mine = libc.prctl(get, 0, 0, 0, 0)  # this thread's (another test's Pacer may have set it)
    before = 50_000  # Linux's default, which a new thread inherits from its creator
    assert libc.prctl(put, ctypes.c_ulong(before), 0, 0, 0) == 0
    seen = {}

    def paced(rate_hz):
        pacer = Pacer(rate_hz)
        pacer.wait(1)
        seen[rate_hz] = libc.prctl(get, 0, 0, 0, 0)

    slow, fast = 0.99 / TIGHT_FROM_S, 1.01 / TIGHT_FROM_S  # a shot each TIGHT_FROM_S: tight
    for rate_hz in (slow, fast):
        thread = threading.Thread(target=paced, args=(rate_hz,))
        thread.start()
        thread.join()
    assert seen == {slow: TIMER_SLACK_NS, fast: before} and TIMER_SLACK_NS < before
    assert libc.prctl(get, 0, 0, 0, 0) == before
    libc.prctl(put, ctypes.c_ulong(mine), 0, 0, 0)
