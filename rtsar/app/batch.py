"""``rtsar batch``: many recordings through ``rtsar process`` on Dask distributed.

Each recording is one Dask task that runs the very ``process`` command in a worker process, so a
batch image is the image ``rtsar process`` writes for the same file and options (tested bit for
bit with one lens named: with ``--lens auto`` each chooses where it runs, and the two lenses
agree to ~1e-7 of the peak).  The lens is built inside the task, in the worker: its OpenCL
context is the worker process's shared one (``rtsar.lens.cl_loader.default_queue``), created
there and never pickled.

Failures are per file.  A file that ``process`` refuses (a malformed recording, a missing
channel, an unwritable output) is reported with its one-line reason and not retried: the same
input fails the same way.  A task whose worker died (killed, out of memory) is retried up to
``--retries`` times (on a LocalCluster; a ``--scheduler`` keeps its own allowed-failures), then
reported as failed with how the worker ended, where the cluster's nannies said so.  The
temporary a dead or stopped worker left beside its output (rtsar.sinks.partials) is removed
once the cluster is closed.

A signal (Ctrl-C, SIGTERM, SIGHUP) at any moment of a batch is only noted (:class:`StopSignal`):
the batch stops submitting, closes its cluster within :data:`CLOSE_TIMEOUT_S` and returns every
file's result, so the table is printed whatever Dask does while it shuts down.  Dask's and
tornado's log records are kept off stderr meanwhile (:func:`quiet_dask_logs`), and the workers
of a LocalCluster write nowhere.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import os
import re
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from ..sinks.partials import remove_stale_partials
from . import signals
from .cli import files
from .progress import Progress

CLOSE_TIMEOUT_S = 10.0  # the longest wait for the cluster's close once the files are done
_QUIET_ROOTS = ("distributed", "tornado", "bokeh", "asyncio")
_worker_quiet = False  # this worker process's log records are dropped


@dataclass
class FileResult:
    recording: str
    output: str
    status: str  # "ok", "failed", "interrupted" (was running) or "not started"
    seconds: float = 0.0
    message: str = ""  # process's summary line, or the reason it failed
    worker: str = ""


# ---- one file, in a worker ----------------------------------------------------------------
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
        reason = text.removeprefix("rtsar: error: ").removeprefix("rtsar: ")
        return FileResult(recording, output, "failed", seconds, reason, worker)
    summary = out.getvalue().strip().splitlines()
    return FileResult(recording, output, "ok", seconds, summary[-1] if summary else "", worker)


def _quiet_then_run(task, options: dict, recording: str, output: str):
    """The task: this worker's log records dropped (once), then ``task``.  A worker started
    after a death writes to the terminal; its shutdown chatter would land in the table."""
    global _worker_quiet
    if not _worker_quiet:
        _drop_records(_quiet_loggers())
        _worker_quiet = True
    return task(options, recording, output)


# ---- signals and logs -----------------------------------------------------------------------
class StopSignal:
    """SIGINT, SIGTERM and SIGHUP, while entered, are noted (the first one's ``signum``), not
    raised: the batch looks at it between steps, so no step of Dask is cut in the middle (a
    KeyboardInterrupt inside Dask's start or close left tracebacks and no table)."""

    NAMES = ("SIGINT", "SIGTERM", "SIGHUP")

    def __init__(self):
        self.signum: int | None = None
        self._saved: dict = {}

    def __enter__(self) -> StopSignal:
        if threading.current_thread() is threading.main_thread():
            for name in self.NAMES:
                sig = getattr(signal, name, None)
                if sig is not None:
                    self._saved[sig] = signal.signal(sig, self._note)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self._saved.items():
            signal.signal(sig, handler)
        self._saved.clear()

    def _note(self, signum, frame) -> None:
        if self.signum is None:
            self.signum = signum

    def __bool__(self) -> bool:
        return self.signum is not None

    @property
    def cause(self) -> KeyboardInterrupt:
        """The signal as the exception it raises elsewhere (rtsar.app.signals)."""
        if self.signum in (None, signal.SIGINT):
            return KeyboardInterrupt()
        return signals.Terminated(self.signum)


@contextlib.contextmanager
def _workers_write_nowhere():
    """While the LocalCluster spawns its workers this process's stderr (file descriptor 2) is
    the null device, which the workers keep: nothing a worker writes reaches the terminal (a
    terminal's Ctrl-C reaches every process of the group, and a worker hit answered with a
    traceback).  This process keeps its handlers: a signal during the start is not lost
    (ignoring it here, for the workers to inherit, lost it).  multiprocessing's resource tracker
    is started here too, with SIGHUP blocked (it ignores SIGINT and SIGTERM itself): a hangup
    killed it and its relaunch printed tracebacks."""
    from multiprocessing import resource_tracker

    sys.stderr.flush()
    saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    os.close(null)
    try:
        main = threading.current_thread() is threading.main_thread()
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGHUP}) if main else None
        try:
            resource_tracker.ensure_running()
        finally:
            if main:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class _Drop(logging.Filter):
    def filter(self, record) -> bool:
        return False


