"""The ``swath-worker`` command: one range slice of a split live pipeline (rtsar.stream.swath)."""

from __future__ import annotations

import sys

from ...stream.swath import (
    BEAT_S,
    COORDINATOR_TIMEOUT_S,
    MIN_COORDINATOR_TIMEOUT_S,
    READY_TIMEOUT_S,
    worker_endpoints,
)
from ...stream.swath_worker import serve
from .options import die, zmq_endpoint


def cmd_swath_worker(args) -> int:
    if args.connect:
        shots, results = worker_endpoints(args.connect, args.index)
    elif args.shots and args.results:
        shots, results = args.shots, args.results
    else:
        return die("give --connect tcp://HOST:PORT (or --shots and --results)")
    if args.index < 0:
        return die(f"--index must be >= 0, got {args.index}")
    wait = args.coordinator_timeout
    if wait != 0 and not wait >= MIN_COORDINATOR_TIMEOUT_S:
        return die(
            f"--coordinator-timeout must be 0 (no limit) or >= {MIN_COORDINATOR_TIMEOUT_S:g} s "
            f"(the coordinator speaks every {BEAT_S:g} s), got {wait:g}"
        )
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731 - one line, one use
    return serve(shots, results, args.index, log, args.parent_pid, wait)


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "swath-worker",
        description="Connect to a coordinator (`rtsar run/replay --swath-workers K "
        "--swath-bind tcp://HOST:PORT`), take its configuration and range columns, run the AO "
        "lens and the shifting CCD of those columns on every pulse block it sends, and send "
        "the lines back; ends when the coordinator's stream ends (exit status 0) or fails "
        "(1).  Until the coordinator sends the setup the worker waits for it without limit (it "
        f"may be started first; the coordinator waits up to {READY_TIMEOUT_S:g} s for its "
        "workers).  From then "
        f"on the coordinator speaks at least every {BEAT_S:g} s (pulse blocks, or beats while "
        "its source is idle), and a worker that hears nothing for --coordinator-timeout ends "
        "with exit status 1 and a one-line message: the coordinator was killed, its host lost "
        "or the network cut.  A coordinator whose run fails tells its workers (a stop message "
        "with the reason): they end at once, exit status 1.  Local workers are started by "
        "the coordinator itself (plain --swath-bind HOST).",
    )
    s.add_argument(
        "--connect",
        metavar="tcp://HOST:PORT",
        type=zmq_endpoint,
        help="the coordinator's --swath-bind endpoint (default: none; or --shots/--results)",
    )
    s.add_argument("--index", type=int, default=0, help="this worker's slice, 0 … K-1 (default 0)")
    s.add_argument(
        "--coordinator-timeout",
        type=float,
        default=COORDINATOR_TIMEOUT_S,
        metavar="SECONDS",
        help="after the setup, end (exit status 1) when the coordinator has sent nothing, not "
        "even a beat, for this long, or when lines wait to go and the connection to it has "
        f"been down this long (default {COORDINATOR_TIMEOUT_S:g}; 0: wait forever; else at "
        f"least {MIN_COORDINATOR_TIMEOUT_S:g})",
    )
    s.add_argument(
        "--shots",
        type=zmq_endpoint,
        help="the pulse endpoint itself (as the coordinator spawns them)",
    )
    s.add_argument("--results", type=zmq_endpoint, help="the results endpoint itself")
    s.add_argument(
        "--parent-pid",
        type=int,
        help="end when this process is gone (set by a coordinator that starts its workers)",
    )
    s.set_defaults(func=cmd_swath_worker)
