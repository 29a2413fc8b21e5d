"""The recorder process's code run in this process (rtsar.sinks.raw_writer, raw_file).

``run --record`` runs raw_writer in a subprocess of its own, where no coverage is measured;
here its Writer reads the same messages from a pipe of this process (rtsar.sinks.raw_pipe) and
writes the file, which is then read back with the recording reader (rtsar.sinks.io).  What is
checked is the public behaviour the module docstrings state: one row per pulse in stream order,
the /pulse_flags bits (1 inserted, 2 zeroed, 4 not recorded), the instrument's numbers and
clock (0 / NaN where none), the final attributes, and the answers told to the run (every
message in answered once as done or lost, the saved counts, failed once when the disk refuses
a write, closed last).
"""

from __future__ import annotations

import datetime
import errno
import json
import os
import threading
import time

import h5py
import numpy as np
import pytest

from rtsar.presets import preset
from rtsar.sinks import raw_writer
from rtsar.sinks.io import open_recording
from rtsar.sinks.raw_file import INSERTED, NOT_RECORDED, ZEROED, Shots
from rtsar.sinks.raw_pipe import receive, send
from rtsar.stream.ingest import PulseBlock

CFG = preset("tiny")
START_M = 12.5
UTC = "2026-11-28T10:00:00Z"


def _block(first, n, rng, flagged=(), inserted=None):
    """n pulses from ``first``: shots and an rx1 channel, the instrument's numbers 1000 + pulse
    and clock 0.002 s per pulse (none on inserted pulses, which carry zeros)."""
    s = CFG.waveform.samples_per_shot
    shape = (n, s)
    samples = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
    rx1 = (0.5 * samples[:, ::-1]).copy()
    flags = np.zeros(n, bool)
    flags[list(flagged)] = True
    ins = None
    if inserted is not None:
        ins = np.zeros(n, bool)
        ins[list(inserted)] = True
        samples[ins] = 0
        rx1[ins] = 0
        flags |= ins
    p = np.arange(first, first + n)
    return PulseBlock(first, samples, np.zeros(n), flags, {"rx1": rx1}, 1000 + p, 0.002 * p, ins)


def _settings(path):
    return {
        "path": str(path), "config": CFG.to_dict(), "scene": {"name": "unit"},
        "source": "in-process test", "start_along_track_m": START_M, "flush_every_s": 0.05,
        "claim_mark": None,
    }  # fmt: skip


class Session:
    """A Writer (or raw_writer.main, ``main``) on its own thread, fed through a pipe; its
    answers collected by a listener thread, in order."""

    def __init__(self, main: bool = False):
        to_r, self.to_w = os.pipe()
        from_r, self.from_w = os.pipe()
        self.answers: list = []
        self.status: list = []
        self.listener = threading.Thread(target=self._listen, args=(from_r,), daemon=True)
        self.listener.start()
        if main:
            argv = [str(to_r), str(self.from_w), "-1"]
            self.writer = None
            work = lambda: self.status.append(raw_writer.main(argv))  # noqa: E731
        else:
            self.writer = raw_writer.Writer(to_r, self.from_w, None)
            work = self.writer.run
        self.thread = threading.Thread(target=work, daemon=True)
        self.thread.start()

    def _listen(self, fd: int) -> None:
        with os.fdopen(fd, "rb", buffering=0) as stream:
            while True:
                try:
                    self.answers.append(receive(stream))
                except EOFError:
                    return

    def send(self, message) -> None:
        send(self.to_w, message)

    def wait_done(self, items: int) -> None:
        """Until ``items`` messages have been answered done (a generous deadline: a hang)."""
        deadline = time.monotonic() + 60
        while sum(a[1] for a in self.answers if a[0] == "done") < items:
            assert time.monotonic() < deadline, f"no answer: {self.answers}"
            time.sleep(0.01)

    def close(self) -> list:
        """The pipe closes (after an end message, or as the run's death); every answer."""
        os.close(self.to_w)
        self.thread.join(60)
        assert not self.thread.is_alive(), "the writer did not finish"
        os.close(self.from_w)
        self.listener.join(10)
        if self.writer is not None:
            self.writer.stream.close()
        else:
            assert self.status == [0]
        return self.answers


def _run(messages, main=False):
    session = Session(main)
    for m in messages:
        session.send(m)
    return session.close()


