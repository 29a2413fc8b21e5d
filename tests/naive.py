"""Deliberately naive loops: independent references for the vectorised library references."""

import numpy as np


def correlate_loops(lines, mask):
    """g[p, r] = Σ_k line[p-N+1+k, r] mask[k, r] (Psaltis eq. 5 discretised), plain loops."""
    n, nr = mask.shape
    out = np.zeros((len(lines) - n + 1, nr), np.complex128)
    for p in range(out.shape[0]):
        for k in range(n):
            out[p] += lines[p + k] * mask[k]
    return out


def dft_loops(x, sign, n):
    """Unnormalised DFT of a 1-D sequence by the definition."""
    k = np.arange(n)[:, None]
    m = np.arange(len(x))[None, :]
    return (np.exp(sign * 2j * np.pi * k * m / n) * x[None, :]).sum(axis=1)
