"""`rtsar prepare` (rtsar.app.prepare): every numba kernel module has a group, a group leaves
its kernels in numba's cache (a fresh interpreter then compiles nothing), failures and dead
processes are said and give exit status 1, Ctrl-C stops it all; one survey at a time."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from argparse import Namespace
from pathlib import Path

import pytest

from rtsar.app import prepare
from rtsar.child import module_argv
from rtsar.lens.cache import measuring

ROOT = Path(__file__).resolve().parents[1]


def test_every_module_with_numba_kernels_has_a_task():
    """A module that gains a numba kernel must be added to KERNEL_MODULES (else its first run
    still compiles after `rtsar prepare`): the sources are scanned, not the list trusted."""
    found = set()
    for path in (ROOT / "rtsar").rglob("*.py"):
        if re.search(r"@numba\.(njit|jit)\b|@njit\b", path.read_text(encoding="utf-8")):
            rel = path.relative_to(ROOT).with_suffix("")
            found.add(".".join(rel.parts))
    assert found == set(prepare.KERNEL_MODULES)
    assert set(prepare.KERNEL_MODULES.values()) <= set(prepare.TASKS)
    with pytest.raises(ValueError, match="no such task"):
        prepare._compile("nope")


_CHILD = """
import json, sys
from rtsar.app.prepare import run_task, kernel_cache_state
name, seconds, compiled, error = run_task(sys.argv[1])
assert error is None, error
print(json.dumps({"compiled": compiled, "state": kernel_cache_state()}))
"""


def _child(task: str, cache: Path) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    cmd = [sys.executable, "-c", _CHILD, task]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True, timeout=300)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_task_fills_numba_cache_so_the_next_interpreter_compiles_nothing(tmp_path):
    first = _child("resampler", tmp_path)
    again = _child("resampler", tmp_path)
    assert first["compiled"] >= 1  # an empty cache: compiled here
    assert again["compiled"] == 0  # a new interpreter: loaded from the cache
    cached, total, folders, missing = again["state"]
    assert len(missing) == total - cached and "rtsar.ccd.tiled.run_blocks" in missing
    assert total >= 18 and 1 <= cached < total  # the resampler's kernel only
    assert all(str(tmp_path) in f for f in folders)


def test_prepare_says_each_group_and_the_cache_state(monkeypatch, capsys):
    monkeypatch.setattr(prepare, "TASKS", {"resampler": prepare.TASKS["resampler"]})
    monkeypatch.setattr(prepare, "KERNEL_MODULES", {"rtsar.focus.resample": "resampler"})
    status = prepare.run(Namespace(workers=1, no_survey=True))
    out = capsys.readouterr().out
    assert status == 0, out
    assert "the band-limited resampler" in out and ("compiled" in out or "cache already" in out)
    assert "kernels: 1 of 1 in numba's cache" in out
    assert "prepared in" in out and "not all" not in out


def test_a_group_that_fails_is_said_and_the_status_is_1(monkeypatch, capsys):
    monkeypatch.setattr(prepare, "TASKS", {"nope": "a group that fails"})
    monkeypatch.setattr(prepare, "KERNEL_MODULES", {})
    status = prepare.run(Namespace(workers=1, no_survey=True))
    out = capsys.readouterr().out
    assert status == 1
    assert "a group that fails: failed: ValueError: no such task" in out
    assert "not all: nope" in out


def test_a_group_whose_process_dies_is_a_failed_group_not_a_hang(monkeypatch, capsys):
    """A worker killed (the OOM killer, a crash in LLVM) gives its group's line and status 1;
    the command does not wait for an answer that will never come."""
    monkeypatch.setattr(prepare, "TASKS", {"gone": "a group killed"})
    monkeypatch.setattr(prepare, "KERNEL_MODULES", {})

    def start(name):
        out = tempfile.TemporaryFile(mode="w+")
        die = "import os, signal; os.kill(os.getpid(), signal.SIGKILL)"
        return subprocess.Popen([sys.executable, "-c", die], stdout=out, text=True), out

    monkeypatch.setattr(prepare, "_start", start)
    t0 = time.perf_counter()
    status = prepare.run(Namespace(workers=2, no_survey=True))
    out = capsys.readouterr().out
    assert status == 1 and time.perf_counter() - t0 < 60
    assert "a group killed: failed: its process ended without an answer (killed by signal 9" in out


def test_ctrl_c_stops_prepare_and_its_processes(tmp_path):
    """SIGINT to the whole process group (a terminal's Ctrl-C) during a cold compile: exit
    status 130 within seconds, no group's process left."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "nc"), RTSAR_CACHE_DIR=str(tmp_path))
    cmd = [sys.executable, "-m", "rtsar", "prepare", "--no-survey"]
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True, start_new_session=True)
    line = p.stdout.readline()  # the first line: the groups are starting
    assert "compiling rtsar's numba kernels" in line
    time.sleep(1.0)
    os.killpg(p.pid, signal.SIGINT)
    t0 = time.perf_counter()
    p.communicate(timeout=60)
    assert p.returncode == 130 and time.perf_counter() - t0 < 15
    time.sleep(0.2)
    left = subprocess.run(["pgrep", "-g", str(p.pid)], capture_output=True, text=True).stdout
    assert not left.strip(), f"processes left in the group: {left}"


