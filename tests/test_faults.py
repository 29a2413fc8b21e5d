"""Bad input never reaches a traceback or a silent success: malformed recordings, hostile strip
headers, impossible configurations each get a one-line error naming what is wrong (exit status
2), or are counted and reported."""

import json

import h5py
import numpy as np
import pytest

from rtsar.app.cli import main
from rtsar.presets import preset

CFG = preset("tiny")
S = CFG.waveform.samples_per_shot


def recording(path, mutate):
    with h5py.File(path, "w") as f:
        f.attrs["format"] = "rtsar-recording"
        f.attrs["format_version"] = 1
        f.attrs["config"] = json.dumps(CFG.to_dict())
        f.attrs["scene"] = "{}"
        n = 160
        f["shots"] = np.zeros((n, S), np.complex64)
        f["pulse_index"] = np.arange(n)
        f["time_s"] = np.arange(n) / CFG.geometry.prf_hz
        f["along_track_m"] = np.arange(n) * CFG.geometry.along_track_step_m
        mutate(f)
    return path


def _replace(f, name, data):
    del f[name]
    f[name] = data


BAD_RECORDINGS = {
    "config missing": (lambda f: f.attrs.__delitem__("config"), "'config' is missing"),
    "config not JSON": (lambda f: f.attrs.__setitem__("config", "{nope"), "not JSON"),
    "config a list": (lambda f: f.attrs.__setitem__("config", "[1, 2]"), "not a JSON object"),
    "unknown config key": (
        lambda f: f.attrs.__setitem__(
            "config",
            json.dumps({**CFG.to_dict(), "processor": {**CFG.to_dict()["processor"], "x": 1}}),
        ),
        "unknown key",
    ),
    "along_track_m missing": (lambda f: f.__delitem__("along_track_m"), "'along_track_m'"),
    "time_s missing": (lambda f: f.__delitem__("time_s"), "'time_s' is missing"),
    "shots of strings": (
        lambda f: _replace(f, "shots", np.full((160, S), b"ab", "S2")),
        "must be 2-D complex",
    ),
    "shots of the wrong length": (
        lambda f: _replace(f, "shots", np.ones((160, S + 3), np.complex64)),
        f"hold {S + 3} samples",
    ),
    "descending pulse_index": (
        lambda f: _replace(f, "pulse_index", np.arange(160)[::-1]),
        "must increase",
    ),
    "short time_s": (lambda f: _replace(f, "time_s", np.arange(10.0)), "10 entries"),
    # From a cold review: process read this as gapless, replay zero-filled 5 shots.
    "pulse_index skips, the platform does not": (
        lambda f: _replace(f, "pulse_index", np.arange(160) + 5 * (np.arange(160) >= 100)),
        "pulse_index jumps by 6 after shot 99",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_RECORDINGS))
