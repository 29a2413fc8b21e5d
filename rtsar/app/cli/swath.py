"""The ``swath-worker`` command: one range slice of a split live pipeline (rtsar.stream.swath)."""

from __future__ import annotations

import sys

from ...stream.swath import serve, worker_endpoints
from .options import die


def cmd_swath_worker(args) -> int:
    if args.connect:
        shots, results = worker_endpoints(args.connect, args.index)
    elif args.shots and args.results:
        shots, results = args.shots, args.results
    else:
        return die("give --connect tcp://HOST:PORT (or --shots and --results)")
    if args.index < 0:
        return die(f"--index must be >= 0, got {args.index}")
    log = lambda m: print(m, file=sys.stderr)  # noqa: E731 - one line, one use
    return serve(shots, results, args.index, log, args.parent_pid)


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "swath-worker",
        help="one range slice of a live pipeline split across processes or hosts",
        description="Connect to a coordinator (`rtsar run/replay --swath-workers K "
        "--swath-bind tcp://HOST:PORT`), take its configuration and range columns, run the AO "
        "lens and the shifting CCD of those columns on every pulse block it sends, and send "
        "the lines back; ends when the coordinator's stream ends (exit status 0) or fails "
        "(1).  Local workers are started by the coordinator itself (plain --swath-bind HOST).",
    )
    s.add_argument(
        "--connect",
        metavar="tcp://HOST:PORT",
        help="the coordinator's --swath-bind endpoint (default: none; or --shots/--results)",
    )
    s.add_argument("--index", type=int, default=0, help="this worker's slice, 0 … K-1 (default 0)")
    s.add_argument("--shots", help="the pulse endpoint itself (as the coordinator spawns them)")
    s.add_argument("--results", help="the results endpoint itself")
    s.add_argument(
        "--parent-pid",
        type=int,
        help="end when this process is gone (set by a coordinator that starts its workers)",
    )
    s.set_defaults(func=cmd_swath_worker)
