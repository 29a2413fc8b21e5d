"""`rtsar prepare` (rtsar.app.prepare): every numba kernel module has a task, a task leaves its
kernels in numba's cache (a fresh interpreter then compiles nothing), failures are said and
give exit status 1."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from argparse import Namespace
from pathlib import Path

import pytest

from rtsar.app import prepare

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
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, task], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_task_fills_numba_cache_so_the_next_interpreter_compiles_nothing(tmp_path):
    first = _child("resampler", tmp_path)
    again = _child("resampler", tmp_path)
    assert first["compiled"] >= 1  # an empty cache: compiled here
    assert again["compiled"] == 0  # a new interpreter: loaded from the cache
    cached, total, folders = again["state"]
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
    monkeypatch.setattr(prepare, "TASKS", {"nope": prepare.Task("nope", "a group that fails")})
    monkeypatch.setattr(prepare, "KERNEL_MODULES", {})
    status = prepare.run(Namespace(workers=1, no_survey=True))
    out = capsys.readouterr().out
    assert status == 1
    assert "a group that fails: failed: ValueError: no such task" in out
    assert "not all: nope" in out


def test_prepare_refuses_no_workers():
    with pytest.raises(ValueError, match="--workers must be >= 1"):
        prepare.run(Namespace(workers=0, no_survey=True))
