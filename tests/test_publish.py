"""ZeroMQ strips: wire format, replay → subscribe equals process, stalled subscribers, CURVE."""

import json
import threading
import time

import numpy as np
import pytest
import zmq
from conftest import free_port as _conftest_free_port

import rtsar.sinks.publish as publish
from rtsar.app.cli import main
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene
from rtsar.sinks.client import StripSubscriber
from rtsar.sinks.image_file import read_image
from rtsar.sinks.publish import ZmqPublisher, is_local_endpoint
from rtsar.sinks.wire import decode
from rtsar.sources.replay import ReplaySource
from rtsar.stream.pipeline import Pipeline, PipelineSettings

SCENE = """
preset = "tiny"
seed = 5
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
[[targets]]
along_track_m = 12.0
slant_range_m = 1960.0
[[effects]]
name = "noise"
snr_db = 10.0
"""


def free_endpoint() -> str:
    return f"tcp://127.0.0.1:{_conftest_free_port()}"


def test_replay_max_into_subscribe_equals_process(tmp_path):
    scene, rec = tmp_path / "s.toml", tmp_path / "r.h5"
    scene.write_text(SCENE)
    assert main(["simulate", str(scene), "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(tmp_path / "batch.h5")]) == 0
    ep = free_endpoint()
    codes = []
    sub = threading.Thread(
        target=lambda: codes.append(
            main(["subscribe", ep, "-o", str(tmp_path / "sub.h5"), "--timeout", "30"])
        )
    )
    sub.start()
    args = ["replay", str(rec), "--rate", "max", "--endpoint", ep, "--wait-subscribers", "1"]
    assert main(args + ["--strip-lines", "5"]) == 0
    sub.join(60)
    assert codes == [0]
    batch, az_b, rg_b, _ = read_image(tmp_path / "batch.h5")
    streamed, az_s, rg_s, attrs = read_image(tmp_path / "sub.h5")
    assert streamed.shape == batch.shape
    assert np.abs(streamed - batch).max() <= 1e-6 * np.abs(batch).max()
    np.testing.assert_allclose(az_s, az_b, rtol=0, atol=1e-9)
    np.testing.assert_allclose(rg_s, rg_b, rtol=1e-12)
    assert attrs["complete"] and attrs["missing_lines"] == 0 and attrs["missed_strips"] == 0
    assert attrs["stopped_by"] == ""  # the replay ran to its end
    assert json.loads(attrs["counters"])["pulses_processed"] > 0
    # the recording's collection start travels in the strip header to the subscriber's file
    batch_start = read_image(tmp_path / "batch.h5")[3]["collection_start_utc"]
    assert attrs["collection_start_utc"] == batch_start


def test_a_subscriber_keeps_the_signal_that_stopped_the_publisher_s_source(tmp_path, monkeypatch):
    """The end message's ``stopped_by`` (a paced replay stopped by Ctrl-C after its first
    strip) goes into ``subscribe -o``'s image, which is complete: the stream ended, early."""
    from test_replay_part import ctrl_c_once

    scene, rec = tmp_path / "s.toml", tmp_path / "r.h5"
    scene.write_text(SCENE)
    assert main(["simulate", str(scene), "-o", str(rec)]) == 0
    ctrl_c_once(monkeypatch, lambda pipe: pipe.own["strips_published"] > 0)
    ep, codes = free_endpoint(), []
    sub = threading.Thread(
        target=lambda: codes.append(
            main(["subscribe", ep, "-o", str(tmp_path / "sub.h5"), "--timeout", "30"])
        )
    )
    sub.start()
    args = ["replay", str(rec), "--endpoint", ep, "--wait-subscribers", "1", "--lens", "numpy"]
    assert main(args + ["--delivery", "lossless"]) == 130
    sub.join(60)
    assert codes == [0]
    *_, attrs = read_image(tmp_path / "sub.h5")
    assert attrs["complete"] and attrs["stopped_by"] == "SIGINT"


def test_a_simulated_run_waits_for_its_subscriber(tmp_path):
    """`rtsar run --wait-subscribers 1` (the docs' two-terminal example): a subscriber that
    starts 3 s late still gets the stream from its first strip, nothing missed."""
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    ep = free_endpoint()
    codes = []

    def subscribe_late():
        time.sleep(3.0)  # longer than the run's setup and its 1 s of stream
        codes.append(main(["subscribe", ep, "-o", str(tmp_path / "sub.h5"), "--timeout", "10"]))

    sub = threading.Thread(target=subscribe_late)
    sub.start()
    argv = ["run", "--scene", str(scene), "--endpoint", ep, "--wait-subscribers", "1"]
    assert main(argv + ["--duration", "1", "--delivery", "lossless"]) == 0
    sub.join(60)
    assert codes == [0]
    _, az, _, attrs = read_image(tmp_path / "sub.h5")
    assert attrs["complete"] and attrs["missing_lines"] == 0 and attrs["missed_strips"] == 0
    assert json.loads(attrs["counters"])["pulses_processed"] > 0 and len(az) > 0


@pytest.fixture(scope="module")
def tiny_shots():
    cfg = preset("tiny")
    scene = point_scene(cfg, [0.0], [cfg.geometry.slant_range_m], pulses=1200)
    return cfg, Simulator(scene).block(scene.pulses)


def run_pipeline(cfg, shots, publisher, repeat=1, rate="max"):
    shots = np.concatenate([shots] * repeat)
    seq = np.arange(len(shots))
    src = ReplaySource(shots, seq, seq / cfg.geometry.prf_hz, cfg.geometry.prf_hz, rate, 64)
    t = time.perf_counter()
    Pipeline(cfg, src, [publisher], PipelineSettings(strip_lines=4)).run()
    return time.perf_counter() - t


def test_messages_carry_the_documented_header_and_payload(tiny_shots):
    cfg, shots = tiny_shots
    pub = ZmqPublisher("tcp://127.0.0.1:*", "lossless")
    sub = StripSubscriber(pub.endpoint)
    assert pub.wait_for_subscribers(1, timeout_s=10)
    run_pipeline(cfg, shots, pub)
    msgs = []
    while (m := sub.recv(2.0)) is not None:
        msgs.append(m)
        if m.topic == "end":
            break
    pub.close()
    sub.close()
    strips = [m for m in msgs if m.topic == "strip"]
    assert msgs[-1].topic == "end" and strips
    h = strips[0].header
    for key in (
        "seq",
        "first_line",
        "line_count",
        "range_bins",
        "azimuth_first_m",
        "azimuth_step_m",
        "range_first_m",
        "range_step_m",
        "first_pulse_arrival_unix_s",
        "last_pulse_arrival_unix_s",
        "publish_unix_s",
        "flagged_lines",
        "counters",
    ):
        assert key in h
    # Strips of 4 lines (run_pipeline), one cut short where no line came for a strip's time
    # (a loaded machine: seen beside a second test run, a first strip of 2 lines).
    assert strips[0].lines.shape == (h["line_count"], h["range_bins"])
    assert 1 <= h["line_count"] <= 4 and h["range_bins"] == 64
    assert h["first_pulse_arrival_unix_s"] <= h["last_pulse_arrival_unix_s"] <= h["publish_unix_s"]
    assert [m.header["seq"] for m in strips] == list(range(len(strips)))
    assert sum(m.header["line_count"] for m in strips) == msgs[-1].header["counters"]["lines_out"]


GOOD_HEADER = {
    "format": "rtsar-strip",
    "version": 1,
    "stream_id": "abc",
    "seq": 0,
    "first_line": 0,
    "line_count": 2,
    "range_bins": 3,
    "dtype": "complex64",
    "byte_order": "little",
    "azimuth_first_m": 0.0,
    "azimuth_step_m": 1.0,
    "range_first_m": 100.0,
    "range_step_m": 3.0,
    "flagged_lines": [],
    "counters": {},
    "config": {},
}


def test_decode_rejects_malformed_messages():
    good = [b"strip", json.dumps(GOOD_HEADER).encode(), bytes(48)]
    assert decode(good).lines.shape == (2, 3)
    for bad in (
        [b"strip"],
        [b"strip", b"{not json", b""],
        [b"strip", b"[1]", b""],
        good[:2] + [bytes(40)],
        [good[0], good[1].replace(b"rtsar", b"other"), good[2]],
    ):
        with pytest.raises(ValueError):
            decode(bad)


def test_a_stalled_subscriber_does_not_stall_the_pipeline(tiny_shots):
    cfg, shots = tiny_shots
    pub = ZmqPublisher("tcp://127.0.0.1:*", "drop", hwm_messages=20)
    stalled = zmq.Context.instance().socket(zmq.SUB)
    stalled.setsockopt(zmq.RCVHWM, 20)
    stalled.setsockopt(zmq.RCVBUF, 4096)
    stalled.setsockopt(zmq.SUBSCRIBE, b"")
    stalled.connect(pub.endpoint)
    assert pub.wait_for_subscribers(1, timeout_s=10)
    result = []
    t = threading.Thread(target=lambda: result.append(run_pipeline(cfg, shots, pub, repeat=8)))
    t.start()
    t.join(120)  # the subscriber never reads: with a blocking publisher this would hang
    assert not t.is_alive() and result
    assert pub.sent["strip"] > 200  # far more than both high-water marks hold
    stalled.close(0)
    pub.close()


def test_curve_encryption_needs_the_server_key(tmp_path, tiny_shots):
    assert main(["keygen", str(tmp_path)]) == 0
    pub = ZmqPublisher("tcp://127.0.0.1:*", "drop", curve_secret_key=tmp_path / "rtsar.key_secret")
    good = StripSubscriber(pub.endpoint, curve_server_key=tmp_path / "rtsar.key")
    plain = StripSubscriber(pub.endpoint)
    assert pub.wait_for_subscribers(1, timeout_s=10)
    pub.send("stats", {"hello": 1})
    assert good.recv(5.0).header == {"hello": 1}
    assert plain.recv(0.3) is None
    for s in (good, plain, pub):
        s.close()


def test_endpoints_default_to_loopback():
    assert is_local_endpoint("tcp://127.0.0.1:5555") and is_local_endpoint("ipc:///tmp/x")
    assert not is_local_endpoint("tcp://0.0.0.0:5555") and not is_local_endpoint("tcp://*:5555")
    warnings = []
    pub = ZmqPublisher("tcp://0.0.0.0:*", warn=warnings.append)
    pub.close()
    assert warnings and "without encryption" in warnings[0]


def test_run_demo_publishes_and_records(tmp_path, capsys):
    ep, out = free_endpoint(), tmp_path / "live.h5"
    assert main(["run", "--duration", "0.6", "--endpoint", ep, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "done: 960 pulses" in text and "dropped 0" in text
    image, az, rg, attrs = read_image(out)
    assert image.shape[0] == 960 - 512 + 1 and np.isfinite(image).all() and np.abs(image).max() > 0
    assert attrs["missing_lines"] == 0 and json.loads(attrs["counters"])["lines_out"] == len(az)


def test_numpy_range_doppler_reference_matches_the_engine():
    from rtsar.app.bench_pipeline import bench_shots, numpy_range_doppler
    from rtsar.stream.engine import process_block

    cfg = preset("tiny")
    shots = bench_shots(cfg, 400)
    expect, _, _ = process_block(cfg, shots, "numpy")
    got = numpy_range_doppler(cfg, shots)
    assert got.shape == expect.shape
    assert np.abs(got - expect).max() <= 1e-5 * np.abs(expect).max()


def test_a_stalled_subscriber_cannot_freeze_lossless_delivery(tiny_shots):
    """Lossless delivery with one subscriber that never reads: the run ends within the stall
    bound, the stall is counted, and a subscriber that keeps up receives every strip."""
    cfg, shots = tiny_shots
    # While the stalled one is cut off, delivery drops for every pipe at its high-water mark
    # (ZeroMQ's XPUB_NODROP is per socket): 300 messages (0.6 s) of slack for the reader.
    pub = ZmqPublisher("tcp://127.0.0.1:*", "lossless", hwm_messages=300, stall_timeout_s=0.5)
    stalled = zmq.Context.instance().socket(zmq.SUB)
    stalled.setsockopt(zmq.RCVHWM, 20)
    stalled.setsockopt(zmq.RCVBUF, 4096)
    stalled.setsockopt(zmq.SUBSCRIBE, b"")
    stalled.connect(pub.endpoint)
    reader = StripSubscriber(pub.endpoint)
    assert pub.wait_for_subscribers(2, timeout_s=10)
    got = []

    def read():
        while (m := reader.recv(5.0)) is not None:
            got.append(m)
            if m.topic == "end":
                return

    t_read = threading.Thread(target=read)
    t_read.start()
    result = []
    # Shots at 4× the PRF: 500 strips/s, which the reading subscriber keeps up with.
    t_run = threading.Thread(
        target=lambda: result.append(run_pipeline(cfg, shots, pub, 4, rate=4.0))
    )
    t_run.start()
    t_run.join(60)  # before: blocked for ever on the subscriber that never reads
    t_read.join(10)
    assert not t_run.is_alive() and result
    assert pub.subscriber_stalls >= 1 and pub.counters()["messages_missed_by_stalled"] > 0
    strips = [m for m in got if m.topic == "strip"]
    assert got and got[-1].topic == "end"
    assert [m.header["seq"] for m in strips] == list(range(pub.sent["strip"]))  # nothing lost
    assert got[-1].header["counters"]["subscriber_stalls"] == pub.subscriber_stalls
    stalled.close(0)
    reader.close()
    pub.close()


def test_a_subscriber_that_left_is_not_counted():
    pub = ZmqPublisher("tcp://127.0.0.1:*", "lossless")
    gone = StripSubscriber(pub.endpoint)
    assert pub.wait_for_subscribers(1, timeout_s=10)
    gone.close()
    time.sleep(0.2)  # its unsubscription travels
    assert not pub.wait_for_subscribers(1, timeout_s=0.5) and pub.subscribers == 0
    pub.close()


def test_hurry_ends_a_lossless_wait_at_once():
    pub = ZmqPublisher("tcp://127.0.0.1:*", "lossless", hwm_messages=2, stall_timeout_s=60)
    stalled = zmq.Context.instance().socket(zmq.SUB)
    stalled.setsockopt(zmq.RCVHWM, 2)
    stalled.setsockopt(zmq.RCVBUF, 1024)
    stalled.setsockopt(zmq.SUBSCRIBE, b"")
    stalled.connect(pub.endpoint)
    assert pub.wait_for_subscribers(1, timeout_s=10)
    hurried = []

    def hurry():
        hurried.append(time.perf_counter())
        pub.hurry()

    threading.Timer(0.3, hurry).start()
    for _ in range(2000):  # fills every buffer on the way, then would wait 60 s
        pub.send("stats", {"x": "y" * 1000})
    # Timed from the hurry, not from the first send: 2,000 sends took 3.8 s beside a second
    # test run.  Without the hurry the wait is 60 s.
    assert time.perf_counter() - hurried[0] < 10.0 and pub.subscriber_stalls == 1
    stalled.close(0)
    pub.close()


def test_keygen_keeps_the_secret_private_and_refuses_to_overwrite(tmp_path):
    assert main(["keygen", str(tmp_path)]) == 0
    secret = tmp_path / "rtsar.key_secret"
    assert secret.stat().st_mode & 0o777 == 0o600
    before = secret.read_bytes()
    assert main(["keygen", str(tmp_path)]) == 2 and secret.read_bytes() == before
    assert main(["keygen", str(tmp_path), "--force"]) == 0 and secret.read_bytes() != before


def test_a_publisher_with_client_keys_admits_only_those_clients(tmp_path):
    server, known, stranger = (tmp_path / d for d in ("server", "known", "stranger"))
    for d in (server, known, stranger):
        assert main(["keygen", str(d)]) == 0
    allowed = tmp_path / "allowed"
    allowed.mkdir()
    (allowed / "known.key").write_bytes((known / "rtsar.key").read_bytes())
    pub = ZmqPublisher(
        "tcp://127.0.0.1:*",
        "drop",
        curve_secret_key=server / "rtsar.key_secret",
        curve_clients=allowed,
    )
    ok = StripSubscriber(pub.endpoint, server / "rtsar.key", known / "rtsar.key_secret")
    no = StripSubscriber(pub.endpoint, server / "rtsar.key", stranger / "rtsar.key_secret")
    anon = StripSubscriber(pub.endpoint, server / "rtsar.key")  # an ephemeral key pair
    assert pub.wait_for_subscribers(1, timeout_s=10)
    time.sleep(0.3)
    pub.send("stats", {"hello": 1})
    assert ok.recv(5.0).header == {"hello": 1}
    assert no.recv(0.3) is None and anon.recv(0.3) is None
    assert pub.subscribers == 1
    for s in (ok, no, anon, pub):
        s.close()


def test_an_invalid_endpoint_is_one_error_without_a_warning_first():
    """From a cold review: `--endpoint garbage` warned "publishing … without encryption" and
    then said the address was invalid; the warning now comes once the socket is bound."""
    warned = []
    with pytest.raises(ValueError, match="cannot bind garbage"):
        ZmqPublisher("garbage", warn=warned.append)
    assert warned == []


def _stalled_subscriber(endpoint):
    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.setsockopt(zmq.RCVHWM, 20)
    sub.setsockopt(zmq.RCVBUF, 4096)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.connect(endpoint)
    return sub


def _drain(sub) -> list[int]:
    seen = []
    while sub.poll(500):
        seen.append(json.loads(sub.recv_multipart()[1])["seq"])
    return seen


def test_a_cut_off_subscriber_that_never_reads_again_misses_exactly_what_is_counted():
    """Issue 29: the run said 294 strips were missed by a stalled subscriber that missed 2,404.
    ZeroMQ leaves a cut-off subscriber out of delivery silently, also after lossless delivery
    is tried again, and only the messages sent in drop mode were counted (752 of 1,881 here
    before).  Every message from the cut-off on counts now: exactly what it missed."""
    pub = ZmqPublisher("tcp://127.0.0.1:*", "lossless", hwm_messages=50, stall_timeout_s=0.3)
    sub = _stalled_subscriber(pub.endpoint)
    assert pub.wait_for_subscribers(1, timeout_s=10)
    lines = np.zeros((16, 64), np.complex64)
    t0, sent = time.perf_counter(), 0
    while time.perf_counter() - t0 < 2.5:  # two probes of lossless delivery after the cut-off
        pub.send("strip", {"seq": sent}, lines)
        sent += 1
        time.sleep(0.001)
    missed = sent - len(_drain(sub))
    assert pub.subscriber_stalls == 1 and missed > 0
    assert pub.counters()["messages_missed_by_stalled"] == missed
    sub.close(0)
    pub.close()


def test_what_a_cut_off_subscriber_that_reads_again_missed_is_never_more_than_counted():
    """One that reads again after a while misses the messages from its cut-off to then; the
    publisher cannot see when that is (no sign from ZeroMQ), so its count is the most it can
    have missed, never less (it was 819 for 1,090 missed before)."""
    pub = ZmqPublisher("tcp://127.0.0.1:*", "lossless", hwm_messages=50, stall_timeout_s=0.3)
    sub = _stalled_subscriber(pub.endpoint)
    assert pub.wait_for_subscribers(1, timeout_s=10)
    seen, reading = [], threading.Event()

    def read():
        reading.wait()
        seen.extend(_drain(sub))

    reader = threading.Thread(target=read)
    reader.start()
    lines = np.zeros((16, 64), np.complex64)
    t0, sent = time.perf_counter(), 0
    while time.perf_counter() - t0 < 3.0:
        if time.perf_counter() - t0 > 1.8:
            reading.set()  # it reads again, 1.5 s after its cut-off
        pub.send("strip", {"seq": sent}, lines)
        sent += 1
        time.sleep(0.001)
    reader.join(10)
    missed = sent - len(seen)
    assert missed > 0 and seen[-1] == sent - 1  # it missed some, and reads again to the end
    assert pub.counters()["messages_missed_by_stalled"] >= missed
    sub.close(0)
    pub.close()


def test_the_default_endpoint_comes_from_rtsar_endpoint(tmp_path):
    """$RTSAR_ENDPOINT sets the default endpoint (the suite sets its own free port in conftest,
    so a demo on 5555 beside it does not fail tests); a child process sees it in --help."""
    import os
    import subprocess
    import sys

    from rtsar.sinks.endpoint import DEFAULT_ENDPOINT

    assert DEFAULT_ENDPOINT == os.environ["RTSAR_ENDPOINT"] != "tcp://127.0.0.1:5555"
    env = dict(os.environ, RTSAR_ENDPOINT="tcp://127.0.0.1:6123", COLUMNS="200")
    out = subprocess.run(
        [sys.executable, "-m", "rtsar", "subscribe", "--help"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        check=True,
    ).stdout
    assert "default tcp://127.0.0.1:6123" in out


def test_a_strip_header_encodes_its_config_once_and_reads_back_whole(monkeypatch):
    """The config (one dict for the stream) is encoded once, not in every strip's header; the
    header a subscriber parses is the same object either way."""
    import json
    import types

    from rtsar.presets import preset
    from rtsar.sinks import publish

    config = preset("tiny").to_dict()
    me = types.SimpleNamespace(_config_obj=None, _config_json="")
    calls = []
    real = json.dumps
    monkeypatch.setattr(publish.json, "dumps", lambda o: calls.append(o) or real(o))
    for seq in range(3):
        header = {"format": "rtsar-strip", "seq": seq, "config": config, "counters": {"a": 1}}
        text = publish.ZmqPublisher._encode(me, header)
        assert json.loads(text) == header
    assert sum(1 for o in calls if o is config) == 1
    assert json.loads(publish.ZmqPublisher._encode(me, {"config": config})) == {"config": config}
    assert json.loads(publish.ZmqPublisher._encode(me, {"x": 1})) == {"x": 1}


def test_a_strip_message_encodes_the_stream_s_fields_once_and_reads_back_as_its_header(
    monkeypatch,
):
    """The header of a strip message is strip_header's (every field, the same values), its
    stream's fixed fields encoded once per stream info: again for a new info (the pipeline
    replaces its info when the first shot anchors the stream), and the collection start,
    set on the info once the first shot came, read from each strip's own fields."""
    from dataclasses import replace

    from rtsar.sinks import wire
    from rtsar.stream.strips import LineBlock, StreamInfo, StripAssembler

    cfg = preset("tiny")
    info = StreamInfo("s1", cfg, "test", "numpy", np.arange(4.0), 0.0, 0.0)
    sent, fixed = [], []
    pub = ZmqPublisher("inproc://strip-header-once", "drop")
    monkeypatch.setattr(pub, "send", lambda topic, header, payload: sent.append(header))
    real = wire.strip_fixed_fields
    monkeypatch.setattr(publish, "strip_fixed_fields", lambda i: fixed.append(i) or real(i))
    strips = StripAssembler(info)
    try:
        for k, stream in enumerate((info, info, replace(info, start_along_track_m=5.0))):
            if k == 1:
                stream.first_shot_at(100.0)  # the collection start: set once, on this info
            strips.info = stream
            flags = np.array([False, k == 2])
            strips.add(LineBlock(2 * k, np.ones((2, 4), np.complex64), np.zeros(2),
                                 np.zeros(2), flags))  # fmt: skip
            strip, _ = strips.take(2, {"pulses_received": k})
            pub.strip(strip, stream)
            header = json.loads(sent[-1])
            expect = json.loads(json.dumps(wire.strip_header(strip, stream)))
            assert header.pop("publish_unix_s") <= expect.pop("publish_unix_s")
            assert header == expect
    finally:
        pub.close()
    assert len(fixed) == 2  # once for the first info, once for its replacement
    assert json.loads(sent[1])["collection_start_utc"] is not None


@pytest.mark.parametrize("delivery, looks", [("drop", 1), ("lossless", 5)])
def test_dropping_delivery_reads_subscriptions_at_most_every_poll_period(
    monkeypatch, delivery, looks
):
    """Dropping delivery reads the subscriptions at most every POLL_EVERY_S (a look that finds
    none costs a raised zmq.Again per strip); lossless reads them at every send (its cut-off
    rule needs the count)."""
    monkeypatch.setattr(publish, "POLL_EVERY_S", 60.0)
    pub = ZmqPublisher("tcp://127.0.0.1:*", delivery)
    try:
        seen = []
        monkeypatch.setattr(pub, "_poll_subscriptions", lambda *a: seen.append(1))
        for _ in range(5):
            pub.send("stats", {"n": 1})
        assert len(seen) == looks
    finally:
        pub.close()


def test_an_endpoint_in_use_names_the_ways_out():
    # A new user's trial: a second `rtsar run` said only "Address already in use".
    first = ZmqPublisher("tcp://127.0.0.1:*")
    try:
        said = "in use.*; another program publishes there: give --endpoint"
        with pytest.raises(ValueError, match=said):
            ZmqPublisher(first.endpoint)
    finally:
        first.close()


def test_a_terminal_status_line_fits_the_terminal_and_clears_the_rest(monkeypatch):
    import os
    import shutil

    from rtsar.app.progress import terminal_line

    monkeypatch.setattr(shutil, "get_terminal_size", lambda *a: os.terminal_size((80, 24)))
    line = terminal_line("t=   1.0 s  " + "x" * 150)
    assert line.startswith("\r") and line.endswith("\x1b[K")
    assert len(line) - len("\r\x1b[K") == 79  # one column spare: no wrap at the edge
    assert terminal_line("short") == "\rshort\x1b[K"
