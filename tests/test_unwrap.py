"""2-D phase unwrapping (rtsar.topo.unwrap): residues, least squares, min-cost flow, the peer.

Truth is the phase the test builds (surfaces and ramps in radians); references are dense NumPy
float64 least-squares solves and hand-counted residues.  Phase noise comes from correlated circular
Gaussian pairs (an interferogram of coherence γ, averaged over a few looks), seeded.
"""

import json
import warnings

import numpy as np
import pytest

from rtsar.phase import wrap
from rtsar.topo.phase import residues, wrapped_gradients
from rtsar.topo.unwrap import unwrap
from rtsar.topo.unwrap_ls import edge_weights, least_squares_phase, solve_poisson_dct
from rtsar.topo.unwrap_mcf import (
    cycle_corrections,
    gradient_costs,
    integrate_cycles,
    integrate_cycles_on,
)

TWO_PI = 2.0 * np.pi


def noisy_interferogram(truth_rad, coherence, looks, seed):
    """Wrapped phase of ``Σ s1 s2* · exp(i·truth)`` for circular Gaussian pairs of correlation γ."""
    rng = np.random.default_rng(seed)
    shape = (looks, *truth_rad.shape)
    a = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2)
    b = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2)
    g = np.broadcast_to(coherence, truth_rad.shape)
    ifg = (a * np.conj(g * a + np.sqrt(1 - g**2) * b)).sum(axis=0)
    return np.angle(ifg * np.exp(1j * truth_rad))


def grid(rows, cols):
    y, x = np.mgrid[0:rows, 0:cols].astype(np.float64)
    return y, x


def smooth_surface(rows=64, cols=80):
    """Sphere cap on a ramp: ~9 fringes, every true gradient below 0.8π (no residues)."""
    y, x = grid(rows, cols)
    r2 = (x - 40.0) ** 2 + (y - 30.0) ** 2
    cap = np.where(
        r2 < 25.0**2, np.sqrt(np.maximum(40.0**2 - r2, 0.0)) - np.sqrt(40.0**2 - 25.0**2), 0
    )
    return 0.35 * x + 0.1 * y + 1.2 * cap


def offset_cycles(unwrapped, truth, where=None):
    """``(unwrapped − truth) / 2π`` on ``where``; must be one integer for a correct unwrap."""
    d = (unwrapped - truth) / TWO_PI
    return d if where is None else d[where]


def dense_ls_reference(psi, u_row=None, u_col=None):
    """Weighted least squares by a dense float64 solve of ``min Σ U (Dφ − Δ)²`` (zero mean)."""
    rows, cols = psi.shape
    d_row = wrap(np.diff(psi, axis=0)).ravel()
    d_col = wrap(np.diff(psi, axis=1)).ravel()
    n = rows * cols
    idx = np.arange(n).reshape(rows, cols)
    eqs = []
    for a, b in ((idx[:-1, :], idx[1:, :]), (idx[:, :-1], idx[:, 1:])):
        for i, j in zip(a.ravel(), b.ravel(), strict=True):
            e = np.zeros(n)
            e[i], e[j] = -1.0, 1.0
            eqs.append(e)
    d = np.array(eqs)
    g = np.concatenate([d_row, d_col])
    u = np.ones(g.size) if u_row is None else np.concatenate([u_row.ravel(), u_col.ravel()])
    phi = np.linalg.lstsq(d * np.sqrt(u)[:, None], g * np.sqrt(u), rcond=None)[0]
    return phi.reshape(rows, cols)


# --- residues ---------------------------------------------------------------------------------


def test_residue_of_a_hand_made_loop():
    # Around (0,0) → (0,1) → (1,1) → (1,0): steps +2π/3, W(−4π/3) = +2π/3, +2π/3, 0 → one cycle.
    psi = np.array([[0.0, 2 * np.pi / 3], [0.0, -2 * np.pi / 3]])
    assert residues(psi).tolist() == [[1]]
    assert residues(-psi).tolist() == [[-1]]
    assert residues(np.array([[0.0, 1.0], [0.5, 1.5]])).tolist() == [[0]]


def test_residues_of_two_vortices_sit_where_they_were_put():
    y, x = grid(12, 14)
    # +1 vortex inside loop (row 2, col 3); −1 vortex inside loop (row 7, col 9); x = col, y = row.
    psi = wrap(np.angle((x - 3.5) + 1j * (y - 2.5)) - np.angle((x - 9.4) + 1j * (y - 7.6)))
    expected = np.zeros((11, 13), dtype=int)
    expected[2, 3] = 1
    expected[7, 9] = -1
    np.testing.assert_array_equal(residues(psi), expected)
    # A mask that removes pixel (3, 4) removes the residues of the four loops touching it.
    mask = np.ones(psi.shape, bool)
    mask[3, 4] = False
    got = residues(psi, mask)
    assert got[2, 3] == 0 and got[7, 9] == -1


