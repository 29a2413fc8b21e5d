"""Options of ``rtsar run`` beyond the live pipeline's: the raw recording (``--record``,
rtsar.sinks.raw_record), the link's silence (``--link-timeout``, rtsar.stream.link) and the
wait for an instrument at the start (``--connect-timeout``, rtsar.sources.serial)."""

from __future__ import annotations

import argparse


def positive_seconds(text: str) -> float:
    """An argparse type: seconds > 0 (else argparse's one-line error, exit status 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0 seconds, got {text}")
    return value


def seconds_at_least_zero(text: str) -> float:
    """An argparse type: seconds >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0 seconds, got {text}")
    return value


def add_run_options(source_group, parser) -> None:
    """--link-timeout and --connect-timeout (in the source group) and --record (beside -o)."""
    source_group.add_argument(
        "--connect-timeout",
        type=seconds_at_least_zero,
        metavar="S",
        help="with --serial: when the port cannot be opened at the start (an instrument not "
        "listening yet), try again for S seconds before giving up, exit status 2 (default: 10 "
        "for socket://, 0 for serial devices)",
    )
    source_group.add_argument(
        "--link-timeout",
        type=positive_seconds,
        metavar="S",
        help="end the run, exit status 1, when the source has delivered no shot for S seconds "
        "(a link gone quiet; default: never). Whatever this says, a silence of max(1 s, 10 pulse "
        "periods) is told on the status line and in the log, and again when shots resume",
    )
    parser.add_argument(
        "--record",
        metavar="RAW.h5",
        help="also keep the raw shots as a recording, written while the run images: every "
        "channel, the instrument's pulse numbers and clock, the gaps and flags as ingest saw "
        "them, the configuration; `rtsar process RAW.h5` or `rtsar replay RAW.h5` gives this "
        "run's image again (or another, with other options). Crash-safe like -o; written by a "
        "process of its own behind a bounded queue: shots a slow disk could not take are "
        "counted (record_dropped) and marked in the file, the imaging never waits; a stop "
        "gives the recording 5 s to finish, then gives it up and says how many shots it may "
        "lack. A file that exists is refused before the run: a recording is never replaced "
        "(docs/pages/guide/live.md, 'Recording a live run')",
    )


def add_wait_subscribers(s) -> None:
    """--wait-subscribers (run of a simulated scene, replay, demo)."""
    s.add_argument(
        "--wait-subscribers",
        type=int,
        default=0,
        metavar="N",
        help="wait until N subscribers are connected before starting (default 0)",
    )
