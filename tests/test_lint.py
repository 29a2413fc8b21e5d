"""ruff over the whole project (STYLE habit 9); skipped only where ruff is not installed.

ruff is looked for beside this interpreter first (a virtual environment that is not activated
still has its ruff in its bin folder), then on PATH."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def find_ruff() -> str | None:
    beside = Path(sys.executable).parent / ("ruff.exe" if sys.platform == "win32" else "ruff")
    return str(beside) if beside.is_file() else shutil.which("ruff")


RUFF = find_ruff()


@pytest.mark.skipif(RUFF is None, reason="ruff not installed (pip install .[test])")
def test_ruff_is_clean():
    out = subprocess.run(
        [RUFF, "check", "rtsar", "tests", "tools"], cwd=ROOT, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stdout + out.stderr
