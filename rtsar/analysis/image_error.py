"""How far an image is from its reference: relative rms error (with and without a gain fit)."""

from __future__ import annotations

import numpy as np


def relative_rms(a: np.ndarray, b: np.ndarray) -> float:
    """Relative RMS difference ``||a - b||_2 / ||b||_2`` (float64 accumulation).

    Parameters
    ----------
    a : np.ndarray
        Array under test.
    b : np.ndarray
        Reference, same shape.

    Returns
    -------
    float
        The relative error.

    Raises
    ------
    ValueError
        If the shapes differ or the reference is all zero.
    """
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"shape mismatch: {a.shape} vs {b.shape}")
    dtype = np.result_type(a.dtype, b.dtype, np.float64)
    a64 = a.astype(dtype)
    b64 = b.astype(dtype)
    ref = float(np.linalg.norm(b64.ravel()))
    if ref == 0:
        raise ValueError("reference is all zero: relative error undefined")
    return float(np.linalg.norm((a64 - b64).ravel())) / ref


def gain_fitted_error(image: np.ndarray, reference: np.ndarray) -> float:
    """‖c·image − reference‖ / ‖reference‖ with the best complex gain c: the error that remains
    once an unobservable constant phase (and scale) is allowed — what a phase correction can
    restore, measured against the error-free image."""
    a = np.asarray(image, np.complex128).ravel()
    b = np.asarray(reference, np.complex128).ravel()
    aa = np.vdot(a, a).real
    c = np.vdot(a, b) / aa if aa > 0 else 0.0
    return float(np.linalg.norm(c * a - b) / np.linalg.norm(b))
