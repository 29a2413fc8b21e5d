"""The correlator's block options (``--partition-lines``, ``--tail-block-lines``,
``--fft-length``): each applies to the correlators that read it, and ``--fft-length`` to the
lengths the fft correlator takes.  An option that the correlator named by ``--correlator``
does not read is refused in one line (before, it was ignored without a word)."""

from __future__ import annotations

from scipy.fft import next_fast_len

from ...fft_lengths import is_fast_fft_length

# option → (its argparse name, the correlators that read it)
BLOCK_OPTIONS = {
    "--partition-lines": ("partition_lines", ("partitioned", "nonuniform")),
    "--tail-block-lines": ("tail_block_lines", ("nonuniform",)),
    "--fft-length": ("fft_length", ("fft",)),
}


def check_block_options(args, aperture_pulses: int, configured: str | None = None) -> None:
    """ValueError where a block option given does not apply to ``--correlator``'s correlator
    (without one, ``configured``: the recording's, where the command runs it as it is), or
    ``--fft-length`` is shorter than the aperture or not a product of 2, 3 and 5."""
    given = getattr(args, "correlator", None)
    kind, whose = (given, "the") if given else (configured, "the recording's")
    for option, (name, kinds) in BLOCK_OPTIONS.items():
        if kind and getattr(args, name, None) is not None and kind not in kinds:
            readers = " and ".join(kinds) + (" correlators" if len(kinds) > 1 else " correlator")
            raise ValueError(
                f"{option} sets the block of the {readers}; {whose} {kind} correlator does "
                "not read it (leave it out, or name another --correlator)"
            )
    m, n = getattr(args, "fft_length", None), aperture_pulses
    if m is not None and not (m >= n and is_fast_fft_length(m)):
        rule = f"at least the aperture, N = {n}" if m < n else "a product of 2, 3 and 5"
        raise ValueError(
            f"--fft-length {m}: must be {rule} (the least length >= N that is a product of "
            f"2, 3 and 5 from {max(m, n)} up: {next_fast_len(max(m, n), real=True)})"
        )
