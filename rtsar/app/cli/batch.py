"""The ``batch`` command: many recordings through ``process`` on Dask distributed."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from .. import batch, signals
from .options import add_process_options, die

# The options of ``batch`` itself; every other parsed option is a ``process`` option.
BATCH_ONLY = {"command", "func", "inputs", "out_dir", "workers", "scheduler", "retries"}


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def cmd_batch(args) -> int:
    recordings = batch.find_recordings(args.inputs)
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if not os.access(out_dir, os.W_OK):
        return die(f"{out_dir}: cannot write there")
    outputs = batch.output_paths(recordings, out_dir)
    if args.workers < 1:
        return die("--workers must be at least 1")
    options = {k: v for k, v in vars(args).items() if k not in BATCH_ONLY}
    procs = f"{args.workers} worker process{'' if args.workers == 1 else 'es'}"
    where = args.scheduler or f"a local cluster of {procs}"
    n = len(recordings)
    print(f"rtsar batch: {_count(n, 'recording')} on {where} → {out_dir}", file=sys.stderr)
    try:
        results = batch.run_batch(
            recordings, outputs, options, args.workers, args.scheduler, args.retries
        )
    except batch.BatchInterrupted as exc:  # what finished is listed; their images are whole
        print(batch.summary_table(exc.results))
        ok = sum(r.status == "ok" for r in exc.results)
        print(f"{signals.describe(exc.cause)}: {ok} of {_count(n, 'recording')} focused")
        return signals.exit_status(exc.cause)
    print(batch.summary_table(results))
    failed = [r for r in results if r.status != "ok"]
    total_s = sum(r.seconds for r in results)
    print(
        f"{len(results) - len(failed)} of {_count(len(results), 'recording')} focused "
        f"({total_s:.1f} s of processing in all)" + (f"; {len(failed)} failed" if failed else "")
    )
    return 1 if failed else 0


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "batch",
        help="focus many recordings with `process` on Dask (local processes or a cluster)",
        description="Run `rtsar process` on every recording named (files, or folders of *.h5) as "
        "Dask tasks: a LocalCluster of --workers processes by default, or the cluster at "
        "--scheduler tcp://HOST:PORT (its workers need rtsar installed and the files at the "
        "same paths).  Each image is the one `rtsar process` writes for the same options: "
        "OUT_DIR/STEM-img.h5.  A file that process refuses is reported with its reason and "
        "not retried; a task whose worker died is retried.  Prints a summary table; exit "
        "status 1 when any file failed.",
    )
    s.add_argument("inputs", nargs="+", help="recordings (.h5) and/or folders holding them")
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
        "reported as failed (default 2; with --scheduler, that scheduler's own "
        "distributed.scheduler.allowed-failures applies)",
    )
    add_process_options(s)
    s.set_defaults(func=cmd_batch)
