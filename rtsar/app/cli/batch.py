"""The ``batch`` command: many recordings through ``process`` on Dask distributed.

Which files it takes (:func:`find_recordings`) and what it checks before it starts a cluster
(:func:`refusal`: process's own checks on each file's header) live here; running them is
``rtsar.app.batch``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import h5py

from ...focus.spec import parse_spec
from ...lens import range_axis_m
from ...sinks.name_claim import check_unclaimed
from ...sources.formats.sigmf_reader import auxiliary_of
from .. import batch, signals
from .files import process_setup
from .inputs import open_input
from .options import add_process_options, die

# The options of ``batch`` itself; every other parsed option is a ``process`` option.
BATCH_ONLY = {"command", "func", "inputs", "out_dir", "workers", "scheduler", "retries"}
RECORDING_SUFFIXES = (".h5", ".hdf5")
OTHER_FORMATS = (".cphd", ".sigmf-meta", ".sigmf")  # CPHD, SigMF (metadata file or archive)
FOLDER_RULE = (
    "a folder gives every file that process reads: rtsar recordings (*.h5, *.hdf5; rtsar image "
    "files, such as an earlier batch's, are left out), CPHD (*.cphd) and SigMF (*.sigmf-meta "
    "with its .sigmf-data, or a *.sigmf archive; an export's auxiliary channel files are read "
    "with it); the files of a folder not taken are named on "
    "one line with the reason; hidden files and folders inside are not looked at"
)


# ---- which files ------------------------------------------------------------------------------
def _is_image(path: Path) -> bool:
    """An rtsar image file (``format = "rtsar-image"``), e.g. a previous batch's output."""
    try:
        with h5py.File(path, "r") as f:
            return f.attrs.get("format") == "rtsar-image"
    except OSError:
        return False


def _not_taken(path: Path) -> str | None:
    """Why a folder's entry is not a recording to process (None: it is one; "": it is read as
    part of another file taken, a SigMF pair's data)."""
    name = path.name.lower()
    if path.is_dir():
        return "a folder (folders inside are not searched)"
    if name.endswith(".sigmf-data"):
        meta = path.with_name(path.name[: -len(".sigmf-data")] + ".sigmf-meta")
        return "" if meta.is_file() else "SigMF data without its .sigmf-meta"
    if name.endswith(".sigmf-meta"):
        return _sigmf_channel(path)
    if name.endswith(OTHER_FORMATS):
        return None
    if path.suffix.lower() in RECORDING_SUFFIXES:
        return "an rtsar image, not a recording" if _is_image(path) else None
    return "not a format process reads"


def _sigmf_channel(meta: Path) -> str | None:
    """No reason ("") for an auxiliary channel's metadata whose recording is beside it (read
    with it), a reason when that recording is missing, None for a recording (or a file that
    process judges)."""
    try:
        info = json.loads(meta.read_text(encoding="utf-8")).get("global", {})
    except (OSError, ValueError, AttributeError):
        return None
    base = meta.with_name(meta.name[: -len(".sigmf-meta")])
    main = auxiliary_of(info, base) if isinstance(info, dict) else None
    if main is None:
        return None
    if main.with_name(main.name + ".sigmf-meta").is_file():
        return ""
    return f"the auxiliary channel of a SigMF export whose {main.name}.sigmf-meta is missing"


def find_recordings(inputs: list[str]) -> tuple[list[Path], list[tuple[Path, str]]]:
    """The recordings named, and the entries of the folders named that were not taken, each
    with its reason (:data:`FOLDER_RULE`).  A file named is taken as it is (process says what
    is wrong with it).  Raises ValueError for a path that does not exist or no recording."""
    found: list[Path] = []
    skipped: list[tuple[Path, str]] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            for entry in sorted(p for p in path.iterdir() if not p.name.startswith(".")):
                why = _not_taken(entry)
                if why is None:
                    found.append(entry)
                elif why:
                    skipped.append((entry, why))
        elif path.is_file():
            found.append(path)
        else:
            raise ValueError(f"{item}: no such file or folder")
    # One entry per file (a file named twice, or through a link, is focused once), under the
    # name it was given: a link's name, not its target's, names the image.
    named: dict[Path, Path] = {}
    for p in found:
        named.setdefault(p.resolve(), p.absolute())
    unique = list(named.values())
    if not unique:
        said = f" ({skipped_line(skipped)})" if skipped else ""
        raise ValueError(
            f"no recording (*.h5, *.hdf5, *.cphd, *.sigmf-meta, *.sigmf) in {', '.join(inputs)}"
            + said
        )
    return unique, skipped


