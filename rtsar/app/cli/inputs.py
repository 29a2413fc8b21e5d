"""The recordings ``process`` and ``replay`` take: rtsar's HDF5 recordings, CPHD files and
SigMF recordings (the last two need the optional extra ``formats``), chosen by file name."""

from __future__ import annotations

import sys
from pathlib import Path

from ...sinks.io import open_recording
from ...sources.formats.sigmf_store import sigmf_base

CPHD_SUFFIXES = (".cphd",)


def open_input(path: str | Path):
    """Open a recording by its name: ``*.cphd`` → CPHD, ``*.sigmf-meta``/``*.sigmf-data``/
    ``*.sigmf`` → SigMF, anything else → an rtsar recording (HDF5)."""
    path = Path(path)
    # Each reader loads with its format only (sarkit and sigmf take a while to import).
    if path.suffix.lower() in CPHD_SUFFIXES:
        from ...sources.formats.cphd_reader import open_cphd

        return open_cphd(path)
    if sigmf_base(path) is not None:
        from ...sources.formats.sigmf_reader import open_sigmf

        return open_sigmf(path)
    rec = open_recording(path)
    note_live_recording(rec)
    return rec


def note_live_recording(rec) -> None:
    """A recording made by ``run --record`` that lacks shots says so on stderr: cut short (its
    writer killed: complete = False) or with shots its recorder could not write."""
    attrs = rec.attrs
    if not attrs.get("recorded_live"):
        return
    if not attrs.get("complete", True):
        print(
            f"note: {rec.path} is a live recording cut short (complete = False): its "
            f"{rec.pulses} whole shots are read",
            file=sys.stderr,
        )
    dropped = int(attrs.get("record_dropped", 0))
    if dropped:
        print(
            f"note: {dropped} shots of {rec.path} were not recorded (record_dropped: pulse_flags "
            "4): zero pulses stand in their place, the live image had them",
            file=sys.stderr,
        )
