"""ruff over the whole project (STYLE habit 9); skipped only where ruff is not installed."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("ruff") is None, reason="ruff not installed (pip install .[test])")
def test_ruff_is_clean():
    out = subprocess.run(
        ["ruff", "check", "rtsar", "tests", "tools"], cwd=ROOT, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stdout + out.stderr
