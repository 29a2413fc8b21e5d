"""One command line (issue 37, item 6): the same option means the same thing in every command,
and a wrong value is answered about itself."""

import pytest

from rtsar.app.cli import build_parser, main
from rtsar.presets import PRESETS
from rtsar.sinks.endpoint import DEFAULT_ENDPOINT


@pytest.mark.parametrize("command", ["view", "subscribe"])
def test_subscribers_take_endpoint_as_an_option_like_run_and_replay(command):
    extra = ["-o", "x.h5"] if command == "subscribe" else []
    parse = build_parser(command).parse_args
    assert parse([command, *extra]).endpoint == DEFAULT_ENDPOINT
    assert parse([command, "tcp://127.0.0.1:6001", *extra]).endpoint == "tcp://127.0.0.1:6001"
    option = parse([command, "--endpoint", "tcp://127.0.0.1:6002", *extra])
    assert option.endpoint == "tcp://127.0.0.1:6002"


@pytest.mark.parametrize("command", ["run", "replay"])
def test_publishers_take_endpoint_as_an_option(command):
    argv = [command, "--endpoint", "tcp://127.0.0.1:6003"] + (
        ["r.h5"] if command == "replay" else []
    )
    assert build_parser(command).parse_args(argv).endpoint == "tcp://127.0.0.1:6003"


def test_an_unknown_preset_is_answered_about_the_preset(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["run", "--preset", "nope"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.splitlines()[-1]  # the line after the usage
    assert "--preset" in err and "nope" in err and "--serial" not in err
    assert all(name in err for name in PRESETS)


def test_an_allocation_no_check_foresaw_is_one_line_not_a_traceback(monkeypatch, capsys):
    from rtsar.app.cli import files

    def exhausted(args):
        raise MemoryError("Unable to allocate 128. GiB")

    monkeypatch.setattr(files, "cmd_presets", exhausted)  # bound when the parser is built
    assert main(["presets"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not enough memory" in err and "128. GiB" in err


@pytest.mark.parametrize("command", ["run", "replay", "process"])
def test_an_unknown_option_is_answered_with_its_commands_usage(command, capsys):
    """`rtsar run --bogus` printed the top level's usage (`rtsar [-h] [--version] COMMAND`),
    where a missing option printed the command's own."""
    given = {"run": [], "replay": ["r.h5"], "process": ["r.h5", "-o", "i.h5"]}[command]
    argv = [command, *given, "--bogus"]
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert err.startswith(f"usage: rtsar {command} ")
    assert f"rtsar {command}: error: unrecognized arguments: --bogus" in err


@pytest.mark.parametrize(
    "command", [["run"], ["replay", "r.h5"], ["process", "r.h5", "-o", "i.h5"]]
)
def test_an_unknown_option_before_the_command_is_answered_with_rtsars_usage(command, capsys):
    """`rtsar --bogus run` blamed run (`rtsar run: error: …` under run's usage): the words
    before the command are the top level's."""
    with pytest.raises(SystemExit) as stop:
        main(["--bogus", *command])
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert err.startswith("usage: rtsar [-h] [--version] COMMAND")
    assert "rtsar: error: unrecognized arguments: --bogus" in err


def test_quicklook_names_its_option_for_a_bad_dynamic_range(tmp_path, capsys):
    """From a new user's review: `quicklook --dynamic-range-db -40` said `dynamic_range_db must
    be > 0` (the Python name), after reading the image."""
    args = ["quicklook", str(tmp_path / "none.h5"), "-o", str(tmp_path / "x.png")]
    assert main([*args, "--dynamic-range-db", "-40"]) == 2
    assert "--dynamic-range-db must be > 0, got -40" in capsys.readouterr().err
