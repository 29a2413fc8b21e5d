"""What a weighting should give: the theoretical IRW broadening and PSLR of a window."""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as _fft

from .cut import lobe_metrics

#: Minimum zero-padding of :func:`theoretical_irw_factor` / :func:`theoretical_pslr_db`.
THEORY_PAD_FACTOR = 64


def _weights_response(weights) -> tuple[float, float]:
    """``(irw_factor, pslr_db)`` of ``|DFT(weights)|`` against a rect weighting of that length.

    The DFT is zero-padded >= ``THEORY_PAD_FACTOR`` times, fine enough to measure on its grid.
    """
    w = np.asarray(weights)
    if w.ndim != 1 or w.size < 2:
        raise ValueError("weights must be 1-D with at least 2 samples")
    if not np.issubdtype(w.dtype, np.number) or not np.all(np.isfinite(w)):
        raise ValueError("weights must be finite numbers")
    if not np.any(w):
        raise ValueError("weights are all zero")
    n_fft = max(4096, 1 << math.ceil(math.log2(THEORY_PAD_FACTOR * w.size)))

    def measure(v: np.ndarray) -> tuple[float, float]:
        response = _fft.fftshift(_fft.fft(v, n=n_fft))
        p = response.real**2 + response.imag**2
        i_peak = int(np.argmax(p))
        irw, pslr_db, _ = lobe_metrics(p, i_peak, float(i_peak), float(p[i_peak]), 10.0)
        return irw, pslr_db

    irw_w, pslr_db = measure(w.astype(np.complex128))
    irw_rect, _ = measure(np.ones(w.size, dtype=np.complex128))
    if not (math.isfinite(irw_w) and math.isfinite(irw_rect)):
        raise ValueError("the response of these weights has no measurable -3 dB width")
    return irw_w / irw_rect, pslr_db


def theoretical_irw_factor(weights: np.ndarray) -> float:
    """IRW broadening factor of an aperture (spectral) weighting.

    Parameters
    ----------
    weights : np.ndarray
        1-D weights across the aperture or spectrum (length >= 2).

    Returns
    -------
    float
        -3 dB width of ``|DFT(weights)|`` (zero-padded >= 64x) divided by that of a rectangular
        weighting of the same length: 1.0 for rect, ~1.63 for Hann, ~1.47 for Hamming
        (symmetric windows of length n span n - 1 intervals, hence a factor n / (n - 1)).

    Raises
    ------
    ValueError
        For empty, too short, non-finite or all-zero weights, or a response whose half-power
        level is not crossed.
    """
    return _weights_response(weights)[0]


def theoretical_pslr_db(weights: np.ndarray) -> float:
    """Peak sidelobe ratio (dB) of ``|DFT(weights)|`` (zero-padded >= 64x).

    Parameters
    ----------
    weights : np.ndarray
        1-D weights across the aperture or spectrum (length >= 2).

    Returns
    -------
    float
        PSLR in dB (about -13.26 for rect, -31.5 for Hann, -42.7 for Hamming).

    Raises
    ------
    ValueError
        For empty, too short, non-finite or all-zero weights.
    """
    return _weights_response(weights)[1]
