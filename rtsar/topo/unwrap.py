"""Two-dimensional phase unwrapping: one entry point, three methods.

``unwrap(wrapped_rad, method, mask, weights)`` recovers a continuous phase from an interferogram
wrapped into (-π, π] (Zhao et al. 2014, step VI; Crouch 2012, ch. 6 "Phase Unwrapping").  Methods:

* ``"ls"``  least squares, Ghiglia & Pritt 1998 ch. 5: the unweighted Neumann Poisson problem solved
  by the DCT, or the weighted one by conjugate gradients preconditioned with that DCT solver
  (Ghiglia & Romero 1994).  Fast, but not congruent with the data, and biased where residues are
  (slopes come out too small).  See ``rtsar.topo.unwrap_ls``.
* ``"mcf"`` Costantini 1998 minimum-cost flow: integer cycle corrections of the wrapped gradients
  that cancel every residue at least total cost, solved by OR-tools.  Congruent with the data;
  errors stay local.  See ``rtsar.topo.unwrap_mcf``.
* ``"skimage"`` the scikit-image peer (Herráez et al. 2002, reliability-sorted path following), for
  comparison.  Takes no weights.

Arrays are ``[rows, cols]`` (``image[azimuth, range]`` in rtsar).  The mask is True where a pixel is
valid; invalid pixels may hold anything (NaN included) and come back as 0.0.  The output is never
NaN; bad input (wrong shape, complex values, non-finite valid pixels, negative weights) raises
ValueError.

Grid conventions used by every method: the row gradient ``d_row[i, j] = W(ψ[i+1, j] − ψ[i, j])``
has shape ``(rows − 1, cols)``, the column gradient ``d_col[i, j] = W(ψ[i, j+1] − ψ[i, j])`` has
shape ``(rows, cols − 1)``; the residue of the elementary loop whose top-left pixel is ``(i, j)``
sums the wrapped steps around ``(i, j) → (i, j+1) → (i+1, j+1) → (i+1, j) → (i, j)``, divided by 2π.
With x = column and y = row this loop turns counter-clockwise, so a phase ``arg((x − x0) +
i(y − y0))`` puts a residue of +1 in the loop that holds ``(x0, y0)``.
"""

from __future__ import annotations

import numpy as np

METHODS = ("ls", "mcf", "skimage")
TWO_PI = 2.0 * np.pi


def wrap(phase_rad: np.ndarray) -> np.ndarray:
    """Wrap a phase into [-π, π): ``W(φ) = φ − 2π·round(φ / 2π)`` (Ghiglia & Pritt 1998, ch. 1)."""
    return (np.asarray(phase_rad, dtype=np.float64) + np.pi) % TWO_PI - np.pi


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
    psi = _as_phase(wrapped_rad, None if mask is None else _as_mask(mask, np.shape(wrapped_rad)))
    d_row, d_col = wrapped_gradients(psi)
    loop_sum = d_col[:-1, :] + d_row[:, 1:] - d_col[1:, :] - d_row[:, :-1]
    charge = np.rint(loop_sum / TWO_PI).astype(np.int8)
    if mask is not None:
        valid = _as_mask(mask, psi.shape)
        charge[~(valid[:-1, :-1] & valid[:-1, 1:] & valid[1:, :-1] & valid[1:, 1:])] = 0
    return charge


def unwrap(
    wrapped_rad: np.ndarray,
    method: str = "mcf",
    mask: np.ndarray | None = None,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Unwrap a 2-D wrapped phase; float64 ``[rows, cols]``, 0.0 on invalid pixels.

    Parameters
    ----------
    wrapped_rad : real array [rows, cols], rows, cols ≥ 2
        Wrapped phase in radians (any real values; only their value mod 2π is used).
    method : "ls", "mcf" or "skimage"
        See the module docstring.
    mask : bool array [rows, cols], optional
        True where the pixel is valid.  Invalid pixels take no part and come back as 0.0.
    weights : float array [rows, cols], optional
        Quality of each pixel (e.g. coherence), ≥ 0 and finite on valid pixels.  Used by "ls"
        (weighted least squares, Ghiglia & Pritt weights ``min(w²)`` per gradient) and "mcf"
        (arc costs); "skimage" takes none.

    Returns
    -------
    ndarray float64 [rows, cols]
        The unwrapped phase.  For "mcf" and "skimage" it is congruent with the input on valid
        pixels (``unwrapped − wrapped ∈ 2πℤ``).  For "ls" it is the least-squares solution moved by
        the constant that best matches the input modulo 2π, so it differs from the truth by about
        a multiple of 2π where the data are clean.
    """
    if method not in METHODS:
        raise ValueError(f"unknown unwrapping method {method!r}; choose one of {METHODS}")
    shape = np.shape(wrapped_rad)
    valid = None if mask is None else _as_mask(mask, shape)
    psi = _as_phase(wrapped_rad, valid)
    w = None if weights is None else _as_weights(weights, psi.shape, valid)
    if method == "skimage" and w is not None:
        raise ValueError("the 'skimage' peer takes no weights; pass weights=None or use 'mcf'/'ls'")
    if valid is not None and not valid.any():
        return np.zeros(psi.shape)
    work = psi if valid is None else np.where(valid, psi, 0.0)
    if method == "ls":
        from rtsar.topo.unwrap_ls import unwrap_least_squares

        out = unwrap_least_squares(work, mask=valid, weights=w)
    elif method == "mcf":
        from rtsar.topo.unwrap_mcf import unwrap_min_cost_flow

        out = unwrap_min_cost_flow(work, mask=valid, weights=w)
    else:
        out = _unwrap_skimage(work, valid)
    if valid is not None:
        out[~valid] = 0.0
    return out


def _unwrap_skimage(psi: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    """scikit-image's reliability-guided unwrapper (Herráez et al. 2002), made congruent."""
    from skimage.restoration import unwrap_phase

    image = wrap(psi)
    if valid is not None:
        image = np.ma.array(image, mask=~valid)
    got = np.ma.getdata(unwrap_phase(image, rng=0)).astype(np.float64)
    # The peer adds multiples of 2π to its [-π, π) input; rounding the cycle count makes that exact
    # against the caller's values (which need not lie in [-π, π)).
    return psi + TWO_PI * np.rint((got - psi) / TWO_PI)


def _as_mask(mask: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    m = np.asarray(mask)
    if m.shape != tuple(shape):
        raise ValueError(f"mask shape {m.shape} differs from the phase shape {tuple(shape)}")
    if m.dtype != np.bool_:
        raise ValueError(f"mask must be a bool array (True = valid), got dtype {m.dtype}")
    return m


def _as_phase(wrapped_rad: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
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


def _as_weights(weights: np.ndarray, shape: tuple[int, ...], valid: np.ndarray | None):
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
