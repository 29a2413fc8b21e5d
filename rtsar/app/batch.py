"""``rtsar batch``: many recordings through ``rtsar process`` on Dask distributed.

Each recording is one Dask task that runs the very ``process`` command in a worker process, so a
batch image is the image ``rtsar process`` writes for the same file and options (tested bit for
bit).  The lens is built inside the task, in the worker: its OpenCL context is the worker
process's shared one (``rtsar.lens.cl_loader.default_queue``), created there and never pickled.

Failures are per file.  A file that ``process`` refuses (a malformed recording, a missing
channel, an unwritable output) is reported with its one-line reason and not retried: the same
input fails the same way.  A task whose worker died (killed, out of memory) is retried up to
``--retries`` times (on a LocalCluster; a ``--scheduler`` keeps its own allowed-failures), then
reported as failed.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import h5py

from .cli import files
from .progress import Progress

RECORDING_SUFFIXES = (".h5", ".hdf5")


@dataclass
class FileResult:
    recording: str
    output: str
    status: str  # "ok" or "failed"
    seconds: float = 0.0
    message: str = ""  # process's summary line, or the reason it failed
    worker: str = ""


def _is_image(path: Path) -> bool:
    """An rtsar image file (``format = "rtsar-image"``), e.g. a previous batch's output."""
    try:
        with h5py.File(path, "r") as f:
            return f.attrs.get("format") == "rtsar-image"
    except OSError:
        return False


def find_recordings(inputs: list[str]) -> list[Path]:
    """The recordings named: files as given, folders by their ``*.h5``/``*.hdf5`` files (sorted,
    rtsar image files left out: a folder may hold an earlier batch's images).

    Raises ValueError for a path that does not exist or a list with no recording.
    """
    found: list[Path] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found.extend(
                sorted(
                    p
                    for p in path.iterdir()
                    if p.suffix.lower() in RECORDING_SUFFIXES and not _is_image(p)
                )
            )
        elif path.is_file():
            found.append(path)
        else:
            raise ValueError(f"{item}: no such file or folder")
    unique = list(dict.fromkeys(p.resolve() for p in found))
    if not unique:
        raise ValueError(f"no recording (*.h5) in {', '.join(inputs)}")
    return unique


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


def process_one(options: dict, recording: str, output: str) -> FileResult:
    """Run ``rtsar process RECORDING -o OUTPUT`` with ``options`` in this (worker) process.

    ``options`` are the ``process`` options parsed by ``rtsar batch`` (the same option
    declarations, so the same names).  process's own output is captured and returned.
    """
    args = argparse.Namespace(**options, recording=recording, output=output)
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = files.cmd_process(args)
    except (ValueError, OSError, RuntimeError) as exc:  # process's one-line errors
        return FileResult(recording, output, "failed", time.perf_counter() - t0, str(exc), worker)
    seconds = time.perf_counter() - t0
    if status != 0:
        reason = err.getvalue().strip().splitlines()
        text = reason[-1] if reason else f"exit status {status}"
        reason = text.removeprefix("rtsar: ")
        return FileResult(recording, output, "failed", seconds, reason, worker)
    summary = out.getvalue().strip().splitlines()
    return FileResult(recording, output, "ok", seconds, summary[-1] if summary else "", worker)


