"""GNU Radio ZMQ input (issue 16): frames built to GNU Radio's wire format (gr-zeromq
tag_headers.cc, pmt_serialize.cc) are cut into shots with their numbers and times."""

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import zmq

from rtsar.sources.gr_tags import (
    PmtError,
    parse_tag_header,
    pmt_long,
    pmt_rx_time,
    pmt_symbol,
    read_pmt,
    tag_header,
)
from rtsar.sources.zmq_in import ZmqSource

S = 16


def _shots(rng, n):
    return (rng.standard_normal((n, S)) + 1j * rng.standard_normal((n, S))).astype(np.complex64)


def test_pmt_and_header_parse_by_hand():
    # Bytes written out by hand from the documented layout, not by our writer.
    key = b"\x02\x00\x0apacket_len"
    value = b"\x03\x00\x00\x00\x10"
    rx_key = b"\x02\x00\x07rx_time"
    rx_val = (
        b"\x0c\x00\x00\x00\x02\x0b"
        + struct.pack(">Q", 1700000000)
        + b"\x04"
        + struct.pack(">d", 0.25)
    )
    head = struct.pack("<HBQQ", 0x5FF0, 1, 32, 2)
    head += struct.pack("<Q", 32) + key + value + b"\x01"
    head += struct.pack("<Q", 32) + rx_key + rx_val + b"\x01"
    offset, tags, length = parse_tag_header(head + b"\0" * 8)
    assert (offset, length) == (32, len(head))
    assert [(t.offset, t.key, t.value) for t in tags] == [
        (32, "packet_len", 16),
        (32, "rx_time", (1700000000, 0.25)),
    ]
    assert read_pmt(pmt_long(1 << 40), 0) == (1 << 40, 9)
    with pytest.raises(PmtError):
        parse_tag_header(struct.pack("<HBQQ", 0x5FF1, 1, 0, 0))
    with pytest.raises(PmtError):
        parse_tag_header(head[:-3])
    # From a cold review: 5000 nested pairs exhausted Python's stack (RecursionError ended the
    # run); nesting is bounded, so the message is a counted bad one.
    deep = struct.pack("<HBQQ", 0x5FF0, 1, 0, 1) + struct.pack("<Q", 0) + b"\x07" * 5000
    with pytest.raises(PmtError, match="nested"):
        parse_tag_header(deep + b"\0" * 8)


def test_flat_stream_sliced_by_packet_len_with_gap_and_wrong_length(rng):
    shots = _shots(rng, 6)
    flat = shots.reshape(-1)
    src = ZmqSource("tcp://127.0.0.1:1", S, item_rate_hz=1000.0, shot_rate_hz=10.0)
    tags = [(p * S, pmt_symbol("packet_len"), pmt_long(S)) for p in range(6)]
    tags[0:0] = [(0, pmt_symbol("rx_time"), pmt_rx_time(100, 0.5))]
    # Messages cut across shots: [0, 24), [24, 56), (lost: [56, 72)), [72, 96)
    out = []
    for a, b in ((0, 24), (24, 56), (72, 96)):
        mine = [t for t in tags if a <= t[0] < b]
        out += src.decode(tag_header(a, mine) + flat[a:b].tobytes())
    seqs = [s for s, _, _ in out]
    assert seqs == [0, 1, 2, 5]  # shots 3 and 4 lost in part with the lost message
    for seq, t, samples in out:
        np.testing.assert_array_equal(samples, shots[seq])
        assert t == pytest.approx(100.5 + seq * S / 1000.0)
    # The 8 samples of shot 3 that arrived, and the 8 of shot 4 after the lost message.
    assert src.counters["partial_samples"] == 16
    bad = tag_header(96, [(96, pmt_symbol("packet_len"), pmt_long(S + 1))])
    assert src.decode(bad + np.zeros(S + 1, np.complex64).tobytes()) == []
    assert src.counters["wrong_length"] == 1


def test_guard_samples_between_packets_are_no_gap(rng):
    """Packets of S samples every S + 4 items (a burst flowgraph's guard): 30 shots numbered
    0…29 without a hole (item offset // S made a false gap every 4 shots, zero-filled as lost),
    and a lost message still leaves its gap."""
    period = S + 4
    shots = _shots(rng, 30)
    flat = np.zeros(30 * period, np.complex64)
    for p in range(30):
        flat[p * period : p * period + S] = shots[p]
    tags = [(p * period, pmt_symbol("packet_len"), pmt_long(S)) for p in range(30)]
    src = ZmqSource("tcp://127.0.0.1:1", S, item_rate_hz=1000.0, shot_rate_hz=50.0)
    out = []
    for a in range(0, 30 * period, 50):
        if 200 <= a < 300:  # lost: packets 10…14 (11, 12, 13 whole)
            continue
        mine = [t for t in tags if a <= t[0] < a + 50]
        out += src.decode(tag_header(a, mine) + flat[a : a + 50].tobytes())
    seqs = [s for s, _, _ in out]
    assert seqs == [*range(10), *range(15, 30)]
    for seq, _, samples in out:
        np.testing.assert_array_equal(samples, shots[seq])


