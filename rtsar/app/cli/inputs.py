"""The recordings ``process`` and ``replay`` take: rtsar's HDF5 recordings, CPHD files and
SigMF recordings (the last two need the optional extra ``formats``), chosen by file name."""

from __future__ import annotations

from pathlib import Path

from ...sinks.io import open_recording
from ...sources.formats.cphd_reader import open_cphd
from ...sources.formats.sigmf_reader import open_sigmf, sigmf_base

CPHD_SUFFIXES = (".cphd",)


def open_input(path: str | Path):
    """Open a recording by its name: ``*.cphd`` → CPHD, ``*.sigmf-meta``/``*.sigmf-data``/
    ``*.sigmf`` → SigMF, anything else → an rtsar recording (HDF5)."""
    path = Path(path)
    if path.suffix.lower() in CPHD_SUFFIXES:
        return open_cphd(path)
    if sigmf_base(path) is not None:
        return open_sigmf(path)
    return open_recording(path)
