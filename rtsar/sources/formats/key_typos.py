"""A key that is a near miss of one rtsar reads: an instrument file's [data] keeps the keys it
does not read as provenance, but not one that is likely a typo of a key it reads (the key it
meant would silently go unread: ``byteorder`` for ``byte_order`` reads the samples wrongly,
``agc_db`` for ``agc_db_file`` divides no gain out)."""

from __future__ import annotations


def near_miss(key: str, read: str) -> bool:
    """Whether ``key`` is within a letter or two of ``read`` (one for a read key under six
    letters), or ``read`` with one of its words left out."""
    return edits(key, read) <= (2 if len(read) >= 6 else 1) or one_word_short(key, read)


def one_word_short(key: str, read: str) -> bool:
    """Whether ``key``, of two words or more, is the key ``read`` with one of its words
    (between underscores) left out: ``collection_start`` for ``collection_start_utc``,
    ``agc_db`` for ``agc_db_file`` (a cold review: one word, ``type`` for ``sample_type``,
    refused provenance as common as a mode's name)."""
    words, full = key.split("_"), read.split("_")
    if len(words) < 2:  # a single word (type, order, header) is provenance of its own
        return False
    return len(full) == len(words) + 1 and any(
        full[:i] + full[i + 1 :] == words for i in range(len(full))
    )


def edits(a: str, b: str) -> int:
    """The fewest single-letter insertions, deletions, substitutions or swaps of two adjacent
    letters that turn ``a`` into ``b`` (optimal string alignment distance)."""
    d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            d[i][j] = min(
                d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1])
            )
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]
