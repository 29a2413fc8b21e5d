"""The optional extra ``formats`` (sarkit, sarpy, sigmf): one clear error where it is missing."""

from __future__ import annotations

INSTALL_HINT = 'pip install "rtsar[formats]"'


def require_formats(module, what: str) -> None:
    """RuntimeError naming the install command when an optional module imported as None."""
    if module is None:
        raise RuntimeError(f"{what} needs the optional formats packages: {INSTALL_HINT}")