def test_every_group_compiles_its_modules_kernels(tmp_path):
    """The whole of `rtsar prepare --no-survey` (README's command 1 runs it) from an empty numba
    cache: every group succeeds and every kernel of KERNEL_MODULES is in the cache after, so a
    module mapped to a group that does not run its kernels fails here (30-45 s of CPU)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "nc"), RTSAR_CACHE_DIR=str(tmp_path))
    cmd = [sys.executable, "-m", "rtsar", "prepare", "--no-survey"]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    cached = re.search(r"kernels: (\d+) of (\d+) in numba's cache", done.stdout)
    assert cached and cached.group(1) == cached.group(2) and int(cached.group(2)) >= 18
    assert done.stdout.count(" kernels compiled, ") + done.stdout.count(" kernel compiled, ") == (
        len(prepare.TASKS)
    )


def test_one_survey_at_a_time_on_a_machine(tmp_path, monkeypatch):
    """A process that finds another measuring (the lock of rtsar.lens.cache.measuring) says so
    once and waits for it."""
    monkeypatch.setenv("RTSAR_CACHE_DIR", str(tmp_path))
    hold = (
        "import sys, time; from rtsar.lens.cache import measuring\n"
        "with measuring('x.json'):\n    print('held', flush=True); time.sleep(1.0)\n"
    )
    other = subprocess.Popen(
        [sys.executable, "-c", hold], env=dict(os.environ), stdout=subprocess.PIPE, text=True
    )
    assert other.stdout.readline().strip() == "held"
    told = []
    t0 = time.perf_counter()
    with measuring("x.json", lambda: told.append(1)):
        waited = time.perf_counter() - t0
    other.wait(timeout=30)
    assert told == [1] and waited > 0.3
    with measuring("x.json", lambda: told.append(2)):  # free now: no wait, nothing said
        pass
    assert told == [1]


def test_prepare_refuses_no_workers():
    with pytest.raises(ValueError, match="--workers must be >= 1"):
        prepare.run(Namespace(workers=0, no_survey=True))


def test_children_run_this_rtsar_not_a_clone_in_the_current_folder(tmp_path):
    """README's command 1 runs from the clone: a child started there must import the rtsar its
    parent runs (rtsar.child), not the folder's `rtsar/` (there, `rtsar prepare` compiled the
    clone's kernels and found none in the installed cache: exit status 1)."""
    fake = tmp_path / "rtsar"
    fake.mkdir()
    (fake / "__init__.py").write_text("")
    (fake / "__main__.py").write_text("print('the folder s rtsar')\n")
    done = subprocess.run(
        module_argv("rtsar", "--version"), cwd=tmp_path, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "the folder s rtsar" not in done.stdout and done.stdout.startswith("rtsar ")
    done = subprocess.run(
        module_argv("rtsar.app.prepare", "resampler"), cwd=tmp_path, capture_output=True,
        text=True, env=dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "nc")), timeout=300,
    )  # fmt: skip
    answer = json.loads(done.stdout.strip().splitlines()[-1])
    assert answer["error"] is None and answer["compiled"] >= 1
    assert not list(fake.rglob("*.nbi"))  # nothing compiled into the folder's rtsar


def test_every_child_process_is_started_through_module_argv():
    """No `python -m rtsar…` started from the current folder is left in the sources."""
    offenders = [
        str(p.relative_to(ROOT))
        for p in (ROOT / "rtsar").rglob("*.py")
        if re.search(r"sys\.executable,\s*\"-m\"", p.read_text(encoding="utf-8"))
    ]
    assert not offenders, offenders
