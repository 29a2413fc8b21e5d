"""SerialSource over loop://, a pseudo-terminal and a TCP socket fed by the fake instrument."""

import sys
import threading
import time

import numpy as np
import pytest
from conftest import crandn
from conftest import free_port as _conftest_free_port
from tools_loader import load_tool

from rtsar.presets import preset
from rtsar.scene import point_scene
from rtsar.sources.frame import FrameParser, encode_frame
from rtsar.sources.serial import SerialSource


def _collect(source):
    batches = list(source)
    seq = np.concatenate([b.seq for b in batches]) if batches else np.zeros(0, np.int64)
    return batches, seq


def test_loop_batches_channels_and_wrong_lengths(rng):
    x = crandn(rng, 10, 2, 16, dtype=np.complex64)  # [shot, channel, sample]
    src = SerialSource("loop://", 16, batch_frames=4, idle_timeout_s=0.2, channel=1)
    src.port.write(rng.bytes(100))
    for k in range(10):
        src.port.write(encode_frame(k, 1000 * k, x[k]))
        if k == 4:
            src.port.write(encode_frame(90, 0, x[k, :, :8]))  # too short
            src.port.write(encode_frame(91, 0, x[k, 0]))  # no channel 1
            src.port.write(b"\x1a\xcf\xfc\x1d" + rng.bytes(40))  # a false sync
    batches, seq = _collect(src)
    # Batches of at most batch_frames, whatever the reads: how the bytes fell into reads split
    # the last two once beside a second test run ([4, 4, 1, 1]); the shots themselves are below.
    sizes = [len(b) for b in batches]
    assert sum(sizes) == 10 and all(1 <= n <= 4 for n in sizes) and max(sizes) == 4, sizes
    assert seq.dtype == np.int64
    np.testing.assert_array_equal(seq, np.arange(10))
    np.testing.assert_array_equal(np.concatenate([b.samples for b in batches]), x[:, 1])
    np.testing.assert_allclose(np.concatenate([b.timestamp_s for b in batches]), 1e-6 * seq)
    assert all(b.samples.dtype == np.complex64 and b.samples.shape[1] == 16 for b in batches)
    assert src.counters["wrong_length"] == 2
    # The short frame and the one without channel 1 are refused at their header (never
    # buffered, never decoded).
    assert src.counters["frames_ok"] == 10
    assert src.counters["header_crc_errors"] >= 1
    assert src.stop_reason.startswith("no bytes")
    assert not src.port.is_open


def test_sequence_numbers_above_int64_keep_their_bits():
    src = SerialSource("loop://", 4, idle_timeout_s=0.1)
    src.port.write(encode_frame(2**64 - 1, 0, np.ones(4)))
    _, seq = _collect(src)
    assert seq.tolist() == [-1]


def test_close_stops_iteration_promptly():
    src = SerialSource("loop://", 8, poll_s=0.05)  # nothing ever arrives
    done = threading.Event()
    thread = threading.Thread(target=lambda: (list(src), done.set()))
    thread.start()
    time.sleep(0.1)
    t0 = time.perf_counter()
    src.close()
    assert done.wait(2.0)
    assert time.perf_counter() - t0 < 0.5
    thread.join()
    assert src.stop_reason == "closed"
    assert not src.port.is_open


def test_close_before_iterating():
    src = SerialSource("loop://", 8)
    src.close()
    assert not src.port.is_open
    assert list(src) == []


def _free_port() -> int:
    return _conftest_free_port()


@pytest.mark.parametrize("url", ["socket://127.0.0.1:{free}", "/no/such/tty", "nosuchscheme://x"])
def test_bad_url_is_a_clear_error(url):
    url = url.format(free=_free_port())  # the port is chosen at run time, not in the test's id
    with pytest.raises(ValueError, match="cannot open instrument port") as info:
        SerialSource(url, 8, connect_timeout_s=0)
    assert url in str(info.value)


def test_a_refused_socket_is_waited_for_then_a_clear_error():
    """Nothing listening: the source tries for connect_timeout_s, says so once, then the error
    names the port and the wait (not a bare 'Connection refused' at once)."""
    url = f"socket://127.0.0.1:{_free_port()}"
    messages = []
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"waited 0.6 s: --connect-timeout") as info:
        SerialSource(url, 8, connect_timeout_s=0.6, notify=messages.append)
    assert 0.55 < time.perf_counter() - t0 < 3.0
    assert url in str(info.value)
    assert len(messages) == 1 and "waiting up to 0.6 s" in messages[0]