def test_vector_items_over_a_socket(rng):
    shots = _shots(rng, 5)
    ctx = zmq.Context()
    pub = ctx.socket(zmq.XPUB)  # PUB on the wire; XPUB also tells when the subscriber is there
    port = pub.bind_to_random_port("tcp://127.0.0.1")
    src = ZmqSource(f"tcp://127.0.0.1:{port}", S, 1e3, 10.0, idle_timeout_s=2.0, context=ctx)
    got = []
    it = iter(src)
    import threading

    pub.setsockopt(zmq.RCVTIMEO, 30_000)  # no subscription: the test fails, it does not hang

    def send():
        try:
            pub.recv()  # the subscription (before: a 0.3 s sleep, a slow joiner's race)
        except zmq.Again:
            return
        pub.send(tag_header(10, []) + shots[:2].tobytes())  # vector items 10, 11
        pub.send(tag_header(13, []) + shots[3:].tobytes())  # 12 lost on the way
        pub.send(b"\xf0\x5f\x01garbage")

    threading.Thread(target=send, daemon=True).start()
    for batch in it:
        got.append(batch)
    seq = np.concatenate([b.seq for b in got])
    np.testing.assert_array_equal(seq, [10, 11, 13, 14])
    np.testing.assert_array_equal(np.concatenate([b.samples for b in got]), shots[[0, 1, 3, 4]])
    assert src.counters["bad_messages"] == 1 and src.stop_reason == "idle"
    pub.close()
    ctx.term()


def test_run_zmq_in_equals_process_of_the_recording(tmp_path):
    """`run --zmq-in` of a flat, packet_len-tagged stream (messages cut across shots) gives the
    image `process` makes of the same shots, on the same axes."""
    from rtsar.app.cli import main
    from rtsar.scene import Simulator, load_scene
    from rtsar.sinks.image_file import read_image

    scene_file = tmp_path / "s.toml"
    scene_file.write_text(
        'preset = "tiny"\npulses = 200\nstart_along_track_m = -25.0\n'
        "[[targets]]\nalong_track_m = 0.0\nslant_range_m = 2000.0\n"
    )
    scene = load_scene(scene_file)
    shots = Simulator(scene).block(scene.pulses).astype(np.complex64)
    rec, ref_img, img = tmp_path / "r.h5", tmp_path / "ref.h5", tmp_path / "img.h5"
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(ref_img), "--lens", "numpy"]) == 0
    s = shots.shape[1]
    flat = shots.reshape(-1)
    endpoint = "ipc://" + str(tmp_path / "gr")
    ctx = zmq.Context()
    pub = ctx.socket(zmq.XPUB)  # PUB on the wire; XPUB also tells when the subscriber is there
    pub.bind(endpoint)

    def serve():
        pub.recv()  # the subscription
        for a in range(0, len(flat), 1000):  # 1000 items a message: not whole shots
            b = min(a + 1000, len(flat))
            first = (a + s - 1) // s
            tags = [
                (p * s, pmt_symbol("packet_len"), pmt_long(s)) for p in range(first, b // s + 1)
            ]
            pub.send(tag_header(a, [t for t in tags if a <= t[0] < b]) + flat[a:b].tobytes())

    import threading

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    args = ["run", "--zmq-in", endpoint, "--scene", str(scene_file), "--duration", "1.5"]
    args += ["--lens", "numpy", "-o", str(img), "--endpoint", "ipc://" + str(tmp_path / "pub")]
    args += ["--fft-length", "128"]  # process's (tiny: 2N), not the one chosen for the rate
    assert main(args) == 0
    thread.join(5)
    pub.close()
    ctx.term()
    got, az, _, _ = read_image(img)
    want, want_az, _, _ = read_image(ref_img)
    np.testing.assert_allclose(az, want_az)
    np.testing.assert_array_equal(got, want)


def test_a_late_subscriber_keeps_the_positions_and_counts_what_it_missed(tmp_path):
    """From a cold review: a subscriber that connected after the flowgraph had sent 68 shots
    numbered its first shot pulse 0, and the image moved 34 m along track with no counter.
    The first message's item offset anchors the numbering: the lines are `process`'s lines 68…
    at their positions, and the 68 shots are counted (pulses_before_start)."""
    import json

    from rtsar.app.cli import main
    from rtsar.scene import Simulator, load_scene
    from rtsar.sinks.image_file import read_image

    scene_file = tmp_path / "s.toml"
    scene_file.write_text(
        'preset = "tiny"\npulses = 200\nstart_along_track_m = -25.0\n'
        "[[targets]]\nalong_track_m = 20.0\nslant_range_m = 2000.0\n"
    )
    scene = load_scene(scene_file)
    shots = Simulator(scene).block(scene.pulses).astype(np.complex64)
    rec, ref_img, img = tmp_path / "r.h5", tmp_path / "ref.h5", tmp_path / "img.h5"
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(ref_img), "--lens", "numpy"]) == 0
    late = 68
    endpoint = "ipc://" + str(tmp_path / "gr")
    ctx = zmq.Context()
    pub = ctx.socket(zmq.XPUB)
    pub.bind(endpoint)

    def serve():
        pub.recv()  # the subscription: the flowgraph has been running for 68 shots
        for p in range(late, len(shots), 10):  # vector items, 10 a message
            pub.send(tag_header(p, []) + shots[p : p + 10].tobytes())

    import threading

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    args = ["run", "--zmq-in", endpoint, "--scene", str(scene_file), "--duration", "1.5"]
    args += ["--lens", "numpy", "-o", str(img), "--endpoint", "ipc://" + str(tmp_path / "pub")]
    args += ["--fft-length", "128"]  # process's (tiny: 2N), not the one chosen for the rate
    assert main(args) == 0
    thread.join(5)
    pub.close()
    ctx.term()
    got, az, _, attrs = read_image(img)
    want, want_az, _, _ = read_image(ref_img)
    np.testing.assert_allclose(az, want_az[late:])
    # (the FFT correlator's blocks start 68 pulses later: the same lines to float32 rounding)
    assert np.abs(got - want[late:]).max() <= 1e-5 * np.abs(want).max()
    counters = json.loads(attrs["counters"])
    assert counters["pulses_before_start"] == late and counters.get("gap_pulses", 0) == 0


