"""What every export checks before it writes: shots holding NaN/Inf are zeroed and counted (a
standard file never carries NaN it did not say it had); shot times out of order and a strip
map with fewer than two full-aperture lines are refused in one line naming the recording
(issue 28; the rules: docs/pages/reference/faults.md)."""

from __future__ import annotations

import numpy as np


def zero_nonfinite(shots: np.ndarray) -> tuple[np.ndarray, int]:
    """(``shots`` with every shot [pulse, sample] that holds NaN/Inf set to zero, how many were);
    as ``process`` treats them (rtsar.stream), so an export and the image agree."""
    bad = ~np.isfinite(shots).all(axis=-1)
    count = int(bad.sum())
    if count:
        shots = np.array(shots, copy=True)
        shots[bad] = 0
    return shots, count


def first_step_back(time_s) -> int | None:
    """The first shot whose time is not after its predecessor's (None: the times increase)."""
    steps = np.diff(np.asarray(time_s, np.float64))
    bad = np.flatnonzero(~(steps > 0))
    return None if not len(bad) else int(bad[0]) + 1


def time_order_note(rec) -> str | None:
    """One line saying that ``rec``'s shot times do not increase (how often, the first shot),
    None when they do."""
    time_s = np.asarray(rec.time_s, np.float64)
    k = first_step_back(time_s)
    if k is None:
        return None
    count = int(np.sum(~(np.diff(time_s) > 0)))
    now, before = float(time_s[k]), float(time_s[k - 1])
    return (
        f"{rec.path}: the shot times (time_s) do not increase at {count} of {len(time_s) - 1} "
        f"steps, first at shot {k} ({now!r} s after {before!r} s at shot {k - 1})"
    )


def require_increasing_times(rec, what: str) -> None:
    """ValueError (one line naming the recording and shot) where ``rec``'s shot times do not
    increase: ``what`` (e.g. "CPHD") needs them to (CPHD: TxTime increases vector by vector)."""
    note = time_order_note(rec)
    if note:
        raise ValueError(f"{note}: {what} needs them to increase; not written")


def require_full_aperture(rec, aperture_pulses: int, what: str) -> None:
    """ValueError where a strip map holds fewer than two full-aperture lines (aperture + 1
    shots): with none the image area ``what`` declares runs backwards, with one it has no extent
    along track (sarkit and sarpy refuse both; ``process`` refuses fewer than one line)."""
    if rec.pulses < aperture_pulses + 1:
        lines = max(rec.pulses - aperture_pulses + 1, 0)
        raise ValueError(
            f"{rec.path} holds {rec.pulses} shots, {lines} full-aperture line(s) with the "
            f"aperture of {aperture_pulses}: the image area a {what} declares needs two lines "
            f"({aperture_pulses + 1} shots); not written"
        )