def skipped_line(skipped: list[tuple[Path, str]], most: int = 6) -> str:
    """``skipped 2 files: a-img.h5 (an rtsar image, not a recording); notes.txt (...)``."""
    by_reason: dict[str, list[str]] = {}
    for path, why in skipped:
        by_reason.setdefault(why, []).append(path.name)
    parts = []
    for why, names in by_reason.items():
        more = f" and {len(names) - most} more" if len(names) > most else ""
        parts.append(f"{', '.join(names[:most])}{more} ({why})")
    return f"skipped {_count(len(skipped), 'file')}: " + "; ".join(parts)


def output_paths(recordings: list[Path], out_dir: Path, suffix: str = "-img.h5") -> list[Path]:
    """``OUT_DIR/STEM-img.h5`` for every recording; two recordings with one stem, or an output
    that is one of the recordings, are refused (before any work)."""
    outputs = [out_dir.resolve() / f"{r.stem}{suffix}" for r in recordings]
    inputs = {r.resolve() for r in recordings}
    seen: dict[Path, Path] = {}
    for rec, out in zip(recordings, outputs, strict=True):
        if out in inputs:
            raise ValueError(f"{rec}'s image {out} would overwrite a recording of this batch")
        if out in seen:
            raise ValueError(
                f"{seen[out]} and {rec} would both write {out}: give them different names"
            )
        seen[out] = rec
    return outputs


# ---- checks before the cluster ----------------------------------------------------------------
def refusal(options: dict, recording: Path) -> str | None:
    """Why ``process`` would refuse ``recording`` with ``options``, found from its header before
    any lens is built (None: it would start): the checks process makes first, in its order (the
    file's format, the processor knobs, the corrections against the waveform and the scene, the
    height stage, the channels they read, the aperture).  A bare ``pra`` is checked with a
    stand-in retro-reflector: process finds the real one in a first pass over the file."""
    args = argparse.Namespace(**options, recording=str(recording), output="")
    try:
        with open_input(recording) as rec:
            # process's knobs leave the range window as the recording's configuration has it
            mid_m = float(range_axis_m(rec.config).mean())
            stand_in = f"pra:along_track_m={rec.start_along_track_m},range_m={mid_m}"
            bare = [
                stand_in if s.split(":")[0].strip() == "pra" and "=" not in s else s
                for s in args.correct or []
            ]
            checked = argparse.Namespace(**{**vars(args), "correct": bare or None})
            process_setup(checked, rec)
    except (ValueError, OSError, RuntimeError) as exc:
        return str(exc)
    return None


def unclaimed(output: Path) -> str | None:
    """Why ``output`` may not be written: another rtsar process is writing it live (its name
    claimed, rtsar.sinks.name_claim); None when it is free."""
    try:
        check_unclaimed(output)
    except ValueError as exc:
        return str(exc)
    return None


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def cmd_batch(args) -> int:
    if args.workers < 1:
        return die("--workers must be at least 1")
    if args.retries < 0:
        return die(f"--retries must be >= 0, got {args.retries}")
    options = {k: v for k, v in vars(args).items() if k not in BATCH_ONLY}
    for spec in args.correct or []:
        parse_spec(spec)  # an unknown correction stops here, as in process (exit status 2)
    out_dir = Path(args.out_dir)
    missing = batch.missing_requirement()
    if missing:
        return die(missing)
    made = not out_dir.exists()
    try:
        return _batch(args, options, out_dir)
    finally:  # a folder this run made and left empty (refused before the start) goes
        if made and out_dir.is_dir() and not any(out_dir.iterdir()):
            out_dir.rmdir()


