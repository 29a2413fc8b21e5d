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

Grid conventions (gradients, residues): rtsar.topo.phase.
"""

from __future__ import annotations

import numpy as np

from ..phase import TWO_PI, wrap
from .phase import as_mask, as_phase, as_weights
from .unwrap_ls import unwrap_least_squares
from .unwrap_mcf import unwrap_min_cost_flow

METHODS = ("ls", "mcf", "skimage")


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
    valid = None if mask is None else as_mask(mask, shape)
    psi = as_phase(wrapped_rad, valid)
    w = None if weights is None else as_weights(weights, psi.shape, valid)
    if method == "skimage" and w is not None:
        raise ValueError("the 'skimage' peer takes no weights; pass weights=None or use 'mcf'/'ls'")
    if valid is not None and not valid.any():
        return np.zeros(psi.shape)
    work = psi if valid is None else np.where(valid, psi, 0.0)
    if method == "ls":
        out = unwrap_least_squares(work, mask=valid, weights=w)
    elif method == "mcf":
        out = unwrap_min_cost_flow(work, mask=valid, weights=w)
    else:
        out = _unwrap_skimage(work, valid)
    if valid is not None:
        out[~valid] = 0.0
    return out


def unwrap_quality(wrapped_rad, mask, method: str = "mcf", quality=None) -> np.ndarray:
    """:func:`unwrap` weighted by a pixel quality (the coherence) where the method takes weights
    ("ls", "mcf"); the peer ("skimage") unwraps unweighted.  Masked pixels → 0.0, never NaN."""
    return unwrap(
        np.asarray(wrapped_rad, np.float64),
        method=method,
        mask=np.asarray(mask, bool),
        weights=None if method == "skimage" else quality,
    )


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