def _done(answers):
    """(items answered done, items answered lost)."""
    done = [a for a in answers if a[0] == "done"]
    return sum(a[1] for a in done if not a[2]), sum(a[1] for a in done if a[2])


@pytest.fixture
def mixed(tmp_path):
    """13 pulses: 4 shots (pulse 1 zeroed by ingest), 3 not recorded, 3 shots (pulse 8 a zero
    pulse ingest inserted), 2 inserted zero pulses, 1 not recorded; then the run's end."""
    rng = np.random.default_rng(5)
    b0 = _block(0, 4, rng, flagged=[1])
    b1 = _block(7, 3, rng, inserted=[1])
    b2 = _block(10, 2, rng, inserted=[0, 1])
    path = tmp_path / "raw.h5"
    messages = [
        ("init", _settings(path)),
        ("pulses", Shots.of(b0, UTC)),
        ("drop", 4, 3),
        ("pulses", Shots.of(b1, UTC)),
        ("pulses", Shots.of(b2, UTC)),
        ("drop", 12, 1),
        ("end", {"pulses_in": 13, "record_written": 999}, True),
    ]
    return path, (b0, b1, b2), _run(messages)


def test_rows_flags_and_instrument_data(mixed):
    path, (b0, b1, b2), _ = mixed
    flags = [0, ZEROED, 0, 0, *[NOT_RECORDED] * 3, 0, INSERTED, 0, INSERTED, INSERTED, NOT_RECORDED]
    with open_recording(path) as rec:
        assert rec.pulses == 13
        assert rec.pulse_index.tolist() == list(range(13))
        assert rec.time_s == pytest.approx(np.arange(13) / CFG.geometry.prf_hz)
        assert rec.start_along_track_m == START_M
        assert rec.pulse_flags.tolist() == flags
        assert rec.collection_start == datetime.datetime(2026, 11, 28, 10, 0, 0)
        shots = rec.shots[:]
        rx1 = rec.channels["rx1"][:]
        np.testing.assert_array_equal(shots[0:4], b0.samples)
        np.testing.assert_array_equal(shots[7:10], b1.samples)
        np.testing.assert_array_equal(rx1[0:4], b0.aux["rx1"])
        np.testing.assert_array_equal(rx1[7:10], b1.aux["rx1"])
        for rows in (slice(4, 7), slice(10, 13)):  # never written: they read as zeros
            assert not shots[rows].any() and not rx1[rows].any()
        assert rec.scene == {"name": "unit"}
    with h5py.File(path, "r") as f:
        along = f["along_track_m"][:]
        assert along == pytest.approx(START_M + np.arange(13) * CFG.geometry.along_track_step_m)
        seq = f["instrument_seq"][:].tolist()
        assert seq == [1000, 1001, 1002, 1003, 0, 0, 0, 1007, 0, 1009, 0, 0, 0]
        t = f["instrument_time_s"][:]
        known = [0, 1, 2, 3, 7, 9]
        assert np.isnan(np.delete(t, known)).all()
        assert t[known] == pytest.approx(0.002 * np.array(known))
        assert f.attrs["source"] == "in-process test"
        assert f.attrs["recorded_live"]


def test_final_attributes_count_the_files_own_rows(mixed):
    """record_written: pulses whose rows are in the file (shots and inserted zeros: 9);
    record_dropped: the 4 marked not recorded, in two runs; the run's own record_* entries
    give way to the file's; a run that dropped pulses is not complete."""
    path, _, _ = mixed
    with h5py.File(path, "r") as f:
        a = dict(f.attrs)
    assert a["record_written"] == 9 and a["record_dropped"] == 4
    assert json.loads(a["record_dropped_runs"]) == [[4, 3], [12, 1]]
    counters = json.loads(a["counters"])
    assert counters == {"pulses_in": 13, "record_written": 9, "record_dropped": 4}
    assert not a["complete"]


def test_answers_to_the_run(mixed):
    """Every one of the 5 items is answered done, none lost; the last saved counts are the
    file's (9 written, 4 dropped); closed comes last."""
    _, _, answers = mixed
    assert _done(answers) == (5, 0)
    saved = [a for a in answers if a[0] == "saved"]
    assert saved and saved[-1] == ("saved", 9, 4)
    for before, after in zip(saved, saved[1:], strict=False):  # counts never taken back
        assert after[1] >= before[1] and after[2] >= before[2]
    assert answers[-1] == ("closed",)
    assert not [a for a in answers if a[0] == "failed"]


