"""Endpoints and ports are checked before a run starts (issue 36, item 11).

ZeroMQ takes ``tcp://127.0.0.1:99999`` modulo 2^16 and binds port 34463: the banner named the
port the user typed, and no subscriber given that number could ever connect.
"""

import pytest

from rtsar.app.cli import main
from rtsar.sinks.endpoint import DEFAULT_ENDPOINT, endpoint_error
from rtsar.sources.serial import SerialSource

GOOD = [
    pytest.param(DEFAULT_ENDPOINT, id="the-default"),  # no random port in the test ID
    "tcp://127.0.0.1:5555",
    "tcp://*:5555",
    "tcp://127.0.0.1:*",
    "tcp://127.0.0.1:0",
    "tcp://[::1]:65535",
    "ipc:///tmp/rtsar.sock",
    "inproc://strips",
    "ws://127.0.0.1:8080/strips",
]
BAD = [
    "tcp://127.0.0.1:99999",
    "tcp://127.0.0.1:65536",
    "tcp://127.0.0.1:-1",
    "tcp://127.0.0.1:0x10",
    "tcp://127.0.0.1",
    "tcp://:5555",
    "127.0.0.1:5555",
    "udp://127.0.0.1:5555",
    "ipc://",
    "ws://h:70000/x",
]


@pytest.mark.parametrize("endpoint", GOOD)
def test_a_sound_endpoint_passes(endpoint):
    assert endpoint_error(endpoint) is None


@pytest.mark.parametrize("endpoint", BAD)
def test_an_impossible_endpoint_is_named(endpoint):
    assert endpoint_error(endpoint)


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "--endpoint", "tcp://127.0.0.1:99999", "--duration", "1"],
        ["replay", "nothing.h5", "--endpoint", "tcp://127.0.0.1:99999"],
        ["run", "--zmq-in", "tcp://127.0.0.1:70000", "--preset", "tiny"],
        ["run", "--swath-workers", "2", "--swath-bind", "tcp://127.0.0.1:99999"],
        ["view", "tcp://127.0.0.1:99999"],
        ["subscribe", "tcp://127.0.0.1:99999"],
        ["swath-worker", "--connect", "tcp://127.0.0.1:99999"],
    ],
    ids=lambda a: " ".join(a[:2]),
)
def test_every_endpoint_option_refuses_an_impossible_port_before_start(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "99999" in err or "70000" in err
    assert "Traceback" not in err


def test_a_serial_socket_url_with_an_impossible_port_is_refused_at_once():
    with pytest.raises(ValueError, match="PORT 1-65535"):
        SerialSource("socket://127.0.0.1:99999", samples_per_shot=8, connect_timeout_s=5.0)