def start_client(workers: int, scheduler: str | None, retries: int = 2):
    """A Dask client: on ``scheduler`` (``tcp://HOST:PORT``) or a LocalCluster of ``workers``
    single-threaded processes (the lens and the correlator use their own threads).

    A task whose worker dies is retried by the scheduler's ``allowed-failures``, not by the
    task's own retries: the LocalCluster's scheduler is given ``retries``; a cluster of one's own
    keeps its setting (``distributed.scheduler.allowed-failures``, Dask's default 3).
    """
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise RuntimeError(
            'rtsar batch needs Dask distributed: pip install "rtsar[cluster]"'
        ) from exc
    if scheduler:
        return Client(scheduler, timeout="10s"), None
    # The workers are started with Ctrl-C ignored (they inherit it): a terminal's Ctrl-C reaches
    # every process of the group, and Dask's workers answered it with tracebacks; this process
    # ends them when it is interrupted.
    main = threading.current_thread() is threading.main_thread()
    before = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        with dask.config.set({"distributed.scheduler.allowed-failures": retries}):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=40,  # logging.ERROR: Dask's chatter would bury the progress line
            )
    finally:
        if main:
            signal.signal(signal.SIGINT, before)
    return Client(cluster), cluster


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM/SIGHUP) during a batch: ``results`` has every file, those not finished
    marked "interrupted"; ``cause`` is the interrupt itself."""

    def __init__(self, results: list, cause: KeyboardInterrupt):
        super().__init__(str(cause))
        self.results, self.cause = results, cause
        self.signum = getattr(cause, "signum", signal.SIGINT)


def run_batch(
    recordings: list[Path],
    outputs: list[Path],
    options: dict,
    workers: int = 2,
    scheduler: str | None = None,
    retries: int = 2,
    stream=None,
    task=None,
) -> list[FileResult]:
    """Process every recording on Dask; one FileResult per recording, in the input order.

    Interrupted (Ctrl-C, SIGTERM, SIGHUP): :class:`BatchInterrupted` with every file's result.

    ``task(options, recording, output) -> FileResult`` runs each file (default ``process_one``;
    the tests give one whose worker dies)."""
    stream = stream or sys.stderr
    started = time.time()
    client, cluster = start_client(workers, scheduler, retries)
    results: list[FileResult | None] = [None] * len(recordings)
    interrupted = None
    try:
        futures = {
            client.submit(
                task or process_one,
                options,
                str(rec),
                str(out),
                key=f"rtsar-process-{i}-{rec.name}",
                retries=retries,
                pure=False,
            ): i
            for i, (rec, out) in enumerate(zip(recordings, outputs, strict=True))
        }
        prog = Progress(len(recordings), "batch", unit="files", stream=stream, every_s=5.0)
        try:
            _collect(futures, recordings, outputs, retries, results, prog)
        except KeyboardInterrupt as exc:
            for fut in futures:
                fut.cancel()
            interrupted = exc
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    if interrupted is not None:  # closed now: a file a worker was on may be finished
        left = [r or _unfinished(recordings[i], outputs[i], started) for i, r in enumerate(results)]
        raise BatchInterrupted(left, interrupted) from None
    return [r for r in results if r is not None]


def _unfinished(recording: Path, output: Path, started: float) -> FileResult:
    """A file without a result when the batch was interrupted: its image is whole if it is there
    and new (images take their name only when complete), else it was not done."""
    try:
        new = output.stat().st_mtime >= started
    except OSError:
        new = False
    if new:
        return FileResult(
            str(recording), str(output), "ok", message="finished as the batch stopped"
        )
    return FileResult(str(recording), str(output), "interrupted")


def _collect(futures, recordings, outputs, retries, results, prog) -> None:
    """Fill ``results`` as the files finish (run_batch's loop)."""
    from distributed import as_completed

    done = failed = 0
    for fut in as_completed(futures):
        i = futures[fut]
        try:
            result = fut.result()
        except Exception as exc:  # the worker died on every try (KilledWorker, ...)
            result = FileResult(
                str(recordings[i]),
                str(outputs[i]),
                "failed",
                message=f"{type(exc).__name__}: {exc} (after {retries} retries)",
            )
        results[i] = result
        done += 1
        failed += result.status != "ok"
        prog.update(done, f"{failed} failed" if failed else "")
    prog.done(done, f"{failed} failed" if failed else "")


def summary_table(results: list[FileResult]) -> str:
    """A plain-text table: file, status, seconds, worker, and process's line or the reason."""
    rows = [("recording", "status", "s", "worker", "result")]
    for r in results:
        rows.append((Path(r.recording).name, r.status, f"{r.seconds:.1f}", r.worker, r.message))
    widths = [max(len(row[k]) for row in rows) for k in range(4)]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(row[:4], widths, strict=True)) + "  " + row[4]
        for row in rows
    )