def test_an_instrument_that_starts_after_the_processor_is_waited_for():
    """From CI: the docs' `fake_instrument --listen … & rtsar run --serial socket://…` failed
    with 'Connection refused' when rtsar connected before the instrument listened (a slower
    machine). By default a socket:// instrument is waited for, so the order does not matter."""
    fake = load_tool("fake_instrument")
    cfg, shots = _tiny_shots(200)
    port = _free_port()
    result = {}

    def serve_late():
        time.sleep(0.7)  # the processor is already trying
        with fake.listen(f"127.0.0.1:{port}") as server:
            result["summary"] = fake.serve_tcp(server, [shots], 5000.0, start_delay_s=0.1)

    thread = threading.Thread(target=serve_late)
    thread.start()
    messages = []
    src = SerialSource(
        f"socket://127.0.0.1:{port}",
        cfg.waveform.samples_per_shot,
        idle_timeout_s=2.0,
        reconnect=False,
        notify=messages.append,
    )
    _, seq = _collect(src)
    thread.join(5.0)
    assert result["summary"].sent == 200
    assert len(seq) >= 150 and np.all(np.diff(seq) > 0)
    assert "not there yet" in messages[0] and "waiting up to 10 s" in messages[0]
    assert any(m.endswith("open") for m in messages)


@pytest.mark.parametrize(
    "kwargs", [{"samples_per_shot": 0}, {"batch_frames": 0}, {"channel": -1}, {"idle_timeout_s": 0}]
)
def test_bad_arguments(kwargs):
    args = {"url": "loop://", "samples_per_shot": 8, **kwargs}
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        SerialSource(**args)


def _tiny_shots(pulses):
    cfg = preset("tiny")
    scene = point_scene(
        cfg, [0.0], [cfg.geometry.slant_range_m], pulses=pulses, start_along_track_m=-1.0
    )
    fake = load_tool("fake_instrument")
    return cfg, np.concatenate(list(fake.scene_shots(scene, block=64)))


def test_fake_instrument_over_tcp_with_corruption():
    fake = load_tool("fake_instrument")
    prf = 5000.0
    cfg, shots = _tiny_shots(400)
    server = fake.listen("127.0.0.1:0")
    port = server.getsockname()[1]
    result = {}

    def serve():
        with server:
            result["summary"] = fake.serve_tcp(
                server, [shots], prf, start_delay_s=0.1, corrupt=0.01, seed=3
            )

    thread = threading.Thread(target=serve)
    thread.start()
    src = SerialSource(
        f"socket://127.0.0.1:{port}",
        cfg.waveform.samples_per_shot,
        batch_frames=32,
        idle_timeout_s=5.0,
        reconnect=False,
    )
    batches, seq = _collect(src)
    thread.join(5.0)
    summary = result["summary"]
    assert summary.corrupted >= 1  # the seed must exercise the case
    assert (summary.shots, summary.sent, summary.stopped) == (400, 400, None)

    intact = np.setdiff1d(np.arange(400), summary.corrupted_seqs)
    np.testing.assert_array_equal(seq, intact)
    np.testing.assert_array_equal(np.concatenate([b.samples for b in batches]), shots[intact])
    np.testing.assert_allclose(np.concatenate([b.timestamp_s for b in batches]), seq / prf)
    assert all(len(b) <= 32 for b in batches)
    c = src.counters
    assert c["header_crc_errors"] + c["payload_crc_errors"] == summary.corrupted
    assert c["frames_ok"] == len(intact)
    assert src.failure.startswith("instrument link lost")  # the instrument hung up: said so
    assert src.counters["link_drops"] == 1


