"""The returns of many scatterers at once: sums of windowed complex tones (numba).

Every return the simulator writes (rtsar.scene.simulator) has a phase quadratic in the sample
index n with one quadratic coefficient shared by all scatterers, so a shot factors as

    s[n] = Q[n] · Σ_j g_j · exp(i2π(α_j + β_j n)) · [lo_j ≤ n < hi_j]

* pulsed (Psaltis eq. 1): with a_j = τ_open − τ_j − Tp/2 the chirp phase K/2 (a_j + n/fs)² splits
  into K n²/(2fs²) (in Q, shared), K a_j n/fs (β_j) and K a_j²/2 (in α_j with −2R_j/λ);
* FMCW after dechirp (Crouch eq. 3.4): the beat is already a tone (Q = 1, the whole shot).

α_j, β_j and Q are formed in float64 and reduced mod 1 cycle; the tone is then advanced sample by
sample by complex multiplications (four interleaved recurrences w_{n+4} = w_n · exp(i2π·4β_j)),
re-anchored on exactly evaluated phasors every ``ANCHOR`` samples, so the rounding of the
recurrence stays below ~ANCHOR/4 · 1e-15 of each amplitude — far under the complex64 cast of a
shot (tests compare with the direct formula at 1e-9).  This
is what makes an extended, diffuse scene affordable live: one multiply-add per scatterer and
sample instead of an exponential.
"""

from __future__ import annotations

import math

import numba
import numpy as np

ANCHOR = 256  # samples between exactly evaluated phasors


@numba.njit(nogil=True, cache=True)
def _phasor(gain_re, gain_im, cycles):
    """gain · exp(i2π cycles), cycles reduced mod 1 first (float64)."""
    c = cycles - math.floor(cycles)
    co = math.cos(2.0 * math.pi * c)
    si = math.sin(2.0 * math.pi * c)
    return gain_re * co - gain_im * si, gain_re * si + gain_im * co


@numba.njit(nogil=True, cache=True)
def _tone_sum(out, lo, hi, alpha, beta, gain_re, gain_im, anchor):
    # Four interleaved recurrences (samples n, n+1, n+2, n+3, each stepped by exp(i2π·4β)), so
    # the multiplications of one chain do not wait for the previous ones.
    for j in range(lo.shape[0]):
        al, be = alpha[j], beta[j]
        zr, zi = _phasor(1.0, 0.0, be)  # one sample's step
        z2r, z2i = zr * zr - zi * zi, 2.0 * zr * zi
        sr, si = z2r * z2r - z2i * z2i, 2.0 * z2r * z2i  # four samples' step
        n, h = lo[j], hi[j]
        while n < h:
            stop = min(h, n + anchor)
            ar, ai = _phasor(gain_re[j], gain_im[j], al + be * n)  # exact at the anchor
            br, bi = ar * zr - ai * zi, ar * zi + ai * zr
            cr, ci = ar * z2r - ai * z2i, ar * z2i + ai * z2r
            dr, di = cr * zr - ci * zi, cr * zi + ci * zr
            while n + 4 <= stop:
                out[n] += complex(ar, ai)
                out[n + 1] += complex(br, bi)
                out[n + 2] += complex(cr, ci)
                out[n + 3] += complex(dr, di)
                ar, ai = ar * sr - ai * si, ar * si + ai * sr
                br, bi = br * sr - bi * si, br * si + bi * sr
                cr, ci = cr * sr - ci * si, cr * si + ci * sr
                dr, di = dr * sr - di * si, dr * si + di * sr
                n += 4
            if n < stop:
                out[n] += complex(ar, ai)
                n += 1
            if n < stop:
                out[n] += complex(br, bi)
                n += 1
            if n < stop:
                out[n] += complex(cr, ci)
                n += 1


@numba.njit(nogil=True, cache=True)
def _pulsed_tones(
    r, t_open_s, fs_hz, k_hz_per_s, tp_s, lam_m, c_m_per_s, samples, lo, hi, alpha, beta
):
    """Window and tone of each pulsed return (see pulsed_returns), float64 throughout, into
    lo, hi, alpha and beta (allocated by the caller: numba's allocation code is ~0.3 s more to
    compile on a first run)."""
    m = r.shape[0]
    for j in range(m):
        tau = 2.0 * r[j] / c_m_per_s
        lo[j] = max(0, math.ceil((tau - t_open_s) * fs_hz))
        hi[j] = min(samples, math.ceil((tau + tp_s - t_open_s) * fs_hz))
        a = t_open_s - tau - 0.5 * tp_s
        # α = −2R/λ + K a²/2, β = K a/fs, each reduced mod 1 cycle
        carrier = -2.0 * r[j] / lam_m
        chirp = 0.5 * k_hz_per_s * a * a
        al = (carrier - math.floor(carrier)) + (chirp - math.floor(chirp))
        alpha[j] = al - math.floor(al)
        be = k_hz_per_s * a / fs_hz
        beta[j] = be - math.floor(be)


