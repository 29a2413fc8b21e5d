"""Wrapped phase on a 2-D grid: gradients, residues and input checks, shared by every unwrapper.

Grid conventions used by every method: the row gradient ``d_row[i, j] = W(ψ[i+1, j] − ψ[i, j])``
has shape ``(rows − 1, cols)``, the column gradient ``d_col[i, j] = W(ψ[i, j+1] − ψ[i, j])`` has
shape ``(rows, cols − 1)``; the residue of the elementary loop whose top-left pixel is ``(i, j)``
sums the wrapped steps around ``(i, j) → (i, j+1) → (i+1, j+1) → (i+1, j) → (i, j)``, divided by 2π.
With x = column and y = row this loop turns counter-clockwise, so a phase ``arg((x − x0) +
i(y − y0))`` puts a residue of +1 in the loop that holds ``(x0, y0)``.

Wrapping itself (one convention, [-π, π)) is rtsar.phase.wrap.
"""

from __future__ import annotations

import numpy as np

from ..phase import TWO_PI, wrap


def wrapped_gradients(wrapped_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Wrapped differences along rows and columns, ``(d_row, d_col)``.

    Itoh's condition (Ghiglia & Pritt 1998, ch. 1): ``Δψ = W(ψ[k+1] − ψ[k])`` equals the true
    phase difference wherever that is below π in magnitude.
    """
    psi = np.asarray(wrapped_rad, dtype=np.float64)
    return wrap(np.diff(psi, axis=0)), wrap(np.diff(psi, axis=1))


def residues(wrapped_rad: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Residue charge of every elementary 2×2 loop, int8 ``[rows − 1, cols − 1]`` in {−1, 0, +1}.

    Ghiglia & Pritt 1998, ch. 2 (residues); Costantini 1998: the loop sum of the wrapped
    gradients, ``(d_col[i, j] + d_row[i, j+1] − d_col[i+1, j] − d_row[i, j]) / 2π``, is an integer;
    a non-zero value marks a point the unwrapped phase must not be integrated around.  Loop order
    and sign: see the module docstring.  With a ``mask`` (True = valid), loops that touch an invalid
    pixel are reported as 0.
    """
    psi = as_phase(wrapped_rad, None if mask is None else as_mask(mask, np.shape(wrapped_rad)))
    d_row, d_col = wrapped_gradients(psi)
    loop_sum = d_col[:-1, :] + d_row[:, 1:] - d_col[1:, :] - d_row[:, :-1]
    charge = np.rint(loop_sum / TWO_PI).astype(np.int8)
    if mask is not None:
        valid = as_mask(mask, psi.shape)
        charge[~(valid[:-1, :-1] & valid[:-1, 1:] & valid[1:, :-1] & valid[1:, 1:])] = 0
    return charge


def as_mask(mask: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    m = np.asarray(mask)
    if m.shape != tuple(shape):
        raise ValueError(f"mask shape {m.shape} differs from the phase shape {tuple(shape)}")
    if m.dtype != np.bool_:
        raise ValueError(f"mask must be a bool array (True = valid), got dtype {m.dtype}")
    return m


def as_phase(wrapped_rad: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    a = np.asarray(wrapped_rad)
    if a.ndim != 2 or a.shape[0] < 2 or a.shape[1] < 2:
        raise ValueError(f"wrapped phase must be a 2-D array of at least 2×2, got shape {a.shape}")
    if np.iscomplexobj(a):
        raise ValueError("wrapped phase must be real radians; pass np.angle(interferogram)")
    if not np.issubdtype(a.dtype, np.number) or a.dtype == np.bool_:
        raise ValueError(f"wrapped phase must be a real float array, got dtype {a.dtype}")
    a = a.astype(np.float64)
    bad = ~np.isfinite(a) if valid is None else ~np.isfinite(a) & valid
    if bad.any():
        raise ValueError(f"wrapped phase has {int(bad.sum())} non-finite valid pixel(s)")
    return a


def as_weights(weights: np.ndarray, shape: tuple[int, ...], valid: np.ndarray | None):
    w = np.asarray(weights)
    if w.shape != tuple(shape):
        raise ValueError(f"weights shape {w.shape} differs from the phase shape {tuple(shape)}")
    if np.iscomplexobj(w):
        raise ValueError("weights must be real (e.g. the coherence magnitude)")
    w = w.astype(np.float64)
    if valid is not None:
        w = np.where(valid, w, 0.0)
    if not np.isfinite(w).all():
        raise ValueError("weights have non-finite values on valid pixels")
    if (w < 0).any():
        raise ValueError("weights must be ≥ 0")
    return w
