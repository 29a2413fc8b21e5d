"""Where rtsar's OpenCL kernel sources are: one ``.cl`` file per stage.

They live in the top-level ``kernels/`` folder of a source checkout; ``pip install`` ships the
same folder as the package ``rtsar.kernels``.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

__all__ = ["kernel_path", "kernel_source", "kernels_dir"]


def kernels_dir():
    """Folder holding the ``.cl`` sources (a ``Traversable``; a ``Path`` in a source checkout).

    The installed package ``rtsar.kernels`` is preferred; without it (a checkout on
    ``sys.path``) the top-level ``kernels/`` folder next to the ``rtsar`` package is used.
    """
    try:
        folder = importlib.resources.files("rtsar.kernels")
        if folder.joinpath("lens.cl").is_file():
            return folder
    except ModuleNotFoundError:
        pass
    checkout = Path(__file__).resolve().parents[2] / "kernels"
    if (checkout / "__init__.py").is_file():
        return checkout
    raise FileNotFoundError(
        "rtsar's OpenCL kernels were not found: neither the package rtsar.kernels nor the "
        f"folder {checkout} exists (reinstall rtsar, or run from a complete source checkout)"
    )


def kernel_path(name: str):
    """The kernel file ``name`` (e.g. ``"lens.cl"``); FileNotFoundError if it is missing."""
    path = kernels_dir().joinpath(name)
    if not path.is_file():
        raise FileNotFoundError(f"OpenCL kernel file {name!r} not found in {kernels_dir()}")
    return path


def kernel_source(name: str) -> str:
    """Text of the kernel file ``name``."""
    return kernel_path(name).read_text(encoding="utf-8")