@pytest.mark.parametrize("command", ["process", "replay"])
def test_a_malformed_recording_is_a_one_line_error(tmp_path, capsys, case, command):
    mutate, expected = BAD_RECORDINGS[case]
    rec = recording(tmp_path / "bad.h5", mutate)
    out = tmp_path / "out.h5"
    args = [command, str(rec), "-o", str(out), "--lens", "numpy"]
    if command == "replay":
        args += ["--rate", "max", "--endpoint", "tcp://127.0.0.1:0"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(rec) in err[0] and expected in err[0]
    assert not out.exists()


@pytest.mark.parametrize(
    "changes, expected",
    [
        ({"micro_batch": 10**9}, "micro_batch"),
        ({"fft_length": 2**40}, "fft_length"),
        ({"aperture_pulses": 10**7}, "aperture_pulses"),
        ({"range_bins": 10**7}, "range_bins"),
    ],
)
def test_impossible_processor_sizes_are_refused(changes, expected):
    with pytest.raises(ValueError, match=expected):
        CFG.with_processor(**changes)


def test_a_huge_shot_or_scene_is_refused(tmp_path, capsys):
    scene = tmp_path / "big.toml"
    scene.write_text(
        'preset = "tiny"\n[waveform]\nkind = "pulsed"\nbandwidth_hz = 4e7\n'
        "pulse_duration_s = 3.2e-6\nsample_rate_hz = 1e15\nreceive_window_s = 1.2e-5\n"
        "[[targets]]\nalong_track_m = 0.0\nslant_range_m = 20000.0\n"
    )
    assert main(["simulate", str(scene), "-o", str(tmp_path / "r.h5")]) == 2
    assert "samples per shot" in capsys.readouterr().err
    many = tmp_path / "many.toml"
    many.write_text(
        'preset = "tiny"\npulses = 2000000000\n'
        "[[targets]]\nalong_track_m = 0.0\nslant_range_m = 20000.0\n"
    )
    assert main(["simulate", str(many), "-o", str(tmp_path / "r.h5")]) == 2
    assert "pulses" in capsys.readouterr().err


def test_a_configuration_larger_than_the_machine_is_refused_before_allocating():
    from rtsar.stream.memory import MEMORY_FRACTION, available_bytes, check_memory

    cfg = preset("psaltis-max").with_processor(aperture_pulses=60000, range_bins=60000)
    need = MEMORY_FRACTION * (available_bytes() or 1e9)
    with pytest.raises(ValueError, match="GiB are available"):
        check_memory(cfg, queue_pulses=int(need))


def test_a_block_that_may_change_counts_its_history_and_second_correlator(monkeypatch):
    """A live run whose correlator's block may grow or shrink (rtsar.stream.growth) holds the
    last N lines of the stream and, at a swap, two correlators: the estimate counts both
    (before, neither), and a pipeline checks it with them."""
    from rtsar.sources.replay import ReplaySource
    from rtsar.stream import memory
    from rtsar.stream.pipeline import Pipeline, PipelineSettings

    cfg = preset("psaltis-max").with_processor(correlator="nonuniform")
    p, item = cfg.processor, 8  # complex64
    fixed = memory.estimate_bytes(cfg, 64)
    assert memory.estimate_bytes(cfg, 64, growing=True) - fixed == (
        (2 * p.aperture_pulses + 2 * 8 * p.aperture_pulses) * p.range_bins * item
    )  # the history, a growth's and a shrink's correlators (nonuniform: 8 N lines each)
    seen = []
    monkeypatch.setattr(memory, "available_bytes", lambda: 1e12)
    check = memory.check_memory
    monkeypatch.setattr(
        "rtsar.stream.pipeline.check_memory", lambda *a: seen.append(a) or check(*a)
    )
    settings = PipelineSettings(
        lens_backend="numpy", grow_blocks=(16, 32), grow_rate_hz=1e4, queue_pulses=64
    )
    shots = np.zeros((1, cfg.waveform.samples_per_shot), np.complex64)
    source = ReplaySource(shots, np.arange(1), np.zeros(1), 1e4, "max", 1)
    pipe = Pipeline(cfg, source, [], settings)
    pipe.engine.correlator.close()
    assert seen == [(cfg.with_processor(partition_lines=32), 64, 0, True)]  # the largest


def _subscribe_to_a_bare_publisher(tmp_path):
    """A hand-driven XPUB and `rtsar subscribe -o` reading it in a thread, subscribed:
    (publisher, output path, thread, {"rc": exit status} once it ends)."""
    import threading
    import time

    import zmq

    pub = zmq.Context.instance().socket(zmq.XPUB)
    pub.bind("tcp://127.0.0.1:*")
    endpoint = pub.getsockopt_string(zmq.LAST_ENDPOINT)
    out = tmp_path / "sub.h5"
    result = {}
    t = threading.Thread(
        target=lambda: result.setdefault(
            "rc", main(["subscribe", endpoint, "-o", str(out), "--timeout", "15"])
        ),
        daemon=True,
    )
    t.start()
    assert pub.poll(10_000)  # the subscription
    pub.recv()
    time.sleep(0.2)
    return pub, out, t, result


def test_a_hostile_publisher_is_counted_not_obeyed(tmp_path, capsys):
    """Strips with a missing seq, a changing range axis, malformed flagged_lines, string counters,
    a 1e9-bin header with no lines, a first_line 10^8 ahead: `rtsar subscribe` counts them,
    never crashes, never allocates for them, and keeps the honest strips."""

    from rtsar.sinks.image_file import read_image

    pub, out, t, result = _subscribe_to_a_bare_publisher(tmp_path)
    bins = 8
    good = {
        "format": "rtsar-strip",
        "version": 1,
        "stream_id": "s",
        "first_line": 0,
        "line_count": 2,
        "range_bins": bins,
        "dtype": "complex64",
        "byte_order": "little",
        "azimuth_first_m": 0.0,
        "azimuth_step_m": 1.0,
        "range_first_m": 100.0,
        "range_step_m": 3.0,
        "flagged_lines": [],
        "counters": {"lines_out": 2},
        "config": CFG.to_dict(),
    }

    def send(seq_no, first, lines=2, payload=None, **bad):
        h = {**good, "seq": seq_no, "first_line": first, "line_count": lines, **bad}
        h = {k: v for k, v in h.items() if v is not None}
        data = np.ones((lines, bins), np.complex64).tobytes() if payload is None else payload
        pub.send_multipart([b"strip", json.dumps(h).encode(), data])

    send(0, 0)
    send(None, 2)  # no seq
    send(1, 2, range_bins=16, payload=np.ones((2, 16), np.complex64).tobytes())  # other axis
    send(2, 2, flagged_lines=[["x", 1]])
    send(3, 2, counters="lots")
    send(4, 2, lines=0, range_bins=10**9, payload=b"")  # would allocate 8 GB of range axis
    send(5, 10**8)  # a jump far ahead: listed, not filled with 6 GB of zero lines
    send(6, 10**8 + 2)
    pub.send_multipart([b"end", json.dumps({"stream_id": "s", "counters": "many"}).encode()])
    t.join(20)
    assert not t.is_alive() and result["rc"] == 0
    image, az, rg, attrs = read_image(out)
    assert image.shape == (6, bins)  # the three honest strips, nothing else
    assert json.loads(attrs["line_jumps"]) == [[2, 10**8 - 2]]
    assert attrs["inconsistent_strips"] == 1 and attrs["missing_lines"] == 0
    np.testing.assert_array_equal(az[-2:], [10**8 + 2, 10**8 + 3])  # true positions kept
    err = capsys.readouterr().err
    assert "bad messages 4" in err and "line-number jumps not filled 1" in err
    assert out.stat().st_size < 5_000_000
    pub.close(0)


def test_one_message_cannot_end_or_poison_a_recording(tmp_path, capsys):
    """A seq of 10**30, a strip of another stream, a JSON header nested 200 000 deep and one
    strip 10**15 lines ahead: each counted, none ends `rtsar subscribe`, none crashes it, and
    every honest strip after them is written."""

    from rtsar.sinks.image_file import read_image

    pub, out, t, result = _subscribe_to_a_bare_publisher(tmp_path)
    bins = 8
    head = {
        "format": "rtsar-strip",
        "version": 1,
        "stream_id": "s",
        "line_count": 2,
        "range_bins": bins,
        "dtype": "complex64",
        "byte_order": "little",
        "azimuth_first_m": 0.0,
        "azimuth_step_m": 1.0,
        "range_first_m": 100.0,
        "range_step_m": 3.0,
        "config": CFG.to_dict(),
    }
    data = np.ones((2, bins), np.complex64).tobytes()

    def send(seq_no, first, **other):
        h = {**head, "seq": seq_no, "first_line": first, **other}
        pub.send_multipart([b"strip", json.dumps(h).encode(), data])

    send(0, 0)
    send(10**30, 2)  # not an integer any JSON reader keeps: a bad message
    send(1, 2, stream_id="other")  # another publisher's strip: counted, not written
    pub.send_multipart([b"strip", b"[" * 200_000, data])  # deeper than the JSON parser goes
    send(2, 10**15)  # one strip far ahead, not confirmed by the next: dropped
    for k in range(3, 8):
        send(k, 2 * (k - 2))  # the honest strips go on: lines 2 … 11
    pub.send_multipart([b"end", json.dumps({"stream_id": "s", "counters": {}}).encode()])
    t.join(20)
    pub.close(0)
    assert not t.is_alive() and result["rc"] == 0
    image, az, _, attrs = read_image(out)
    assert image.shape == (12, bins) and attrs["complete"]
    np.testing.assert_array_equal(az, np.arange(12))
    assert attrs["other_stream_strips"] == 1 and attrs["stray_strips"] == 1
    assert json.loads(attrs["line_jumps"]) == []
    assert "bad messages 2" in capsys.readouterr().err


def test_a_v1_height_header_allocates_nothing_from_its_numbers():
    import tracemalloc

    from rtsar.sinks.wire import decode

    header = {"format": "rtsar-height", "version": 1, "stream_id": "x", "seq": 0}
    header.update(first_line=0, line_count=65536, range_bins=65536)
    tracemalloc.start()
    with pytest.raises(ValueError, match="payload does not match"):
        decode([b"height", json.dumps(header).encode(), b"", b""])
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 10_000_000


def test_a_refused_recording_write_leaves_the_file_readable(tmp_path):
    from rtsar.sinks.io import RecordingWriter, open_recording

    path = tmp_path / "r.h5"
    z = np.zeros((2, S), np.complex64)
    step = CFG.geometry.along_track_step_m
    with RecordingWriter(path, CFG) as w:
        w.write(z, [0, 1], [0.0, 0.1], [0.0, step], {"a": z, "b": z})
        with pytest.raises(ValueError, match="channel 'b'"):
            w.write(z, [2, 3], [0.2, 0.3], [2 * step, 3 * step], {"a": z, "b": z[:, :3]})
    with open_recording(path) as r:
        assert r.pulses == 2 and r.channels["a"].shape == (2, S)


def test_the_subscribers_own_stream_is_never_forgotten():
    from rtsar.sinks.client import StripSubscriber

    sub = StripSubscriber("tcp://127.0.0.1:1")
    try:
        for k in range(5):
            sub._count({"stream_id": "A", "seq": k})
        for k in range(8):
            sub._count({"stream_id": f"B{k}", "seq": 0})
        sub._count({"stream_id": "A", "seq": 50})
        assert sub.counters["missed_strips"] == 45
    finally:
        sub.close()


def test_subscribe_says_by_its_status_whether_the_stream_ended(tmp_path, capsys):
    """From reviews: `subscribe` stopped by --timeout after its publisher died exited 0 though
    its file said complete = False; and an end message before any strip (a spotlight
    publisher's) was ignored, so subscribe waited for its timeout (forever without one)."""
    import threading
    import time

    import zmq

    from rtsar.sinks.image_file import read_image

    def bare_publisher():
        pub = zmq.Context.instance().socket(zmq.XPUB)
        pub.bind("tcp://127.0.0.1:*")
        return pub, pub.getsockopt_string(zmq.LAST_ENDPOINT)

    def subscribing(endpoint, out, timeout):
        result = {}
        args = ["subscribe", endpoint, "-o", str(out), "--timeout", str(timeout)]
        t = threading.Thread(target=lambda: result.setdefault("rc", main(args)), daemon=True)
        t.start()
        return t, result

    bins = 8
    header = {"format": "rtsar-strip", "version": 1, "stream_id": "s", "seq": 0, "first_line": 0,
              "line_count": 2, "range_bins": bins, "dtype": "complex64", "byte_order": "little",
              "azimuth_first_m": 0.0, "azimuth_step_m": 1.0, "range_first_m": 100.0,
              "range_step_m": 3.0, "flagged_lines": [], "counters": {}}  # fmt: skip
    header["config"] = CFG.to_dict()
    pub, endpoint = bare_publisher()
    t, result = subscribing(endpoint, tmp_path / "cut.h5", 1.0)
    assert pub.poll(10_000)
    pub.recv()
    time.sleep(0.2)
    pub.send_multipart([b"strip", json.dumps(header).encode(), bytes(2 * bins * 8)])
    t.join(20)  # the publisher sends nothing more: --timeout stops it
    assert not t.is_alive() and result["rc"] == 1
    assert not read_image(tmp_path / "cut.h5")[3]["complete"]
    pub.close(0)

    pub, endpoint = bare_publisher()
    t, result = subscribing(endpoint, tmp_path / "none.h5", 60.0)
    assert pub.poll(10_000)
    pub.recv()
    time.sleep(0.2)
    start = time.monotonic()
    pub.send_multipart([b"end", json.dumps({"stream_id": "x", "counters": {}}).encode()])
    t.join(20)
    assert not t.is_alive() and time.monotonic() - start < 10  # not the 60 s timeout
    assert result["rc"] == 1  # nothing to write
    assert "the publisher's stream ended before any strip" in capsys.readouterr().err
    pub.close(0)