class _Deaths(logging.Handler):
    """The nannies' "Worker process PID exited with status N / was killed by signal N" lines,
    by PID (the reason a worker died, for the row of the file it ran)."""

    PATTERN = re.compile(r"Worker process (\d+) (.+)")

    def __init__(self):
        super().__init__(logging.INFO)
        self.by_pid: dict[int, str] = {}

    def emit(self, record) -> None:
        found = self.PATTERN.match(record.getMessage())
        if found:
            self.by_pid[int(found.group(1))] = found.group(2)


def _quiet_loggers() -> list[logging.Logger]:
    names = [n for n in logging.root.manager.loggerDict if n.split(".")[0] in _QUIET_ROOTS]
    return [logging.getLogger(n) for n in [*_QUIET_ROOTS, *names]]


def _drop_records(loggers) -> list[tuple[logging.Handler, logging.Filter]]:
    """Every handler of ``loggers`` drops every record; the (handler, filter) pairs added."""
    added = []
    for handler in {h for lg in loggers for h in lg.handlers}:
        drop = _Drop()
        handler.addFilter(drop)
        added.append((handler, drop))
    return added


@contextlib.contextmanager
def quiet_dask_logs():
    """Dask's, tornado's and asyncio's log records kept off stderr (and off logging's last-resort
    handler) inside the block; yields the :class:`_Deaths` record of the nannies' lines."""
    loggers = _quiet_loggers()
    added = _drop_records([*loggers, logging.root])
    asyncio_log = logging.getLogger("asyncio")
    was_disabled, asyncio_log.disabled = asyncio_log.disabled, True
    last_resort, logging.lastResort = logging.lastResort, logging.NullHandler()
    nanny = logging.getLogger("distributed.nanny")
    level, deaths = nanny.level, _Deaths()
    nanny.setLevel(logging.INFO)
    nanny.addHandler(deaths)
    try:
        yield deaths
    finally:
        nanny.removeHandler(deaths)
        nanny.setLevel(level)
        logging.lastResort = last_resort
        asyncio_log.disabled = was_disabled
        for handler, drop in added:
            handler.removeFilter(drop)


# ---- the cluster ----------------------------------------------------------------------------
NEEDS_DISTRIBUTED = 'rtsar batch needs Dask distributed: pip install "rtsar[cluster]"'