# --- least squares against a dense reference ------------------------------------------------


def test_dct_poisson_solver_matches_dense_least_squares():
    rng = np.random.default_rng(7)
    psi = wrap(rng.uniform(-np.pi, np.pi, (6, 7)) + np.cumsum(rng.normal(0, 1.5, (6, 7)), axis=1))
    ref = dense_ls_reference(psi)
    got, iterations, converged = least_squares_phase(psi)
    assert iterations == 0 and converged
    np.testing.assert_allclose(got - got.mean(), ref - ref.mean(), atol=1e-10)
    # The solver alone: Dᵀ D φ = rhs for a zero-sum rhs, checked by applying the operator.
    rhs = rng.normal(size=(6, 7))
    rhs -= rhs.mean()
    phi = solve_poisson_dct(rhs)
    lap = np.zeros_like(phi)
    dr, dc = np.diff(phi, axis=0), np.diff(phi, axis=1)
    lap[:-1] -= dr
    lap[1:] += dr
    lap[:, :-1] -= dc
    lap[:, 1:] += dc
    np.testing.assert_allclose(lap, rhs, atol=1e-10)


def test_weighted_pcg_matches_dense_weighted_least_squares():
    rng = np.random.default_rng(8)
    psi = wrap(rng.uniform(-np.pi, np.pi, (7, 6)))
    w = rng.uniform(0.1, 1.0, psi.shape)
    u_row, u_col = edge_weights(w)
    np.testing.assert_allclose(u_row, np.minimum(w[1:] ** 2, w[:-1] ** 2))
    ref = dense_ls_reference(psi, u_row, u_col)
    got, iterations, converged = least_squares_phase(psi, u_row, u_col, rtol=1e-12)
    assert converged and 0 < iterations < 200
    np.testing.assert_allclose(got - got.mean(), ref - ref.mean(), atol=1e-8)


# --- min-cost flow pieces ---------------------------------------------------------------------


def corrected_loop_sums(psi, k_row, k_col):
    d_row, d_col = wrapped_gradients(psi)
    d_row = d_row + TWO_PI * k_row
    d_col = d_col + TWO_PI * k_col
    return (d_col[:-1, :] + d_row[:, 1:] - d_col[1:, :] - d_row[:, :-1]) / TWO_PI


def test_min_cost_flow_cancels_residues_at_least_cost():
    # A dipole three loops apart in the middle of a 12×14 grid: the cheapest cut crosses 3.
    y, x = grid(12, 14)
    psi = wrap(np.angle((x - 4.5) + 1j * (y - 5.5)) - np.angle((x - 7.5) + 1j * (y - 5.5)))
    charge = residues(psi)
    assert np.abs(charge).sum() == 2
    uniform = gradient_costs(psi.shape, None, None)
    assert uniform[0].min() == uniform[0].max() == uniform[1].min() == uniform[1].max() > 0
    k_row, k_col = cycle_corrections(charge, *uniform)
    assert np.abs(k_row).sum() + np.abs(k_col).sum() == 3
    np.testing.assert_allclose(corrected_loop_sums(psi, k_row, k_col), 0.0, atol=1e-9)
    # A single residue next to the top border goes to the earth: one correction.
    single = np.zeros((9, 9), np.int8)
    single[0, 4] = 1
    k_row, k_col = cycle_corrections(single, np.ones((9, 10), np.int64), np.ones((10, 9), np.int64))
    assert np.abs(k_row).sum() + np.abs(k_col).sum() == 1
    assert abs(k_col[0, 4]) == 1


def test_mcf_cut_follows_low_weights():
    # Dipole in loops (8, 8) and (8, 13).  Pixel rows 8–9 have weight 1, all others 0.2, so the
    # straight cut costs 5 × 100 while the least-cost one steps out of the band (100), runs five
    # loops along it at 20 each and steps back (100): 300, with 7 corrections instead of 5.
    y, x = grid(16, 24)
    psi = wrap(np.angle((x - 8.5) + 1j * (y - 8.5)) - np.angle((x - 13.5) + 1j * (y - 8.5)))
    charge = residues(psi)
    assert charge[8, 8] == 1 and charge[8, 13] == -1 and np.abs(charge).sum() == 2
    w = np.where((y == 8) | (y == 9), 1.0, 0.2)
    cost_row, cost_col = gradient_costs(psi.shape, None, w)
    k_row, k_col = cycle_corrections(charge, cost_row, cost_col)
    np.testing.assert_allclose(corrected_loop_sums(psi, k_row, k_col), 0.0, atol=1e-9)
    assert (np.abs(k_row) * cost_row).sum() + (np.abs(k_col) * cost_col).sum() == 300
    assert np.abs(k_row).sum() + np.abs(k_col).sum() == 7
    plain = cycle_corrections(charge, *gradient_costs(psi.shape, None, None))
    assert np.abs(plain[0]).sum() + np.abs(plain[1]).sum() == 5


