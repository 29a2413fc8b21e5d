"""Which rtsar this is: the release number and the git commit it was made from.

Two sources, the first that answers:

1. the git checkout this file lives in (running from a clone, or an editable install
   ``pip install -e .``): asked at the moment, so it follows every new commit and says when
   the working tree has uncommitted changes;
2. ``rtsar/_build_commit.json``, written by ``tools/build_backend.py`` when a wheel was built
   from a checkout (``pip install .``): the commit of that build.

Anything else (a wheel built without git) says the commit is unknown.  Imports nothing of
rtsar, so the build backend can load it by path.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import asdict, dataclass
from pathlib import Path

RELEASE = "0.1.0"
ROOT = Path(__file__).resolve().parents[1]  # the checkout, where rtsar runs from a clone
BUILD_FILE = Path(__file__).with_name("_build_commit.json")


@dataclass(frozen=True)
class Commit:
    sha: str  # abbreviated (12 hex digits)
    date: str  # commit date, YYYY-MM-DD
    dirty: bool  # tracked files differed from the commit

    def describe(self) -> str:
        changes = ", with uncommitted changes" if self.dirty else ""
        return f"git {self.sha} of {self.date}{changes}"


def _git(root: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(
            ["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10
        )
    except (OSError, subprocess.SubprocessError):
        return None  # no git, or it hung
    return done.stdout.strip() if done.returncode == 0 else None


def is_checkout(root: Path) -> bool:
    """``root`` is rtsar's own git checkout (a .git folder, or a worktree's .git file)."""
    project = root / "pyproject.toml"
    return (
        (root / ".git").exists()
        and project.is_file()
        and 'name = "rtsar"' in project.read_text(encoding="utf-8", errors="replace")
    )


def git_commit(root: Path) -> Commit | None:
    """The checkout's HEAD, or None where ``root`` is no checkout or git cannot tell."""
    if not is_checkout(root):
        return None
    head = _git(root, "log", "-1", "--format=%h %cs", "--abbrev=12")
    if not head:
        return None
    sha, date = head.split()
    status = _git(root, "status", "--porcelain", "--untracked-files=no")
    return Commit(sha, date, bool(status))


def built_commit(path: Path = BUILD_FILE) -> Commit | None:
    """The commit recorded when this rtsar was built (None: no record, or not one of ours)."""
    try:
        values = json.loads(path.read_text(encoding="utf-8"))
        return Commit(str(values["sha"]), str(values["date"]), bool(values["dirty"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def write_build_file(commit: Commit | None, path: Path = BUILD_FILE) -> None:
    """Record ``commit`` for a build (tools/build_backend.py); None removes an old record."""
    if commit is None:
        path.unlink(missing_ok=True)
        return
    path.write_text(json.dumps(asdict(commit)) + "\n", encoding="utf-8")


def version_text() -> str:
    """What ``rtsar --version`` prints."""
    live = git_commit(ROOT)
    if live is not None:
        return f"rtsar {RELEASE} ({live.describe()}; the checkout at {ROOT})"
    built = built_commit()
    if built is not None:
        return f"rtsar {RELEASE} (built from {built.describe()})"
    return f"rtsar {RELEASE} (commit unknown: not installed from a git checkout)"
