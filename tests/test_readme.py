"""The README's commands, run as written where that is quick (issue 18: "the README's commands all
run as written").

Every command in the README's "Commands" table gets ``--help``; every command line of the
README's shell blocks (```sh, or unlabelled blocks of commands) is classified by RULES below:
run for real in a temporary folder (outputs there, ``rtsar run`` shortened with ``--duration``),
run with ``--help`` only, or skipped — each with its reason.  A command line no rule knows fails
the test, so a new README command gets a decision here.
"""

import re
import shlex
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from rtsar.app.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")

# (pattern on the command line, what to do, why).  First match wins.
RULES = [
    (r"^python3 -m venv|pip install", "skip", "installs a venv: CI does exactly this"),
    (r"-m pytest", "skip", "the test suite itself"),
    (r"^rtsar run\b(?!.*--serial)", "run", "live demo, shortened: --duration 0.5, 289 lines"),
    (r"^rtsar run .*--serial", "help", "needs an instrument (tests/test_serial.py runs it)"),
    (r"^rtsar (view|subscribe)\b", "help", "needs a live publisher (tests/test_publish.py)"),
    (r"^rtsar (simulate|process|quicklook) ", "run", "quick on the README's scenes"),
    (r"^rtsar measure ", "run", "quick on the SAL demo's image (~2 s)"),
    (r"^rtsar (bench|tradeoff|table1|demo|replay|batch)\b", "help", "a minute or more"),
    (r"^rtsar (spot-simulate|spotlight|projective)\b", "help", "run by tests/test_spot*.py"),
    (r"^rtsar (export|swath-worker)\b", "help", "run by their own tests"),
    (r"^python tools/make_figures\.py", "help", "about a minute (it runs the live demo)"),
    (r"^python tools/sim_cost\.py", "run", "quick with --pulses"),
    (r"^python tools/fake_instrument\.py", "help", "serves until stopped"),
    (r"^python tools/", "help", "a measurement script"),
]


def shell_commands(text: str) -> list[str]:
    """Command lines of the fenced blocks that hold commands (``sh``/unlabelled), split at &&,
    comments removed; blocks in other languages (toml, python) are not commands."""
    out = []
    for lang, body in re.findall(r"^```(\w*)\n(.*?)^```", text, flags=re.S | re.M):
        if lang not in ("", "sh", "bash", "console"):
            continue
        lines = [ln.split("  #")[0].split(" # ")[0].strip() for ln in body.splitlines()]
        lines = [ln for ln in lines if ln and not ln.startswith("#")]
        if not lines or not all(re.match(r"(rtsar|python3?|\.venv/|pip)\b", ln) for ln in lines):
            continue  # a diagram or a listing, not commands
        for ln in lines:
            for part in ln.split("&&"):
                # `.venv/bin/rtsar` is `rtsar` of the activated venv (README "Two commands")
                part = re.sub(r"^\.venv/bin/(rtsar|python)\b", r"\1", part.strip())
                out += [part] if part else []
    return out


def table_commands(text: str) -> list[str]:
    """The subcommands named in the Commands table: rows `| \\`rtsar NAME …\\` | … |`."""
    section = text.split("\n## Commands", 1)[1].split("\n## ", 1)[0]
    return sorted(set(re.findall(r"^\| `rtsar ([a-z0-9-]+)", section, flags=re.M)))


def free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{s.getsockname()[1]}"


def rule_for(line: str):
    for pattern, action, why in RULES:
        if re.search(pattern, line):
            return action, why
    return None, None


COMMANDS = shell_commands(README)


def test_the_readme_has_commands_to_check():
    assert any(c.startswith("rtsar run") for c in COMMANDS)
    assert {"run", "process", "simulate", "quicklook", "view"} <= set(table_commands(README))


@pytest.mark.parametrize("name", table_commands(README))
def test_every_command_of_the_table_has_help(name, capsys):
    with pytest.raises(SystemExit) as done:
        main([name, "--help"])
    assert done.value.code == 0 and capsys.readouterr().out.startswith(f"usage: rtsar {name}")


def test_every_readme_command_line_is_classified():
    unknown = [c for c in COMMANDS if rule_for(c)[0] is None]
    assert not unknown, f"README commands without a rule in tests/test_readme.py: {unknown}"


def _run(line: str, tmp_path: Path) -> None:
    argv = shlex.split(line)
    if argv[0] == "python":  # a tools/ script, with this interpreter
        if "sim_cost.py" in line and "--pulses" not in argv:
            argv += ["--pulses", "1600"]
        done = subprocess.run(
            [sys.executable, str(ROOT / argv[1]), *argv[2:]],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 0, f"{line}: {done.stderr[-2000:]}"
        return
    args = argv[1:]
    if args[0] == "run":
        args = args + ["--duration", "0.5", "--endpoint", free_endpoint()]
    assert main(args) == 0, line


def _help(line: str, tmp_path: Path) -> None:
    argv = shlex.split(line)
    if argv[0] == "python":
        done = subprocess.run(
            [sys.executable, str(ROOT / argv[1]), "--help"], capture_output=True, text=True
        )
        assert done.returncode == 0 and "usage" in done.stdout, f"{line} --help failed"
        return
    with pytest.raises(SystemExit) as done:
        main([argv[1], "--help"])
    assert done.value.code == 0, line


def test_the_readme_commands_run_as_written(tmp_path, monkeypatch, capsys):
    """In README order, in one folder (a block's later commands read what earlier ones wrote)."""
    monkeypatch.chdir(tmp_path)
    ran = []
    for line in COMMANDS:
        action, _ = rule_for(line)
        if action == "run":
            _run(line, tmp_path)
            ran.append(line)
        elif action == "help":
            _help(line, tmp_path)
        capsys.readouterr()
    assert any(c.startswith("rtsar run") for c in ran) and any("quicklook" in c for c in ran)
    for png in re.findall(r"-o (\S+\.png)", " ".join(ran)):
        assert (tmp_path / png).stat().st_size > 1000