def test_spanning_forest_integration_equals_grid_integration():
    rng = np.random.default_rng(4)
    # An irrotational integer field: the differences of a random integer map.
    k_true = rng.integers(-5, 6, (10, 11))
    n_row = np.diff(k_true, axis=0)
    n_col = np.diff(k_true, axis=1)
    np.testing.assert_array_equal(integrate_cycles(n_row, n_col), k_true - k_true[0, 0])
    valid = np.ones(k_true.shape, bool)
    got = integrate_cycles_on(
        n_row, n_col, np.ones(n_row.shape, bool), np.ones(n_col.shape, bool), valid
    )
    np.testing.assert_array_equal(got - got[0, 0], k_true - k_true[0, 0])
    # With a hole and two separate islands: each island is right up to its own constant.
    valid[3:6, 3:7] = False
    valid[:, 9] = False
    got = integrate_cycles_on(
        n_row, n_col, np.ones(n_row.shape, bool), np.ones(n_col.shape, bool), valid
    )
    for island in (valid & (np.arange(11) < 9)[None, :], valid & (np.arange(11) > 9)[None, :]):
        d = (got - k_true)[island]
        assert np.all(d == d[0])
    assert np.all(got[~valid] == 0)


# --- the contract: all three methods ----------------------------------------------------------


@pytest.mark.parametrize("method", ["ls", "mcf", "skimage"])
def test_smooth_surface_recovered_up_to_2pi_k(method):
    truth = smooth_surface()
    psi = wrap(truth)
    assert np.abs(residues(psi)).sum() == 0
    d = offset_cycles(unwrap(psi, method), truth)
    assert np.ptp(d) < 1e-8 and abs(d.mean() - np.rint(d.mean())) < 1e-8


@pytest.mark.parametrize("method", ["ls", "mcf", "skimage"])
def test_smooth_surface_with_mask_and_nan_outside(method):
    truth = smooth_surface()
    y, x = grid(*truth.shape)
    valid = (x - 40.0) ** 2 + (y - 30.0) ** 2 < 28.0**2
    psi = np.where(valid, wrap(truth), np.nan)  # no return outside the target
    got = unwrap(psi, method, mask=valid)
    assert np.isfinite(got).all() and np.all(got[~valid] == 0.0)
    d = offset_cycles(got, truth, valid)
    assert np.ptp(d) < 1e-6 and abs(d.mean() - np.rint(d.mean())) < 1e-6
    if method != "skimage":  # weighted variants (coherence-like weights)
        w = np.where(valid, 0.3 + 0.7 * np.exp(-((x - 40.0) ** 2) / 400.0), 0.0)
        d = offset_cycles(unwrap(psi, method, mask=valid, weights=w), truth, valid)
        assert np.ptp(d) < 1e-5 and abs(d.mean() - np.rint(d.mean())) < 1e-5


@pytest.mark.parametrize("method", ["mcf", "skimage"])
def test_congruent_with_input_on_noisy_data(method):
    y, x = grid(48, 56)
    truth = 0.5 * np.pi * x + 0.05 * y**1.5
    psi = noisy_interferogram(truth, 0.6, 2, seed=11) + TWO_PI * 3  # any real values are accepted
    assert np.abs(residues(psi)).sum() > 50
    valid = np.ones(psi.shape, bool)
    valid[10:20, 15:40] = False
    for mask in (None, valid):
        got = unwrap(psi, method, mask=mask)
        cycles = (got - psi) / TWO_PI
        on = np.ones(psi.shape, bool) if mask is None else mask
        np.testing.assert_allclose(cycles[on], np.rint(cycles[on]), atol=1e-9)


