"""The suite runs with and without pytest-xdist: ``tests/conftest.py`` implements xdist's hooks
(the worker count, worksteal scheduling) as optional hooks, so ``-p no:xdist`` (one process,
as the mutation probe runs it: tools/mutation_probe.py) is not refused as an unknown hook."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_suite_runs_without_xdist():
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist"]
        + ["tests/test_version.py"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert " passed" in done.stdout.splitlines()[-1], done.stdout[-2000:]