def test_a_whole_run_is_complete(tmp_path):
    rng = np.random.default_rng(6)
    path = tmp_path / "whole.h5"
    blocks = [_block(0, 5, rng), _block(5, 3, rng)]
    answers = _run([("init", _settings(path)), *[("pulses", Shots.of(b)) for b in blocks],
                    ("end", {"pulses_in": 8}, True)])  # fmt: skip
    assert _done(answers) == (2, 0) and answers[-1] == ("closed",)
    with open_recording(path) as rec:
        assert rec.pulses == 8 and not rec.pulse_flags.any()
        assert rec.attrs["complete"] and rec.attrs["record_written"] == 8
        assert rec.collection_start is None  # none was handed over
        np.testing.assert_array_equal(rec.shots[:], np.concatenate([b.samples for b in blocks]))


def test_the_runs_death_leaves_a_closed_incomplete_file(tmp_path, monkeypatch):
    """The pipe closes with no end message (the run was killed): what was received is written,
    the file closed and marked incomplete.  Run through main, which leaves the terminal signals
    to the run."""
    ignored = []
    monkeypatch.setattr(raw_writer.signal, "signal", lambda sig, how: ignored.append((sig, how)))
    rng = np.random.default_rng(7)
    path = tmp_path / "cut.h5"
    block = _block(0, 6, rng, flagged=[5])
    answers = _run([("init", _settings(path)), ("pulses", Shots.of(block))], main=True)
    names = {raw_writer.signal.Signals(s).name for s, how in ignored
             if how is raw_writer.signal.SIG_IGN}  # fmt: skip
    assert names == {"SIGINT", "SIGHUP", "SIGTERM"}
    assert _done(answers) == (1, 0) and answers[-1] == ("closed",)
    with open_recording(path) as rec:
        assert rec.pulses == 6
        assert rec.pulse_flags.tolist() == [0, 0, 0, 0, 0, ZEROED]
        assert not rec.attrs["complete"]
        assert json.loads(rec.attrs["counters"]) == {"record_written": 6, "record_dropped": 0}


def test_nothing_recorded_makes_no_file(tmp_path):
    """An end with no pulse before it: no file at all, the name free, closed said."""
    path = tmp_path / "none.h5"
    answers = _run([("init", _settings(path)), ("end", {}, True)])
    assert answers == [("closed",)]
    assert list(tmp_path.iterdir()) == []


def test_a_refused_write_ends_the_recording_not_the_answers(tmp_path, monkeypatch):
    """The disk refuses the second block (ENOSPC from HDF5, through the file's own failure
    handling): failed is told once with the operating system's words, that block and every
    later one are answered lost, the first block's rows stay readable, marked incomplete."""
    rng = np.random.default_rng(8)
    path = tmp_path / "full.h5"
    blocks = [_block(0, 4, rng), _block(4, 4, rng), _block(8, 2, rng)]
    full = threading.Event()
    real = h5py.Dataset.__setitem__

    def refusing(self, key, value):
        if full.is_set():  # (only the writer writes here, while this test runs)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, key, value)

    monkeypatch.setattr(h5py.Dataset, "__setitem__", refusing)
    session = Session()
    session.send(("init", _settings(path)))
    session.send(("pulses", Shots.of(blocks[0])))
    session.wait_done(1)
    full.set()
    session.send(("pulses", Shots.of(blocks[1])))
    session.wait_done(2)
    session.send(("pulses", Shots.of(blocks[2])))
    session.send(("end", {"pulses_in": 10}, True))
    answers = session.close()
    failed = [a for a in answers if a[0] == "failed"]
    assert len(failed) == 1
    assert failed[0][1] == str(path) and failed[0][2] == "No space left on device"
    assert "its 4 shots are saved" in failed[0][3]
    assert _done(answers) == (1, 2) and answers[-1] == ("closed",)
    saved = [a for a in answers if a[0] == "saved"]
    assert saved[-1] == ("saved", 4, 0)
    full.clear()
    with open_recording(path) as rec:
        assert rec.pulses == 4 and not rec.attrs["complete"]
        np.testing.assert_array_equal(rec.shots[:], blocks[0].samples)
