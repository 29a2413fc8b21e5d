"""Under CI=true a skip is a failure (tests/ci_rule.py, which tests/conftest.py registers; issue
39, item 4): a test session of its own, with that rule as a plugin, over tests that skip at run
time, by a mark and by a module's importorskip."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

SKIPPING = {
    "test_at_run_time.py": "import pytest\n\n\ndef test_a():\n    pytest.skip('no device')\n",
    "test_by_mark.py": (
        "import pytest\n\n\n@pytest.mark.skipif(True, reason='not here')\ndef test_b():\n    pass\n"
    ),
    "test_by_import.py": (
        "import pytest\n\npytest.importorskip('no_such_module_rtsar')\n\n\ndef test_c():\n"
        "    pass\n"
    ),
}
REASONS = ("no device", "not here", "could not import 'no_such_module_rtsar'")


def session(tmp_path: Path, ci: str | None) -> subprocess.CompletedProcess:
    """The three files in one session, with the rule alone as a plugin (not this suite's
    conftest: the session takes a second, not the OpenCL survey's)."""
    for name, text in SKIPPING.items():
        (tmp_path / name).write_text(text)
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "PYTHONPATH")}
    env["PYTHONPATH"] = str(TESTS)
    if ci is not None:
        env["CI"] = ci
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "ci_rule"]
        + ["--continue-on-collection-errors", *SKIPPING],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.mark.slow
def test_a_skip_fails_under_ci_and_skips_elsewhere(tmp_path):
    done = session(tmp_path, "true")
    summary = [line for line in done.stdout.splitlines() if line.startswith(("FAILED", "ERROR"))]
    rule = "skipped under CI=true, where every test must run: "
    for name, reason in zip(SKIPPING, REASONS, strict=True):
        assert any(name in line and rule + reason in line for line in summary), done.stdout
    assert done.returncode == 1 and len(summary) == len(SKIPPING), done.stdout
    assert "skipped" not in done.stdout.splitlines()[-1], done.stdout
    done = session(tmp_path, None)
    assert done.returncode == 0, done.stdout
    assert done.stdout.splitlines()[-1].startswith(f"{len(SKIPPING)} skipped"), done.stdout