def test_least_squares_underestimates_slope_where_mcf_holds():
    # Crouch 2012 ch. 6 / Ghiglia & Pritt ch. 5: residues bias least squares toward flatter slopes.
    n = 96
    y, x = grid(n, n)
    slope = 0.5 * np.pi  # rad per pixel along the columns
    truth = slope * x + 0.05 * slope * y
    psi = noisy_interferogram(truth, 0.6, 4, seed=3)
    assert np.abs(residues(psi)).sum() > 300
    design = np.column_stack([x.ravel(), y.ravel(), np.ones(n * n)])
    fitted = {}
    wrong = {}
    for method in ("ls", "mcf"):
        got = unwrap(psi, method)
        fitted[method] = np.linalg.lstsq(design, got.ravel(), rcond=None)[0][0] / slope
        e = got - truth
        e -= TWO_PI * np.rint(e.mean() / TWO_PI)
        wrong[method] = np.mean(np.abs(e) >= np.pi)
    assert fitted["ls"] < 0.9  # measured 0.83
    assert abs(fitted["mcf"] - 1.0) < 0.01
    assert wrong["mcf"] < 0.02 and wrong["ls"] > 0.3


def test_coherence_weights_or_mask_let_mcf_cut_through_a_dead_band():
    # A band of no return from the left edge to 70 % of the width, on a steep slope across it:
    # unweighted MCF closes the band's noise residues with cuts that split the image (half of it
    # 2π off, measured 48 %); with the coherence as weights, or the band masked, they stay in it.
    y, x = grid(64, 64)
    truth = 0.5 * np.pi * y + 0.2 * x
    band = (np.abs(y - 32) < 3) & (x < 44)
    coh = np.where(band, 0.0, 0.85)
    psi = noisy_interferogram(truth, coh, 4, seed=0)
    wrong = {}
    for label, kwargs in (("plain", {}), ("weights", {"weights": coh}), ("mask", {"mask": ~band})):
        e = (unwrap(psi, "mcf", **kwargs) - truth)[~band]
        e -= TWO_PI * np.rint(e.mean() / TWO_PI)
        wrong[label] = np.mean(np.abs(e) >= np.pi)
    assert wrong["plain"] > 0.3
    assert wrong["weights"] < 0.005 and wrong["mask"] < 0.005


# --- bad input and edge cases -----------------------------------------------------------------


def test_bad_input_raises_clear_errors():
    psi = np.zeros((8, 9))
    with pytest.raises(ValueError, match="method"):
        unwrap(psi, "goldstein")
    with pytest.raises(ValueError, match="2-D"):
        unwrap(np.zeros(9))
    with pytest.raises(ValueError, match="2×2"):
        unwrap(np.zeros((1, 9)))
    with pytest.raises(ValueError, match="real"):
        unwrap(np.exp(1j * psi))
    bad = psi.copy()
    bad[2, 3] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        unwrap(bad)
    with pytest.raises(ValueError, match="mask shape"):
        unwrap(psi, mask=np.ones((8, 8), bool))
    with pytest.raises(ValueError, match="bool"):
        unwrap(psi, mask=np.ones((8, 9)))
    with pytest.raises(ValueError, match="≥ 0"):
        unwrap(psi, weights=-np.ones((8, 9)))
    with pytest.raises(ValueError, match="weights shape"):
        unwrap(psi, weights=np.ones((9, 8)))
    with pytest.raises(ValueError, match="no weights"):
        unwrap(psi, "skimage", weights=np.ones((8, 9)))


@pytest.mark.parametrize("method", ["ls", "mcf", "skimage"])
def test_all_masked_and_zero_weights_give_zeros_not_nan(method):
    psi = np.random.default_rng(0).uniform(-3.0, 3.0, (6, 7))
    assert np.abs(residues(psi)).sum() > 0
    got = unwrap(psi, method, mask=np.zeros(psi.shape, bool))
    assert np.all(got == 0.0)
    if method != "skimage":
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = unwrap(psi, method, weights=np.zeros(psi.shape))
        assert np.isfinite(got).all()
        cycles = (got - psi) / TWO_PI  # no information: the wrapped values come back, congruent
        np.testing.assert_allclose(cycles, np.rint(cycles), atol=1e-9)


def test_unwrap_table_tool_runs_and_scores_the_noise_free_plane(tmp_path, capsys):
    from rtsar.app.reports import unwrap_table as table

    out = tmp_path / "table.json"
    assert table.main(["--size", "24", "--json", str(out)]) == 0
    assert "| steep plane" in capsys.readouterr().out
    rows = {r["interferogram"]: r for r in json.loads(out.read_text())["rows"]}
    plane = rows["steep plane 0.9π/px, noise-free"]
    for method, got in plane["methods"].items():
        assert got["rms_rad"] < 1e-6 and got["wrong_fraction"] == 0.0, method
    # Zhao eq. 1 with the quoted geometry: 2π per 3.3 mm of height.
    assert abs(table.AMBIGUITY_HEIGHT_M - 3.3e-3) < 1e-9
