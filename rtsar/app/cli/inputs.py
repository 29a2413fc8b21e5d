"""The recordings ``process`` and ``replay`` take: rtsar's HDF5 recordings, CPHD files and
SigMF recordings (the last two need the optional extra ``formats``), chosen by file name; a
scene's targets outside the range window, said."""

from __future__ import annotations

import sys
from pathlib import Path

from ...lens import range_axis_m
from ...sinks.exports.screen import time_order_note
from ...sinks.io import open_recording
from ...sources.formats.sigmf_store import sigmf_base

CPHD_SUFFIXES = (".cphd",)


def open_input(path: str | Path, note_times: bool = True):
    """Open a recording by its name: ``*.cphd`` → CPHD, ``*.sigmf-meta``/``*.sigmf-data``/
    ``*.sigmf`` → SigMF, anything else → an rtsar recording (HDF5).  Shot times that do not
    increase are said in one warning (``note_times``; docs/pages/reference/faults.md)."""
    rec = _open(Path(path))
    for note in getattr(rec, "notes", ()):  # what a reader had to say (a CPHD's track)
        print(f"rtsar: warning: {note}", file=sys.stderr)
    if note_times:
        note_time_order(rec)
    return rec


def _open(path: Path):
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


def note_time_order(rec) -> None:
    """One warning where a recording's shot times step back or repeat: the image goes by pulse
    number and position, not by time, so it is unchanged, but the times cannot be trusted (a CPHD
    export refuses them: TxTime must increase)."""
    note = time_order_note(rec)
    if note:
        print(
            f"rtsar: warning: {note}: the image does not use them (it goes by pulse_index and "
            "position); a CPHD export refuses them",
            file=sys.stderr,
        )


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


def warn_outside_swath(scene) -> None:
    """Say which targets of a scene lie outside the range window (they will not be imaged)."""
    outside = scene.targets_outside_swath()
    if outside:
        rm = range_axis_m(scene.config)
        print(
            f"warning: {len(outside)} of {len(scene.targets)} targets (indices {outside[:10]}) "
            f"lie outside the range window {rm[0]:.6g}–{rm[-1]:.6g} m and will not be imaged",
            file=sys.stderr,
        )
