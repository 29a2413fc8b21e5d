"""rtsar's build backend: setuptools' own, which first records the git commit being built.

pyproject.toml names it (``[build-system] build-backend = "build_backend"``, ``backend-path =
["tools"]``), so ``pip install .`` and ``pip install -e .`` from a clone run it: before any
build, rtsar/_build_commit.json gets the checkout's HEAD (rtsar/version.py reads it back for
``rtsar --version`` where no checkout is at hand, e.g. in site-packages).  Built from a source
tree without git (an sdist), the record it carries is kept; in a checkout whose commit git cannot
tell, an old record is removed rather than trusted.  Every PEP 517 hook is setuptools'.

Why not setuptools-scm: it derives the version number from tags (this repository has none, so
0.1.devN) and an editable install keeps the commit of its install; rtsar keeps its release
number and asks git at run time in a checkout.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F403  (every hook, re-exported unchanged)

ROOT = Path(__file__).resolve().parents[1]


def _version_module():
    """rtsar/version.py by path: the build environment has none of rtsar's dependencies."""
    name = "_rtsar_version"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "rtsar" / "version.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # before running it: dataclasses look their module up
        spec.loader.exec_module(module)
    return sys.modules[name]


def record_commit(root: Path = ROOT) -> None:
    """Write (or, in a checkout git cannot read, remove) rtsar/_build_commit.json."""
    version = _version_module()
    if not version.is_checkout(root):
        return  # an sdist: keep the record it was made with
    version.write_build_file(version.git_commit(root), root / "rtsar" / version.BUILD_FILE.name)


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    record_commit()
    return _setuptools.build_wheel(wheel_directory, config_settings, metadata_directory)


def build_sdist(sdist_directory, config_settings=None):
    record_commit()
    return _setuptools.build_sdist(sdist_directory, config_settings)


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    record_commit()
    return _setuptools.build_editable(wheel_directory, config_settings, metadata_directory)