def test_emit_drops_duplicates_and_keeps_the_schedule(rng):
    fake = load_tool("fake_instrument")
    shots = crandn(rng, 60, 8)
    prf = 1000.0
    written, times = [], []

    def write(frame):
        written.append(frame)
        times.append(time.perf_counter())

    t0 = time.perf_counter()
    blocks = [shots[:25], shots[25:]]
    summary = fake.emit_frames(write, blocks, prf, drop=0.1, duplicate=0.1, seed=5)
    assert summary.dropped >= 1 and summary.duplicated >= 1
    assert summary.sent == 60 - summary.dropped + summary.duplicated == len(written)
    frames = FrameParser().feed(b"".join(written))
    seqs = [f.sequence for f in frames]
    assert sorted(set(seqs)) == sorted(set(range(60)) - set(summary.dropped_seqs))
    assert len(seqs) - len(set(seqs)) == summary.duplicated
    # Absolute schedule: frame n never leaves before t0 + n / PRF.
    due = t0 + np.array(seqs) / prf
    assert np.all(np.array(times) >= due - 1e-4)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="pty reader detection is Linux's")
def test_fake_instrument_on_a_pty():
    fake = load_tool("fake_instrument")
    cfg, shots = _tiny_shots(200)
    pty = fake.Pty()
    result = {}

    def serve():
        result["summary"] = fake.serve_pty(
            pty, [shots], 5000.0, start_delay_s=0.1, linger_s=5.0, sample_type="ci16", scale=1e3
        )

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        src = SerialSource(pty.path, cfg.waveform.samples_per_shot, idle_timeout_s=5.0)
        got = []
        for batch in src:
            got.append(batch)
            if sum(len(b) for b in got) >= 200:
                break
        src.close()  # the instrument sees the reader go and stops lingering
        thread.join(5.0)
        assert not thread.is_alive()
    finally:
        pty.close()
    seq = np.concatenate([b.seq for b in got])
    np.testing.assert_array_equal(seq, np.arange(200))
    x = 1000.0 * shots
    want = np.rint(x.real) + 1j * np.rint(x.imag)
    np.testing.assert_array_equal(np.concatenate([b.samples for b in got]), want)
    assert result["summary"].sent == 200


def test_a_lost_socket_is_reported_and_reopened():
    """The instrument hangs up after 150 shots and serves again: the source says so, reconnects
    and gets the second connection's shots; nothing is silent."""
    fake = load_tool("fake_instrument")
    cfg, shots = _tiny_shots(300)
    server = fake.listen("127.0.0.1:0")
    port = server.getsockname()[1]

    def serve():
        with server:
            fake.serve_tcp(server, [shots[:150]], 5000.0, start_delay_s=0.1)
            fake.serve_tcp(server, [shots[150:]], 5000.0, start_delay_s=0.3, first_seq=150)

    thread = threading.Thread(target=serve)
    thread.start()
    messages = []
    src = SerialSource(
        f"socket://127.0.0.1:{port}", cfg.waveform.samples_per_shot, idle_timeout_s=1.0
    )
    src.notify = messages.append
    batches, seq = _collect(src)
    thread.join(5.0)
    assert src.counters["link_drops"] == 2 and src.counters["reconnects"] == 1
    assert any("lost" in m for m in messages) and any("reopened" in m for m in messages)
    # What arrived on both connections (the first frames of a connection may be discarded by
    # pyserial when it opens): in order, from both halves.
    assert np.all(np.diff(seq) > 0) and seq.min() < 150 <= seq.max()
    assert src.failure is not None  # the link was down when the source gave up


def test_serial_run_of_a_scene_keeps_its_along_track_positions(tmp_path):
    """`run --serial … --scene S` labels lines where the scene's targets are: the same image and
    azimuth axis as `process` of the scene's recording (it was 60 m off for the demo scene)."""
    from rtsar.app.cli import main
    from rtsar.scene import Simulator, load_scene
    from rtsar.sinks.image_file import read_image

    scene_file = tmp_path / "s.toml"
    scene_file.write_text(
        'preset = "tiny"\npulses = 300\nstart_along_track_m = -25.0\n'
        "[[targets]]\nalong_track_m = 0.0\nslant_range_m = 2000.0\n"
    )
    scene = load_scene(scene_file)
    shots = Simulator(scene).block(scene.pulses)
    rec, ref_img, img = tmp_path / "r.h5", tmp_path / "ref.h5", tmp_path / "img.h5"
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(ref_img), "--lens", "numpy"]) == 0
    fake = load_tool("fake_instrument")
    server = fake.listen("127.0.0.1:0")
    port = server.getsockname()[1]

    def serve():
        with server:
            fake.serve_tcp(server, [shots], 4 * scene.config.geometry.prf_hz, start_delay_s=0.1)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    args = ["run", "--serial", f"socket://127.0.0.1:{port}", "--scene", str(scene_file)]
    args += ["--no-reconnect", "--duration", "2", "--lens", "numpy", "-o", str(img)]
    args += ["--fft-length", "128"]  # process's (tiny: 2N), not the one chosen for the rate
    args += ["--endpoint", "ipc://" + str(tmp_path / "pub")]
    assert main(args) == 1  # the instrument hung up at the end of its shots: said so
    thread.join(5)
    got, az, _, _ = read_image(img)
    want, want_az, _, _ = read_image(ref_img)
    np.testing.assert_allclose(az, want_az)
    np.testing.assert_array_equal(got, want)


