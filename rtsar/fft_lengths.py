"""FFT lengths the fft correlator may use: products of 2, 3 and 5 (SciPy's and NumPy's FFTs
transform them in O(M log M) with their short radices; the least such length >= n is SciPy's
``scipy.fft.next_fast_len(n, real=True)``)."""

from __future__ import annotations

import numbers


def is_fast_fft_length(m: int) -> bool:
    """Whether ``m`` (an integer, NumPy's too) >= 1 is a product of 2, 3 and 5 only."""
    if not isinstance(m, numbers.Integral) or isinstance(m, bool) or m < 1:
        return False
    m = int(m)
    for p in (2, 3, 5):
        while m % p == 0:
            m //= p
    return m == 1
