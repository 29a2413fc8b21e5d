"""Least-squares phase unwrapping: DCT Poisson solver and preconditioned conjugate gradients.

Ghiglia & Pritt 1998, ch. 5 (minimum-norm methods); Ghiglia & Romero 1994, JOSA A 11(1).  The
unwrapped phase φ minimises ``Σ U_row (φ[i+1,j] − φ[i,j] − Δ_row)² + Σ U_col (φ[i,j+1] − φ[i,j] −
Δ_col)²`` over the wrapped gradients Δ (``rtsar.topo.phase.wrapped_gradients``).  With D the
forward-difference operator, the normal equations are ``Dᵀ U D φ = Dᵀ U Δ``: a discrete Poisson
equation with Neumann boundaries.  Unweighted (U = 1) it is diagonal in the DCT-II basis with
eigenvalues ``(2 − 2 cos(π p / M)) + (2 − 2 cos(π q / N))``, which gives the direct solver;
weighted, it is solved by conjugate gradients with that direct solver as preconditioner.

Known limits (Crouch 2012, ch. 6; Ghiglia & Pritt ch. 5): the solution is not congruent with the
data, and residues make it smooth across the places where the phase should jump, so slopes come out
too small and the error spreads over the whole image instead of staying local.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy import fft, ndimage

from ..phase import TWO_PI, wrap
from .phase import wrapped_gradients


def solve_poisson_dct(rhs: np.ndarray) -> np.ndarray:
    """Solve ``Dᵀ D φ = rhs`` with Neumann boundaries; the zero-mean solution, float64.

    Ghiglia & Romero 1994 (their eq. for the DCT solution of the Poisson equation):
    ``φ̂[p, q] = ρ̂[p, q] / ((2 − 2 cos(π p / M)) + (2 − 2 cos(π q / N)))`` in the DCT-II domain,
    with φ̂[0, 0] = 0.  Here ``rhs = Dᵀ Δ`` is minus their driving function ρ, so the denominator is
    positive.
    """
    rows, cols = rhs.shape
    lam = (2.0 - 2.0 * np.cos(np.pi * np.arange(rows) / rows))[:, None] + (
        2.0 - 2.0 * np.cos(np.pi * np.arange(cols) / cols)
    )[None, :]
    lam[0, 0] = 1.0
    spec = fft.dctn(rhs, type=2, norm="ortho")
    spec /= lam
    spec[0, 0] = 0.0
    return fft.idctn(spec, type=2, norm="ortho")


def divergence(g_row: np.ndarray, g_col: np.ndarray) -> np.ndarray:
    """``Dᵀ g`` for a gradient field ``(g_row [M−1, N], g_col [M, N−1])``: minus its divergence."""
    out = np.zeros((g_col.shape[0], g_row.shape[1]))
    out[:-1, :] -= g_row
    out[1:, :] += g_row
    out[:, :-1] -= g_col
    out[:, 1:] += g_col
    return out


def weighted_laplacian(phi: np.ndarray, u_row: np.ndarray, u_col: np.ndarray) -> np.ndarray:
    """``Dᵀ U D φ`` (Ghiglia & Pritt 1998, ch. 5, the weighted Poisson operator), float64."""
    return divergence(u_row * np.diff(phi, axis=0), u_col * np.diff(phi, axis=1))


def edge_weights(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient weights from pixel weights: ``U = min(w[a]², w[b]²)`` (Ghiglia & Pritt, ch. 5)."""
    w2 = np.asarray(weights, dtype=np.float64) ** 2
    return np.minimum(w2[1:, :], w2[:-1, :]), np.minimum(w2[:, 1:], w2[:, :-1])


