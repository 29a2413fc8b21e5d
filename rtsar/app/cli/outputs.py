"""Outputs that would replace an input, or a file another process is writing: refused before
any work, for every command (its options naming files it reads and files it writes)."""

from __future__ import annotations

from pathlib import Path

import h5py

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from ...sinks.h5_open import open_for_reading
from ...sinks.io import RECORDING_FORMAT, check_writable
from ...sinks.name_claim import check_unclaimed

# Options naming files a command reads, and files it writes (``--sigmf BASE`` writes
# BASE.sigmf-meta and BASE.sigmf-data).
INPUT_OPTIONS = ("scene", "recording", "image", "input", "images", "inputs", "instrument")
INPUT_OPTIONS += ("curve_key", "curve_server_key", "curve_client_key")
OUTPUT_OPTIONS = ("output", "png", "json", "out", "cphd", "sicd", "sigmf", "record")
COMMAND_INPUTS = {"spotlight": ("live",), "projective": ("simulate",)}  # named like others
COMMAND_OUTPUTS = {"quicklook": ("height",)}  # --height PNG (elsewhere --height is a method)
# Commands whose -o writes an HDF5 file (a recording or an image), and the suffixes of what
# such a file is not: `process rec.h5 -o x.png` wrote HDF5 under a picture's name.
HDF5_OUTPUT_COMMANDS = (
    "simulate", "process", "run", "replay", "subscribe", "demo", "spot-simulate", "spotlight",
    "import",
)  # fmt: skip
RECORDING_COMMANDS = ("simulate", "import", "spot-simulate")  # -o writes a recording
NOT_HDF5_SUFFIXES = (
    ".png", ".jpg", ".jpeg", ".gif", ".pdf", ".svg", ".tif", ".tiff", ".csv", ".json", ".txt",
    ".md", ".toml", ".cphd", ".nitf", ".ntf", ".sigmf", ".sigmf-meta", ".sigmf-data",
)  # fmt: skip


def check_outputs_spare_inputs(args) -> None:
    """ValueError before any work when an output of the command names one of its inputs (or
    another of its outputs): ``process rec.h5 -o rec.h5`` replaced the recording by its image;
    or a file another process writes live (rtsar.sinks.name_claim).  A SigMF recording
    exported onto itself (``export rec.sigmf-meta --sigmf rec``) is the exception: that export
    reads the recording whole first.  An HDF5 output named like another kind of file
    (``process rec.h5 -o x.png``) is refused too, and so is a ``--record`` file that exists:
    an image can be made again from its recording, a recording cannot (``run --record`` over
    an earlier recording replaced it without a word)."""
    command = getattr(args, "command", None)
    inputs = {}
    for name in INPUT_OPTIONS + COMMAND_INPUTS.get(command, ()):
        for value in _values(getattr(args, name, None)):
            for path in _files_of(value, name):
                if path.exists():  # a built-in scene's name is not a file the output replaces
                    inputs[_identity(path)] = path
    outputs = {}
    for name in OUTPUT_OPTIONS + COMMAND_OUTPUTS.get(command, ()):
        for value in _values(getattr(args, name, None)):
            for path in _files_of(value, name):
                key = _identity(path)
                if key in outputs:
                    raise ValueError(f"{path} is named as two outputs of this command")
                outputs[key] = path
                sigmf_in_place = name == "sigmf" and str(inputs.get(key, "")).endswith(
                    (".sigmf-meta", ".sigmf-data")
                )
                if key in inputs and not sigmf_in_place:
                    raise ValueError(
                        f"the output {path} is this command's input {inputs[key]}: writing it "
                        "would replace what it reads; choose another output name"
                    )
    named = (("-o", getattr(args, "output", None)), ("--record", getattr(args, "record", None)))
    for option, value in named:
        suffix = Path(value).suffix.lower() if value else ""
        if command in HDF5_OUTPUT_COMMANDS and suffix in NOT_HDF5_SUFFIXES:
            raise ValueError(
                f"{option} {value}: {command} writes an HDF5 file (.h5), not a {suffix} file; "
                "pictures come from `rtsar quicklook IMG.h5 -o PICTURE`, CPHD/SICD/SigMF from "
                "`rtsar export`"
            )
    for path in outputs.values():  # a file another process writes live is never replaced
        check_unclaimed(path)
        check_writable(path)  # a missing folder said now (process said it after the lens)
        refuse_replacing_a_recording(command, path)
    record = getattr(args, "record", None)
    if record and Path(record).exists():
        raise ValueError(
            f"--record {record}: the file exists, and a recording is never replaced (its raw "
            "shots cannot be taken again); give a new name, or remove the old file first"
        )


def refuse_replacing_a_recording(command: str | None, path: Path) -> None:
    """ValueError where ``path`` is a recording the command would replace: one recorded live
    (``run --record``: its shots cannot be taken again) by any command, another (simulated,
    imported) by any but the commands that write recordings (``process rec2.h5 -o rec.h5``
    made an image of the only copy of a recording, ``simulate -o`` replaced a live one, both
    without a word: a new user's trial)."""
    try:
        if not h5py.is_hdf5(path):  # (not HDF5, or no file: not a recording)
            return
        with open_for_reading(path) as f:
            kind, live = f.attrs.get("format"), bool(f.attrs.get("recorded_live", False))
            shots = f["shots"].shape[0] if "shots" in f else 0
    except (OSError, ValueError, KeyError):  # not ours to judge: the writer's own checks
        return
    if kind != RECORDING_FORMAT or (command in RECORDING_COMMANDS and not live):
        return
    what = "a live recording" if live else "a recording"
    raise ValueError(
        f"{path} is {what} ({shots:,} shots), and a recording is never replaced by "
        f"{'another' if command in RECORDING_COMMANDS else 'an image or another output'}"
        f"{' (its shots cannot be taken again)' if live else ''}; give a new name, or "
        "remove it first"
    )


def _values(value) -> list[str]:
    if value is None or isinstance(value, bool):
        return []
    return [str(v) for v in value] if isinstance(value, list | tuple) else [str(value)]


def _files_of(value: str, option: str) -> list[Path]:
    """The files an option's value names (SigMF: both files of a recording)."""
    path = Path(value)
    if option == "sigmf":
        return [Path(value + ".sigmf-meta"), Path(value + ".sigmf-data")]
    if path.suffix.lower() in (".sigmf-meta", ".sigmf-data"):
        return [path.with_suffix(".sigmf-meta"), path.with_suffix(".sigmf-data")]
    if option == "instrument":  # the file and the data (and AGC, replica) files it names
        return [path, *_instrument_files(path)]
    return [path]


def _instrument_files(path: Path) -> list[Path]:
    """The files an instrument TOML names ([data] file, agc_db_file; [radar] replica_file),
    relative to its folder; none when it cannot be read (its reader says why, later)."""
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return []
    named = [
        (doc.get("data") or {}).get("file"),
        (doc.get("data") or {}).get("agc_db_file"),
        (doc.get("radar") or {}).get("replica_file"),
    ]
    return [path.parent / n for n in named if isinstance(n, str)]


def _identity(path: Path):
    """What tells two names of one file apart from two files: (device, inode) of an existing
    file (hard links, symlinks, ./x and x), else its absolute path."""
    try:
        st = path.stat()
    except OSError:
        return str(path.resolve())
    return st.st_dev, st.st_ino