def _batch(args, options: dict, out_dir: Path) -> int:
    with batch.StopSignal() as stop:  # a signal from here on ends with the table
        recordings, skipped = find_recordings(args.inputs)
        out_dir.mkdir(parents=True, exist_ok=True)
        if not os.access(out_dir, os.W_OK):
            return die(f"{out_dir}: cannot write there")
        outputs = output_paths(recordings, out_dir)
        if skipped:
            print(f"rtsar batch: {skipped_line(skipped)}", file=sys.stderr)
        refused: dict[int, str] = {}
        for i, rec in enumerate(recordings):
            if stop:
                break
            why = refusal(options, rec) or unclaimed(outputs[i])
            if why:
                refused[i] = why
        n = len(recordings)
        if len(refused) == n:
            reasons = set(refused.values())
            if len(reasons) == 1:  # process's one line, e.g. "unknown correction 'foo'"
                return die(reasons.pop())
        todo = [i for i in range(n) if i not in refused]
        procs = f"{args.workers} worker process{'' if args.workers == 1 else 'es'}"
        where = args.scheduler or f"a local cluster of {procs}"
        also = f" ({len(refused)} more refused: see the table)" if refused else ""
        if todo:
            print(
                f"rtsar batch: {_count(len(todo), 'recording')} on {where} → {out_dir}{also}",
                file=sys.stderr,
            )
        ran = []
        if todo:
            ran = batch.run_batch(
                [recordings[i] for i in todo],
                [outputs[i] for i in todo],
                options,
                args.workers,
                args.scheduler,
                args.retries,
                stop=stop,
            )
    results = [
        batch.FileResult(str(r), str(o), "failed", message=refused.get(i, ""))
        for i, (r, o) in enumerate(zip(recordings, outputs, strict=True))
    ]
    for i, result in zip(todo, ran, strict=True):
        results[i] = result
    print(batch.summary_table(results))
    ok = sum(r.status == "ok" for r in results)
    if stop:  # what finished is listed; their images are whole
        print(f"{signals.describe(stop.cause)}: {ok} of {_count(n, 'recording')} focused")
        return signals.exit_status(stop.cause)
    failed = n - ok
    total_s = sum(r.seconds for r in results)
    print(
        f"{ok} of {_count(n, 'recording')} focused ({total_s:.1f} s of processing in all)"
        + (f"; {failed} failed" if failed else "")
        + (f" ({len(refused)} refused before the start)" if refused else "")
    )
    if not todo:
        return 2  # nothing could start: as process, an input error
    return 1 if failed else 0


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "batch",
        description="Run `rtsar process` on every recording named (files, or folders) as "
        "Dask tasks: a LocalCluster of --workers processes by default, or the cluster at "
        "--scheduler tcp://HOST:PORT (its workers need rtsar installed and the files at the "
        "same paths).  Each image is the one `rtsar process` writes for the same options: "
        f"OUT_DIR/STEM-img.h5.  Files: {FOLDER_RULE}.  Before any cluster starts, the options "
        "and each file's header are checked as process checks them: an option error stops "
        "the batch (exit status 2), a file that process would refuse is reported in the table "
        "and the others run.  A file that process refuses while it runs is not retried; a task "
        "whose worker died is retried.  Prints a summary table, also when interrupted "
        "(Ctrl-C, SIGTERM, SIGHUP: each file done, finished as the batch stopped, interrupted "
        "or not started; exit status 128 + the signal).  Exit status 1 when any file failed, "
        "2 when none could start.",
    )
    s.add_argument(
        "inputs",
        nargs="+",
        help="recordings (.h5, .cphd, .sigmf-meta) and/or folders holding them",
    )
    s.add_argument("--out-dir", required=True, help="folder for the images (created if missing)")
    s.add_argument(
        "--workers",
        type=int,
        default=2,
        help="worker processes of the local cluster (default 2: one per core here)",
    )
    s.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="a running Dask scheduler to use instead of a local cluster (default: none)",
    )
    s.add_argument(
        "--retries",
        type=int,
        default=2,
        help="retries of a file whose worker died (killed, out of memory) before it is "
        "reported as failed with how the worker ended (default 2; with --scheduler, that "
        "scheduler's own distributed.scheduler.allowed-failures applies)",
    )
    add_process_options(s)
    s.set_defaults(func=cmd_batch)