def least_squares_phase(
    psi: np.ndarray,
    u_row: np.ndarray | None = None,
    u_col: np.ndarray | None = None,
    *,
    rtol: float = 1e-6,
    max_iter: int = 1000,
) -> tuple[np.ndarray, int, bool]:
    """Least-squares phase from wrapped ``psi``: ``(phi, iterations, converged)``.

    Unweighted (``u_row is None``): one DCT solve (iterations = 0).  Weighted: preconditioned
    conjugate gradients (Ghiglia & Romero 1994, their PCG algorithm) until the residual norm is
    below ``rtol`` times that of the right-hand side.  ``phi`` is defined up to a constant
    (per connected region of positive weight).
    """
    d_row, d_col = wrapped_gradients(psi)
    if u_row is None:
        return solve_poisson_dct(divergence(d_row, d_col)), 0, True
    b = divergence(u_row * d_row, u_col * d_col)
    x = np.zeros_like(b)
    b_norm = _norm(b)
    if b_norm == 0.0:
        return x, 0, True
    r = b.copy()
    z = solve_poisson_dct(r)
    p = z.copy()
    rz = _dot(r, z)
    for it in range(1, max_iter + 1):
        ap = weighted_laplacian(p, u_row, u_col)
        pap = _dot(p, ap)
        if pap <= 0.0:  # the search direction lies in the null space: nothing left to reduce
            return x, it, _norm(r) <= rtol * b_norm
        alpha = rz / pap
        x += alpha * p
        r -= alpha * ap
        if _norm(r) <= rtol * b_norm:
            return x, it, True
        z = solve_poisson_dct(r)
        rz_new = _dot(r, z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, max_iter, False


def unwrap_least_squares(
    psi: np.ndarray,
    mask: np.ndarray | None = None,
    weights: np.ndarray | None = None,
    *,
    rtol: float = 1e-6,
    max_iter: int = 1000,
) -> np.ndarray:
    """Least-squares unwrapping of a checked float64 phase (call ``rtsar.topo.unwrap.unwrap``).

    Unweighted DCT solution when neither ``mask`` nor ``weights`` is given, otherwise weighted
    PCG with pixel weights ``weights`` (default 1) set to 0 outside ``mask``.  Each connected region
    of positive weight is then moved by the constant that best matches the data modulo 2π,
    ``c = arg Σ w exp(i(ψ − φ))``, so clean regions come out equal to the truth plus a multiple of
    2π.  Valid pixels of zero weight carry no information: they get the wrapped value nearest to the
    solver's.  Warns (RuntimeWarning) if PCG does not converge; the result is still finite.
    """
    if mask is None and weights is None:
        phi, _, _ = least_squares_phase(psi)
        return _align(psi, phi, np.ones(psi.shape, dtype=bool), np.ones(psi.shape))
    w = np.ones(psi.shape) if weights is None else np.array(weights, dtype=np.float64)
    if mask is not None:
        w[~mask] = 0.0
    u_row, u_col = edge_weights(w)
    phi, iterations, converged = least_squares_phase(
        psi, u_row, u_col, rtol=rtol, max_iter=max_iter
    )
    if not converged:
        warnings.warn(
            f"weighted least-squares unwrapping stopped after {iterations} PCG iterations "
            f"before reaching rtol={rtol:g}",
            RuntimeWarning,
            stacklevel=3,
        )
    labels, count = ndimage.label(w > 0.0)  # 4-connected regions of positive weight
    out = psi + TWO_PI * np.rint((phi - psi) / TWO_PI)  # zero-weight pixels: nearest congruent
    for k in range(1, count + 1):
        region = labels == k
        out[region] = _align(psi, phi, region, w)[region]
    return out


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    # Plain sum rather than np.vdot: BLAS threads stall on a loaded machine for so small a product.
    return float(np.sum(a * b))


def _norm(a: np.ndarray) -> float:
    return float(np.sqrt(np.sum(a * a)))


def _align(psi: np.ndarray, phi: np.ndarray, region: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``φ + c``, ``c = arg Σ_region w exp(i W(ψ − φ))``: the constant that best fits ψ mod 2π."""
    s = np.sum(w[region] * np.exp(1j * wrap(psi[region] - phi[region])))
    c = float(np.angle(s)) if abs(s) > 0.0 else 0.0
    return phi + c