def pulsed_returns(
    samples: int,
    range_m: np.ndarray,
    gain: np.ndarray,
    t_open_s: float,
    sample_rate_hz: float,
    chirp_rate_hz_per_s: float,
    pulse_duration_s: float,
    wavelength_m: float,
    c_m_per_s: float,
    chirp_phasor: np.ndarray,
) -> np.ndarray:
    """Pulsed returns (Psaltis eq. 1 at baseband) of scatterers at ``range_m`` with ``gain``.

    Sample n (time t_n = t_open + n/fs) of the return from range R, delay τ = 2R/c, within the
    pulse's samples ceil((τ − t_open) fs) ≤ n < ceil((τ + Tp − t_open) fs):
    g · exp i2π[−2R/λ + K/2 (t_n − τ − Tp/2)²], as the factored tone of the module docstring;
    ``chirp_phasor`` is quadratic_phasor(samples, K/(2 fs²)).  complex128[samples].
    """
    r = np.require(range_m, np.float64, ["C", "W"])  # (a read-only array: another specialisation)
    lo, hi = np.empty(len(r), np.int64), np.empty(len(r), np.int64)
    alpha, beta = np.empty(len(r)), np.empty(len(r))
    # Every scalar cast here: an int or float32 would compile another specialisation.
    figures = (t_open_s, sample_rate_hz, chirp_rate_hz_per_s, pulse_duration_s, wavelength_m)
    _pulsed_tones(r, *map(float, figures), float(c_m_per_s), int(samples), lo, hi, alpha, beta)
    g = np.asarray(gain, np.complex128)
    out = np.zeros(samples, np.complex128)
    _tone_sum(out, lo, hi, alpha, beta, g.real.copy(), g.imag.copy(), ANCHOR)
    out *= chirp_phasor
    return out


def tone_sum(
    samples: int,
    lo: np.ndarray,
    hi: np.ndarray,
    alpha_cycles: np.ndarray,
    beta_cycles: np.ndarray,
    gain: np.ndarray,
) -> np.ndarray:
    """Σ_j gain_j · exp(i2π(α_j + β_j n)) over lo_j ≤ n < hi_j, for n in [0, samples).

    Parameters
    ----------
    samples : int
        Length of the output.
    lo, hi : int arrays
        Each tone's sample window (clipped to [0, samples); empty windows add nothing).
    alpha_cycles, beta_cycles : float64 arrays
        Phase at n = 0 and phase step per sample, in cycles (reduced mod 1 here).
    gain : complex array
        Complex amplitude of each tone.

    Returns
    -------
    complex128[samples]
    """
    out = np.zeros(samples, np.complex128)
    g = np.asarray(gain, np.complex128)  # (none: the kernel still runs, so a warm-up compiles it)
    _tone_sum(
        out,
        np.clip(np.asarray(lo, np.int64), 0, samples),
        np.clip(np.asarray(hi, np.int64), 0, samples),
        np.mod(np.asarray(alpha_cycles, np.float64), 1.0),
        np.mod(np.asarray(beta_cycles, np.float64), 1.0),
        np.ascontiguousarray(g.real),
        np.ascontiguousarray(g.imag),
        ANCHOR,
    )
    return out


def kernels_compiled() -> int:
    """How many of this module's kernel specialisations numba compiled in this process rather
    than loaded from its cache (``cache=True``: 0 after the first run of an installation)."""
    stats = [getattr(k, "stats", None) for k in (_phasor, _tone_sum, _pulsed_tones)]
    return sum(sum(s.cache_misses.values()) for s in stats if s is not None)  # None: no JIT


def kernels_cached(pulsed: bool) -> bool | None:
    """Whether numba's on-disk cache holds this installation's kernels for a scene of this
    kind (``pulsed``: a pulsed chirp's three, else an FMCW chirp's two), read from the caches'
    index files without compiling; None where that cannot be told (no JIT, another numba)."""
    kernels = (_phasor, _tone_sum) + ((_pulsed_tones,) if pulsed else ())
    try:
        return all(bool(k._cache._cache_file._load_index()) for k in kernels)
    except Exception:  # numba's private layout: not knowing is not an error
        return None


def quadratic_phasor(samples: int, cycles_per_sample2: float) -> np.ndarray:
    """Q[n] = exp(i2π · (c n² mod 1)), n = 0 … samples − 1 (the shared chirp factor), float64."""
    n = np.arange(samples, dtype=np.float64)
    return np.exp(2j * math.pi * np.mod(cycles_per_sample2 * n * n, 1.0))