def _false_header(samples: int, channels: int) -> bytes:
    """A CRC-valid frame header with no payload behind it (what a bit pattern in the data can
    be, one time in 2**32)."""
    import struct
    import zlib

    header = struct.pack("<BBHIQQ", 1, 1, channels, samples, 7, 0)
    return b"\x1a\xcf\xfc\x1d" + header + struct.pack("<I", zlib.crc32(header))


@pytest.mark.parametrize("channel_map", [None, "main,rx1"])
def test_a_false_header_claiming_64_channels_holds_no_true_frame(channel_map):
    """Issue 29: the source's parser took frames of up to 64 channels, so a CRC-valid false
    header claiming 64 held up to 63 true frames behind it (a 12 s stall at 5 Hz).  The
    configured frame (its samples, exactly the channels the shot takes) is the only shape
    accepted: the header is refused at once and the frames behind it come out in the same
    call; the parser never holds more than one configured frame."""
    from rtsar.sources.channel_map import ChannelMap
    from rtsar.sources.frame import frame_bytes

    cmap = None if channel_map is None else ChannelMap.parse(channel_map)
    width = 1 if cmap is None else cmap.frame_channels
    src = SerialSource("loop://", 16, idle_timeout_s=0.1, channel_map=cmap)
    said = []
    src.notify = said.append
    shots = [encode_frame(k, k, np.full((width, 16), k, np.complex64)) for k in range(6)]
    got = src.parser.feed(shots[0] + _false_header(16, 64) + b"".join(shots[1:]))
    assert [f.sequence for f in got] == list(range(6))
    assert src.parser.counters["wrong_length"] == 1
    assert src.parser.buffered == 0
    # Fed byte by byte, nothing beyond one configured frame is ever held.
    held = 0
    for byte in _false_header(16, 64) + b"".join(shots):
        src.parser.feed(bytes([byte]))
        held = max(held, src.parser.buffered)
    assert held < frame_bytes(16, width)
    # A frame with more channels than the shot takes is another shape too, said once.
    src.port.write(encode_frame(9, 0, np.ones((width + 1, 16), np.complex64)) * 2)
    list(src)
    assert src.counters["wrong_length"] == 4
    assert len(said) == 1 and f"{width + 1} channels x 16 samples refused" in said[0]


def test_run_waits_for_connect_timeout_then_exits_2(capsys):
    """`rtsar run --serial` with nothing listening: tried for --connect-timeout, said on stdout,
    then one error line naming the port and the wait; --connect-timeout without --serial is
    refused."""
    from rtsar.app.cli import main

    url = f"socket://127.0.0.1:{_free_port()}"
    t0 = time.perf_counter()
    assert main(["run", "--serial", url, "--connect-timeout", "0.4"]) == 2
    assert 0.35 < time.perf_counter() - t0 < 5.0
    out, err = capsys.readouterr()
    assert "waiting up to 0.4 s" in out
    assert url in err and "waited 0.4 s" in err
    assert main(["run", "--connect-timeout", "1"]) == 2
    assert "--connect-timeout is for --serial" in capsys.readouterr().err


def test_wait_subscribers_is_refused_for_an_instrument(capsys):
    from rtsar.app.cli import main

    assert main(["run", "--serial", "loop://", "--wait-subscribers", "1"]) == 2
    assert "--wait-subscribers is for a simulated run" in capsys.readouterr().err
