"""`rtsar --version` names the commit (issue 31): asked of git in a checkout (a clone, an editable
install), recorded by tools/build_backend.py in a built wheel (`pip install .`)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import tomllib
from tools_loader import load_tool

from rtsar.version import Commit, built_commit, git_commit, write_build_file

ROOT = Path(__file__).resolve().parents[1]
GIT = shutil.which("git")


def head(root: Path) -> str | None:
    if GIT is None:
        return None
    done = subprocess.run(
        [GIT, "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True
    )
    return done.stdout.strip() if done.returncode == 0 else None


def test_rtsar_version_names_the_commit_it_was_installed_from(tmp_path):
    """From this checkout: the commit git reports, whether rtsar runs from the clone (editable)
    or from a wheel built from it (CI's `pip install .`)."""
    sha = head(ROOT)
    if sha is None:
        pytest.skip("the tests run outside a git checkout: there is no commit to name")
    done = subprocess.run(
        [sys.executable, "-m", "rtsar", "--version"], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0 and done.stdout.startswith("rtsar 0.1.0 (")
    assert f"git {sha} of " in done.stdout, done.stdout


def git_repo(tmp_path: Path) -> Path:
    """A one-commit checkout shaped like rtsar's (its pyproject.toml, an rtsar/ folder)."""
    if GIT is None:
        pytest.skip("git is not installed")
    root = tmp_path / "clone"
    (root / "rtsar").mkdir(parents=True)
    (root / "pyproject.toml").write_text('[project]\nname = "rtsar"\n')
    (root / "rtsar" / "x.py").write_text("A = 1\n")
    env = ["-c", "user.name=t", "-c", "user.email=t@example.org", "-c", "commit.gpgsign=false"]
    for args in (["init", "-q"], ["add", "."], [*env, "commit", "-q", "-m", "one"]):
        subprocess.run([GIT, "-C", str(root), *args], check=True, capture_output=True)
    return root


def test_the_build_records_the_checkouts_commit_and_its_changes(tmp_path):
    backend = load_tool("build_backend")
    root = git_repo(tmp_path)
    record = root / "rtsar" / "_build_commit.json"
    backend.record_commit(root)
    commit = built_commit(record)
    assert commit == git_commit(root) and commit.sha == head(root) and not commit.dirty
    (root / "rtsar" / "x.py").write_text("A = 2\n")
    backend.record_commit(root)
    assert built_commit(record).dirty


def test_a_build_outside_a_checkout_keeps_the_record_it_came_with(tmp_path):
    backend = load_tool("build_backend")
    sdist = tmp_path / "rtsar-0.1.0"
    (sdist / "rtsar").mkdir(parents=True)
    (sdist / "pyproject.toml").write_text('[project]\nname = "rtsar"\n')
    record = sdist / "rtsar" / "_build_commit.json"
    write_build_file(Commit("0123456789ab", "2026-01-02", False), record)
    backend.record_commit(sdist)
    assert built_commit(record) == Commit("0123456789ab", "2026-01-02", False)


def test_a_record_that_is_not_ours_is_no_commit(tmp_path):
    path = tmp_path / "_build_commit.json"
    assert built_commit(path) is None
    path.write_text("{not json")
    assert built_commit(path) is None
    write_build_file(Commit("0123456789ab", "2026-01-02", True), path)
    assert built_commit(path).dirty
    write_build_file(None, path)
    assert not path.exists()


def test_pip_builds_through_the_backend_with_every_hook():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    system = config["build-system"]
    assert system["build-backend"] == "build_backend" and system["backend-path"] == ["tools"]
    assert "_build_commit.json" in config["tool"]["setuptools"]["package-data"]["rtsar"]
    backend = load_tool("build_backend")
    for hook in (
        "build_wheel",
        "build_sdist",
        "build_editable",
        "get_requires_for_build_wheel",
        "get_requires_for_build_sdist",
        "get_requires_for_build_editable",
        "prepare_metadata_for_build_wheel",
        "prepare_metadata_for_build_editable",
    ):
        assert callable(getattr(backend, hook)), hook