def test_the_flowgraph_without_gnu_radio_says_what_to_install(tmp_path):
    """Issue 31: tools/gnuradio_flowgraph.py under a Python without GNU Radio was a traceback
    (ModuleNotFoundError); it is one line naming what to install, exit status 2."""
    if subprocess.run([sys.executable, "-c", "import gnuradio"]).returncode == 0:
        pytest.skip("this interpreter has GNU Radio")
    script = Path(__file__).resolve().parents[1] / "tools" / "gnuradio_flowgraph.py"
    done = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "rec.sigmf-meta")],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert "Traceback" not in done.stderr and done.stderr.count("\n") == 1
    assert "apt-get install gnuradio" in done.stderr


def test_one_short_packet_costs_its_own_number_not_the_streams_scale(rng):
    """Issue 36, item 3: 1,500 good packets, one with packet_len 10, 1,500 more: the period
    was learnt from the smallest spacing ever seen (10 items), so every later packet took
    ~S/10 numbers (26,983 zero-filled pulses, the image 10x too long).  Now the short packet
    is counted and costs one number; the good ones stay consecutive."""
    good = 300
    shots = _shots(rng, 2 * good)
    parts, tags, at = [], [], 0
    for p in range(2 * good):
        if p == good:  # the short packet, inserted between the two halves
            tags.append((at, pmt_symbol("packet_len"), pmt_long(10)))
            parts.append(np.zeros(10, np.complex64))
            at += 10
        tags.append((at, pmt_symbol("packet_len"), pmt_long(S)))
        parts.append(shots[p])
        at += S
    flat = np.concatenate(parts)
    src = ZmqSource("tcp://127.0.0.1:1", S, item_rate_hz=1000.0, shot_rate_hz=50.0)
    out = []
    for a in range(0, len(flat), 64):
        mine = [t for t in tags if a <= t[0] < a + 64]
        out += src.decode(tag_header(a, mine) + flat[a : a + 64].tobytes())
    seqs = [s for s, _, _ in out]
    assert len(out) == 2 * good and src.counters["wrong_length"] == 1
    assert seqs == [*range(good), *range(good + 1, 2 * good + 1)]  # one number lost, no more
    for k, (_, _, samples) in enumerate(out):
        np.testing.assert_array_equal(samples, shots[k])


def test_an_instrument_without_a_configuration_is_said_to_be_the_demos(tmp_path, capsys):
    # A new user's trial: `run --zmq-in` without --preset ran the demo's configuration and
    # the banner never said so (a real instrument's shots would be focused as the demo's).
    from rtsar.app.cli import main

    pub = zmq.Context.instance().socket(zmq.PUB)
    port = pub.bind_to_random_port("tcp://127.0.0.1")
    try:
        argv = ["run", "--zmq-in", f"tcp://127.0.0.1:{port}", "--duration", "0.5"]
        argv += ["--lens", "numpy", "--endpoint", "ipc://" + str(tmp_path / "pub")]
        assert main(argv) == 0
    finally:
        pub.close(0)
    out = capsys.readouterr().out
    assert "no --preset, --scene or --instrument: the instrument is taken to be the demo" in out
    assert "(480 samples a shot at 1600 Hz)" in out
