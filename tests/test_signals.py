"""Signals in the block loops of simulate and process (rtsar.app.signals): a Ctrl-C or SIGTERM
that lands in a finalizer must not be lost (a kill test saw simulate ignore 7 of 40)."""

import os
import signal
import sys

import pytest

from rtsar.app import signals


@pytest.fixture
def handlers():
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    signals.install()
    yield
    for s, h in saved.items():
        signal.signal(s, h)


class _KillsItselfWhenCollected:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)  # the handler runs inside this finalizer


def test_a_signal_inside_a_finalizer_is_not_lost_in_a_deferred_block(handlers, monkeypatch):
    # Outside a deferred block the finalizer swallows it, as Python does ("Exception ignored").
    dropped = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: dropped.append(u.exc_type))
    _KillsItselfWhenCollected()
    assert dropped == [signals.Terminated]  # reported, then dropped: nothing raised here
    # Inside, the handler only notes it and the loop's next check raises it.
    with pytest.raises(signals.Terminated):
        with signals.deferred():
            _KillsItselfWhenCollected()
            signals.check()
    signals.check()  # raised once, not twice
    assert dropped == [signals.Terminated]


def test_a_second_signal_is_raised_at_once_and_the_first_at_the_end(handlers):
    with pytest.raises(KeyboardInterrupt):
        with signals.deferred():
            os.kill(os.getpid(), signal.SIGINT)  # noted
            with pytest.raises(KeyboardInterrupt):
                os.kill(os.getpid(), signal.SIGINT)  # a second: raised here
            os.kill(os.getpid(), signal.SIGHUP)  # noted; the block's end raises it
    with pytest.raises(signals.Terminated) as info:
        with signals.deferred():
            os.kill(os.getpid(), signal.SIGHUP)
    assert signals.exit_status(info.value) == 128 + signal.SIGHUP


def test_a_ctrl_c_during_the_commands_imports_is_one_line(monkeypatch, capsys):
    """From a kill test: Ctrl-C in the second the rtsar command spends importing printed a
    KeyboardInterrupt traceback.  The console script imports the command inside its main."""
    import subprocess
    import types

    from rtsar.app import entry

    code = "import sys, rtsar.app.entry; print('rtsar.app.cli' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"  # nothing heavy before main runs

    class Importing(types.ModuleType):
        def __getattr__(self, name):
            raise KeyboardInterrupt

    monkeypatch.setitem(sys.modules, "rtsar.app.cli", Importing("rtsar.app.cli"))
    assert entry.main(["presets"]) == 130
    assert capsys.readouterr().err.strip() == "rtsar: interrupted"