def missing_requirement() -> str | None:
    """Why ``rtsar batch`` cannot run here (None: Dask distributed imports).  Asked before any
    work: README command 1's environment has no cluster extra."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return NEEDS_DISTRIBUTED
    return None


def start_client(workers: int, scheduler: str | None, retries: int = 2):
    """A Dask client: on ``scheduler`` (``tcp://HOST:PORT``) or a LocalCluster of ``workers``
    single-threaded processes (the lens and the correlator use their own threads).

    A task whose worker dies is retried by the scheduler's ``allowed-failures``, not by the
    task's own retries: the LocalCluster's scheduler is given ``retries``; a cluster of one's own
    keeps its setting (``distributed.scheduler.allowed-failures``, Dask's default 3).  The
    LocalCluster's workers write nowhere (:func:`_workers_write_nowhere`) and take one task at
    a time (worker-saturation 1: a file waits for a free worker, not behind another file).
    """
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise RuntimeError(NEEDS_DISTRIBUTED) from exc
    if scheduler:
        return Client(scheduler, timeout="10s"), None
    settings = {
        "distributed.scheduler.allowed-failures": retries,
        "distributed.scheduler.worker-saturation": 1.0,
    }
    with _workers_write_nowhere(), dask.config.set(settings):
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.CRITICAL,
        )
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
    return client, cluster


def _bounded(fn, seconds: float):
    """``fn()`` in a thread of its own, waited for ``seconds`` at most; its result, or None when
    it raised or had not returned by then."""
    out: list = []

    def run():
        with contextlib.suppress(Exception):
            out.append(fn())

    thread = threading.Thread(target=run, name="rtsar-batch", daemon=True)
    thread.start()
    thread.join(seconds)
    return out[0] if out else None


def _close(client, cluster) -> None:
    for closable in (client, cluster):
        if closable is not None:
            with contextlib.suppress(Exception):
                closable.close()


def run_batch(
    recordings: list[Path],
    outputs: list[Path],
    options: dict,
    workers: int = 2,
    scheduler: str | None = None,
    retries: int = 2,
    stream=None,
    task=None,
    stop: StopSignal | None = None,
) -> list[FileResult]:
    """Process every recording on Dask; one FileResult per recording, in the input order.

    ``stop``: an entered :class:`StopSignal`; once it is set (before the start, during it, while
    the files run) the batch stops: files not done are "interrupted" (their worker was on them)
    or "not started", or "ok" when their image appeared as the batch stopped (images take their
    name only when complete).  The cluster is closed within :data:`CLOSE_TIMEOUT_S` in any case.

    ``task(options, recording, output) -> FileResult`` runs each file (default ``process_one``;
    the tests give one whose worker dies)."""
    stream = stream or sys.stderr
    stop = stop if stop is not None else StopSignal()
    started = time.time()
    results: list[FileResult | None] = [None] * len(recordings)
    submitted: set[int] = set()
    if not stop:
        import distributed  # noqa: F401  (its loggers exist before they are quieted)

        with quiet_dask_logs() as deaths:
            client = cluster = None
            try:
                try:
                    client, cluster = start_client(workers, scheduler, retries)
                except Exception as exc:
                    if not stop:  # a start cut short by the stop (a worker hit) is no error
                        where = scheduler or "the local cluster"
                        raise RuntimeError(f"Dask did not start on {where}: {exc}") from exc
                if client is not None and not stop:
                    slots = workers if cluster is not None else _threads(client)
                    run = _Files(client, task or process_one, recordings, outputs, options)
                    run.retries, run.deaths = retries, deaths.by_pid
                    prog = Progress(len(recordings), "batch", unit="files", stream=stream)
                    run.collect(results, slots, prog, stop)
                    submitted = set(run.futures.values())
                    if stop:
                        _bounded(lambda: client.cancel(list(run.futures)), 5.0)
            finally:
                _bounded(lambda: _close(client, cluster), CLOSE_TIMEOUT_S)
    for output in outputs:  # a worker that died (or was stopped) left its temporary there
        remove_stale_partials(output)
    return [
        r or _unfinished(recordings[i], outputs[i], started, i in submitted)
        for i, r in enumerate(results)
    ]


def _threads(client) -> int:
    """The threads of a running cluster's workers (at least 1: the tasks wait for a worker)."""
    return max(1, sum((_bounded(client.nthreads, 10.0) or {}).values()))


class _Files:
    """The files as Dask tasks, at most ``slots`` in flight: a file goes to a worker when one is
    free, so the files submitted and not done are the ones being processed ("interrupted" if
    the batch stops), the rest "not started", and a worker's death fails only its own file
    (given all at once, the scheduler sent each worker two files when there were few, Dask's
    queuing being for larger groups: a death failed the file waiting behind the one it hit)."""

    def __init__(self, client, task, recordings, outputs, options):
        self.client, self.task, self.options = client, task, options
        self.recordings, self.outputs = recordings, outputs
        self.futures: dict = {}  # future → file index
        self.retries, self.deaths = 0, {}

    def submit(self, i: int):
        fut = self.client.submit(
            _quiet_then_run,
            self.task,
            self.options,
            str(self.recordings[i]),
            str(self.outputs[i]),
            key=f"rtsar-process-{i}-{self.recordings[i].name}",
            retries=self.retries,
            pure=False,
        )
        self.futures[fut] = i
        return fut

    def collect(self, results, slots, prog, stop) -> None:
        """Fill ``results`` as the files finish, until all are or ``stop``."""
        from distributed import as_completed

        n = len(self.recordings)
        pending = as_completed([self.submit(i) for i in range(min(slots, n))])
        following = iter(range(min(slots, n), n))
        done = failed = 0
        while not stop and not pending.is_empty():
            ready = pending.next_batch(block=False)
            if not ready:
                time.sleep(0.05)
                continue
            for fut in ready:
                i = self.futures[fut]
                try:
                    result = fut.result()
                except Exception as exc:  # raised by the task on every try, or its worker died
                    why = _why(exc, self.deaths, self.retries)
                    result = FileResult(
                        str(self.recordings[i]), str(self.outputs[i]), "failed", message=why
                    )
                results[i] = result
                done += 1
                failed += result.status != "ok"
                prog.update(done, f"{failed} failed" if failed else "")
                after = next(following, None)
                if after is not None and not stop:
                    pending.add(self.submit(after))
        if not stop:
            prog.done(done, f"{failed} failed" if failed else "")


def _unfinished(recording: Path, output: Path, started: float, running: bool) -> FileResult:
    """A file without a result when the batch stopped: its image is whole if it is there and new
    (images take their name only when complete), else it was interrupted or not started."""
    try:
        new = output.stat().st_mtime >= started
    except OSError:
        new = False
    if new:
        return FileResult(
            str(recording), str(output), "ok", message="finished as the batch stopped"
        )
    return FileResult(str(recording), str(output), "interrupted" if running else "not started")


DEATH_LINE_WAIT_S = 3.0  # the longest a failed row waits for its worker's nanny to say how


def _why(exc: Exception, deaths: dict[int, str], retries: int) -> str:
    """A failed task's row: the exception it raised, or how its worker ended (Dask's
    KilledWorker: the nanny's exit status or signal of the last one, where known)."""
    if type(exc).__name__ != "KilledWorker":
        return f"{type(exc).__name__}: {exc} (raised on each of {retries + 1} tries)"
    tries = int(getattr(exc, "allowed_failures", 0)) + 1
    pid = getattr(getattr(exc, "last_worker", None), "pid", None)
    # The scheduler may give up on the worker before its nanny has logged how it ended (a
    # busy machine): wait for that line a moment rather than say "not known".
    deadline = time.monotonic() + DEATH_LINE_WAIT_S
    while pid is not None and pid not in deaths and time.monotonic() < deadline:
        time.sleep(0.05)
    said = deaths.get(pid)
    found = re.fullmatch(r"was killed by signal (\d+)", said or "")
    if found:
        with contextlib.suppress(ValueError):
            said += f" ({signal.Signals(int(found.group(1))).name})"
    if not said:
        how = "how is not known (killed by the OS? out of memory?)"
    else:
        how = f"the last {said}" if tries > 1 else f"it {said}"
    died = f"on each of {tries} tries" if tries > 1 else "(no retries)"
    return f"its worker process died {died}; {how}"


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
