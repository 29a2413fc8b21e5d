"""HCN start-frequency alignment: fit absorption lines per shot, shift each shot onto the chirp.

Physics (Crouch 2012, ch. 3, "HCN Cell" and Appendix A; Zhao 2014, channel 1)
----------------------------------------------------------------------------
The chirp does not start at the same optical frequency on every shot: Crouch saw the HCN
features move by ~1 ms relative to the trigger, ~10 GHz at 10 THz/s.  A start-frequency offset
δf turns the transmitted frequency into f(t) = f0 + K t + δf and adds -δf·Δτ cycles to a return
of differential delay Δτ (rtsar.focus.linearize, module docstring): a range-dependent phase
that changes from shot to shot and defocuses the azimuth compression away from the LO range.

The cell transmits exp(-A(f(t))) with A a sum of Lorentzian lines at known optical frequencies
f_j.  Fitting a line's dip gives the instant t_j at which f(t_j) = f_j, hence
δf = f_j - f0 - K t_j (one line, as Crouch's MATLAB fit; here the median over every line in the
sweep).  Which dip is which line is settled first by cross-correlating the whole recorded
absorbance with the line model over offsets up to ±``max_offset_hz`` (the comb's unequal
spacings and strengths make a shift by one line spacing a poor match).  Crouch then shifts the
record so its first sample always sees the same frequency; here the shot is resampled at
τ_k = t_k - δf/K (band-limited, rtsar.focus.resample.resample), which restores
exp -i2π Δτ (f0 + K t_k) exactly (no whole-sample rounding).

Line list: a *synthetic* HCN-like comb, not certified line centres.  It is a rigid-rotor P/R band
ν(m) = ν0 + (B' + B'') m + (B' - B'') m², m = -J (P branch), J + 1 (R branch), with constants of
the order of those of the H¹³C¹⁴N 2ν3 band used for 1.53-1.56 µm wavelength references
(ν0 = 194.32 THz ≈ 1542.8 nm, B'' = 43.17 GHz, B' = 42.86 GHz) and Boltzmann strengths at 296 K;
P lines span 1543-1565 nm.  The absolute values are a documented stand-in (the NIST SRM 2519a
table could not be cited from here): simulator and processor share this list, as an instrument
and its calibration sheet do.

Stream stage: raw shots, between ingest and the AO lens (``HCNAligner.process``); or only the
offsets, as the absolute anchor of rtsar.focus.linearize.ChirpLinearizer.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy import fft as sp_fft

from ..instrument import (
    DEFAULT_LINEWIDTH_HZ,
    HCN_CHANNEL,
    channel_times_s,
    hcn_absorbance,
    hcn_lines,
    infer_oversampling,
)
from ..params import FMCWChirp
from ..samples import zero_nonfinite_rows
from .resample import DEFAULT_KAISER_BETA, DEFAULT_TAPS, resample, resample_reference
from .stage import CorrectionStage

# --------------------------------------------------------------------------------------------
# Lorentzian dip fit
# --------------------------------------------------------------------------------------------


def _model(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Absorbance near one line: b0 + b1 x + d / (1 + ((x - x0)/h)²); p = (b0, b1, d, x0, h)."""
    b0, b1, d, x0, h = (p[..., i, None] for i in range(5))
    z = (x - x0) / h
    return b0 + b1 * x + d / (1.0 + z * z)


def _jacobian(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    b0, b1, d, x0, h = (p[..., i, None] for i in range(5))
    z = (x - x0) / h
    den = 1.0 + z * z
    g = 2.0 * d * z / (h * den * den)
    one = np.ones_like(z)
    return np.stack([one, x * one, 1.0 / den, g, g * z], axis=-1)


def _initial(y: np.ndarray, x: np.ndarray, h0: float) -> np.ndarray:
    """Start values from a window centred on its maximum: edges for the baseline, a parabola
    through the three middle samples for the centre."""
    c = y.shape[-1] // 2
    left, right = y[..., :2].mean(-1), y[..., -2:].mean(-1)
    b1 = (right - left) / (x[-2] - x[1])
    ym, y0, yp = y[..., c - 1], y[..., c], y[..., c + 1]
    curv = ym - 2.0 * y0 + yp
    x0 = np.where(curv < 0, 0.5 * (ym - yp) / np.where(curv < 0, curv, -1.0), 0.0)
    x0 = np.clip(x0, -0.5, 0.5)
    b0 = 0.5 * (left + right)
    return np.stack([b0, b1, y0 - b0, x0, np.full_like(b0, h0)], axis=-1)


def fit_dips(y: np.ndarray, h0: float, iterations: int = 12) -> np.ndarray:
    """Levenberg-Marquardt fit of ``_model`` to each window y[..., W] (x = -W//2 … W//2).

    Vectorised over the leading axes (shots × lines): Crouch's per-shot Lorentzian fit.
    Returns p[..., 5] = (b0, b1, d, x0, |h|); non-finite where the data were.
    """
    y = np.asarray(y, np.float64)
    w = y.shape[-1]
    x = np.arange(w, dtype=np.float64) - w // 2
    p = _initial(y, x, h0)
    lam = np.full(y.shape[:-1], 1e-3)
    r = y - _model(p, x)
    cost = np.sum(r * r, axis=-1)
    eye = np.eye(5)
    for _ in range(iterations):
        jac = _jacobian(p, x)
        jt = np.swapaxes(jac, -1, -2)
        jtj = jt @ jac
        g = (jt @ r[..., None])[..., 0]
        a = np.where(np.isfinite(jtj), jtj, 0.0)
        # Marquardt damping plus a floor ε·I (ε > 0): positive definite, so solve never fails
        floor = 1e-12 * (1.0 + np.max(np.abs(a * eye), axis=(-2, -1)))
        a = a + lam[..., None, None] * (a * eye) + floor[..., None, None] * eye
        step = np.linalg.solve(a, g[..., None])[..., 0]
        trial = p + step
        r_new = y - _model(trial, x)
        cost_new = np.sum(r_new * r_new, axis=-1)
        better = cost_new < cost
        p = np.where(better[..., None], trial, p)
        r = np.where(better[..., None], r_new, r)
        cost = np.where(better, cost_new, cost)
        lam = np.where(better, lam / 3.0, lam * 4.0)
    p[..., 4] = np.abs(p[..., 4])
    return p


# --------------------------------------------------------------------------------------------
# Per-shot offsets
# --------------------------------------------------------------------------------------------


class _Plan:
    """Geometry of the estimate, shared by the stream stage and the reference.

    Coarse step: the absorbance of a shot, put on a uniform grid of ν_rel (the frequency curve
    known up to the offset c), is cross-correlated with the line model shifted by every lag up
    to ``max_offset_hz``: the whole comb (unequal spacings, strengths, band gap) fixes c to one
    grid step, with no ambiguity of one line spacing.  Fine step: each line's dip is fitted.
    """

    def __init__(
        self,
        config,
        oversampling,
        linewidth_hz,
        search_hz,
        fit_halfwidths,
        max_lines,
        max_offset_hz,
    ):
        wf = config.waveform
        if not isinstance(wf, FMCWChirp):
            raise ValueError("HCN alignment applies to FMCW waveforms")
        self.f0 = config.geometry.carrier_hz
        self.k = wf.chirp_rate_hz_per_s
        self.fs = oversampling * wf.sample_rate_hz
        self.t = channel_times_s(config, oversampling)
        self.grid = self.k * self.t  # uniform ν grid of the coarse step
        self.step_hz = step = self.k / self.fs
        self.search = max(2, math.ceil(search_hz / step))
        self.half = max(3, math.ceil(fit_halfwidths * linewidth_hz / step))
        self.h0 = 0.5 * linewidth_hz / step  # HWHM in samples
        self.lags = math.ceil(max_offset_hz / step)
        m = len(self.t)
        ext = self.grid[0] + (np.arange(m + 2 * self.lags) - self.lags) * step
        self.model = hcn_absorbance(self.f0 + ext, linewidth_hz)  # model[j + n] ↔ ν = g_n + lag
        # Circular correlation is exact for lags 0 … 2L once nfft ≥ len(model) = M + 2L.
        self.nfft = sp_fft.next_fast_len(len(self.model), real=True)
        self.model_spectrum = sp_fft.rfft(self.model, self.nfft)
        f, s = hcn_lines(self.f0 + self.grid[0], self.f0 + self.grid[-1])
        if max_lines is not None:
            keep = np.sort(np.argsort(-s, kind="stable")[:max_lines])
            f, s = f[keep], s[keep]
        self.lines_nu = f - self.f0  # line frequencies relative to the carrier
        if len(self.lines_nu) == 0:
            raise ValueError(
                "no HCN line inside the chirp: the sweep "
                f"{(self.f0 + self.grid[0]) / 1e12:.3f}-{(self.f0 + self.grid[-1]) / 1e12:.3f} "
                "THz misses the band (the synthetic HCN lines lie near 191-197 THz)"
            )

    def on_grid(self, a: np.ndarray, nu_rel: np.ndarray) -> np.ndarray:
        """Absorbance rows resampled onto the uniform grid of ν_rel, mean removed."""
        if nu_rel is None:
            u = a
        else:
            u = np.stack([np.interp(self.grid, nu, row) for nu, row in zip(nu_rel, a, strict=True)])
        return u - u.mean(axis=-1, keepdims=True)

    def coarse_offsets(self, a: np.ndarray, nu_rel) -> np.ndarray:
        """c to one grid step: argmax over lags L of Σ_n a(g_n) model(g_n + L) (FFT)."""
        u = self.on_grid(a, nu_rel)
        corr = sp_fft.irfft(self.model_spectrum * np.conj(sp_fft.rfft(u, self.nfft)), self.nfft)
        return (np.argmax(corr[:, : 2 * self.lags + 1], axis=-1) - self.lags) * self.step_hz


def _absorbance(hcn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """-ln(intensity) (floored at 1e-9) and the shots that hold only finite samples."""
    i = np.asarray(hcn)
    i = i.real if np.iscomplexobj(i) else i
    finite = np.isfinite(i).all(axis=-1)
    i = np.where(np.isfinite(i), i, 1.0)
    return -np.log(np.clip(i.astype(np.float64), 1e-9, None)), finite


def _combine(c: np.ndarray, valid: np.ndarray, max_spread_hz: float):
    """Median of the valid per-line offsets; ok when ≥ 1 line and their MAD ≤ max_spread_hz."""
    masked = np.where(valid, c, np.nan)
    n = valid.sum(axis=-1)
    with warnings.catch_warnings():  # all-NaN rows (no valid line) are expected: not ok below
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(masked, axis=-1)
        mad = np.nanmedian(np.abs(masked - med[..., None]), axis=-1)
    ok = (n >= 1) & np.isfinite(med) & (mad <= max_spread_hz)
    return np.where(ok, med, 0.0), ok


def _accept(p: np.ndarray, plan: _Plan, min_depth: float) -> np.ndarray:
    finite = np.isfinite(p).all(axis=-1)
    x0, d, h = p[..., 3], p[..., 2], p[..., 4]
    return finite & (np.abs(x0) <= 2.0) & (d >= min_depth) & (h > 0.2 * plan.h0) & (h < 5 * plan.h0)


class HCNAligner(CorrectionStage):
    """Stream stage: per-shot start-frequency offsets from the HCN channel, shots shifted on them.

    ``stage.process(samples[P, S], aux={HCN_CHANNEL: hcn[P, q·S], ...})`` → complex64[P, S]
    (raw shots; q, the channel's oversampling, is read from its length).  ``offsets_hz(hcn,
    nu_rel_hz)`` returns only the offsets c with ν(t) = ν_rel(t) + c (ν_rel: the frequency curve
    relative to the carrier at the channel's samples, default the nominal K t), the absolute
    anchor used by ChirpLinearizer.  Causal, bounded; a shot whose lines cannot be fitted (no
    line found, non-finite data, lines disagreeing by more than ``max_spread_hz``) reuses the last
    good offset (0 before any) and is counted in ``shots_not_aligned``; a main-channel shot
    holding NaN/Inf is zeroed and counted in ``shots_nonfinite``; ``samples_zeroed`` counts
    output samples shifted in from beyond the record.  ``last_offsets_hz``: the offsets of the
    last batch.

    Parameters: ``linewidth_hz`` expected FWHM of the lines (start value, window size);
    ``max_offset_hz`` largest offset the coarse comb registration looks for (default 100 GHz,
    10 σ of Crouch's jitter); ``search_hz`` half-width of the search for each dip's maximum
    around its coarse position; ``fit_halfwidths`` fit window half-width in FWHM; ``min_depth``
    smallest fitted absorbance; ``max_lines`` use only the strongest lines in the sweep;
    ``max_spread_hz`` (default: the linewidth) largest median absolute deviation of the per-line
    offsets; ``taps``/``kaiser_beta`` the resampler (rtsar.focus.linearize.resample).
    """

    domain = "raw"
    counter_names = ("shots_in", "shots_not_aligned", "shots_nonfinite", "samples_zeroed")

    def __init__(
        self,
        config,
        linewidth_hz: float = DEFAULT_LINEWIDTH_HZ,
        search_hz: float = 3e9,
        fit_halfwidths: float = 3.0,
        min_depth: float = 0.05,
        max_lines: int | None = None,
        max_spread_hz: float | None = None,
        max_offset_hz: float = 100e9,
        taps: int = DEFAULT_TAPS,
        kaiser_beta: float = DEFAULT_KAISER_BETA,
        channel: str = HCN_CHANNEL,
    ):
        for name, v in (
            ("linewidth_hz", linewidth_hz),
            ("search_hz", search_hz),
            ("fit_halfwidths", fit_halfwidths),
            ("max_offset_hz", max_offset_hz),
        ):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"HCNAligner.{name} must be finite and > 0, got {v!r}")
        if max_lines is not None and not (isinstance(max_lines, int) and max_lines >= 1):
            raise ValueError(
                f"HCNAligner.max_lines must be None or an integer >= 1, got {max_lines!r}"
            )
        self.config = config
        self.options = dict(
            linewidth_hz=float(linewidth_hz),
            search_hz=float(search_hz),
            fit_halfwidths=float(fit_halfwidths),
            min_depth=float(min_depth),
            max_lines=max_lines,
            max_spread_hz=float(linewidth_hz if max_spread_hz is None else max_spread_hz),
            max_offset_hz=float(max_offset_hz),
        )
        self.taps, self.kaiser_beta, self.channel = taps, float(kaiser_beta), channel
        self.channels = (channel,)
        wf = config.waveform
        if not isinstance(wf, FMCWChirp):
            raise ValueError("HCN alignment applies to FMCW waveforms")
        self._plans: dict[int, _Plan] = {}
        self._last_good = 0.0
        self.shots_in = 0
        self.shots_not_aligned = 0
        self.shots_nonfinite = 0
        self.samples_zeroed = 0
        self.last_offsets_hz = np.zeros(0)

    def _plan(self, q: int) -> _Plan:
        if q not in self._plans:
            o = self.options
            self._plans[q] = _Plan(
                self.config,
                q,
                o["linewidth_hz"],
                o["search_hz"],
                o["fit_halfwidths"],
                o["max_lines"],
                o["max_offset_hz"],
            )
        return self._plans[q]

    def offsets_hz(self, hcn: np.ndarray, nu_rel_hz: np.ndarray | None = None) -> np.ndarray:
        """Start-frequency offsets c[P] (Hz): true ν(t) = ν_rel(t) + c (module docstring)."""
        hcn = np.asarray(hcn)
        if hcn.ndim != 2:
            raise ValueError(f"HCN channel must be [pulses, samples], got {hcn.shape}")
        plan = self._plan(infer_oversampling(self.config, hcn, self.channel))
        a, finite = _absorbance(hcn)
        n_shots, m = a.shape
        if nu_rel_hz is not None:
            nu_rel_hz = np.asarray(nu_rel_hz, np.float64)
            if nu_rel_hz.shape != a.shape:
                raise ValueError(f"nu_rel_hz must be {a.shape}, got {nu_rel_hz.shape}")
        nu_rel = np.broadcast_to(plan.grid, a.shape) if nu_rel_hz is None else nu_rel_hz
        coarse = plan.coarse_offsets(a, nu_rel_hz)
        idx = np.arange(m, dtype=np.float64)
        pred = np.stack(
            [np.interp(plan.lines_nu - c, nu, idx) for c, nu in zip(coarse, nu_rel, strict=True)]
        )
        pred = np.rint(pred).astype(np.int64)  # [P, J]
        rows = np.arange(n_shots)[:, None, None]
        k_s = np.arange(-plan.search, plan.search + 1)
        inside = (pred - plan.search - plan.half >= 0) & (pred + plan.search + plan.half < m)
        win = a[rows, np.clip(pred[..., None] + k_s, 0, m - 1)]
        i0 = pred + k_s[np.argmax(win, axis=-1)]
        k_f = np.arange(-plan.half, plan.half + 1)
        p = fit_dips(a[rows, np.clip(i0[..., None] + k_f, 0, m - 1)], plan.h0)
        valid = _accept(p, plan, self.options["min_depth"]) & inside & finite[:, None]
        frac = i0 + np.where(valid, p[..., 3], 0.0)
        nu_dip = np.stack([np.interp(f, idx, nu) for f, nu in zip(frac, nu_rel, strict=True)])
        c, ok = _combine(plan.lines_nu[None, :] - nu_dip, valid, self.options["max_spread_hz"])
        for i in range(n_shots):  # causal fallback
            if ok[i]:
                self._last_good = float(c[i])
            else:
                c[i] = self._last_good
        self.shots_in += n_shots
        self.shots_not_aligned += int(np.count_nonzero(~ok))
        self.last_offsets_hz = c
        return c

    def process(self, samples: np.ndarray, aux: dict) -> np.ndarray:
        """Align a micro-batch of raw shots [P, S]: resample at τ_k = t_k - c/K (complex64)."""
        x = np.asarray(samples)
        wf = self.config.waveform
        s, fs, k = wf.samples_per_shot, wf.sample_rate_hz, wf.chirp_rate_hz_per_s
        if x.ndim != 2 or x.shape[1] != s:
            raise ValueError(f"samples must be [pulses, {s}], got {x.shape}")
        if self.channel not in aux:
            raise ValueError(f"auxiliary channel {self.channel!r} missing (got {sorted(aux)})")
        hcn = np.asarray(aux[self.channel])
        if hcn.shape[0] != len(x):
            raise ValueError(f"{self.channel!r} has {hcn.shape[0]} shots, samples have {len(x)}")
        x, bad = zero_nonfinite_rows(x)
        self.shots_nonfinite += int(bad.sum())
        c = self.offsets_hz(hcn)
        u = np.arange(s)[None, :] - (c / k * fs)[:, None]
        out, outside = resample(x, u, self.taps, self.kaiser_beta)
        self.samples_zeroed += int(np.count_nonzero(outside))  # shots_in: in offsets_hz
        return out.astype(np.complex64)


# --------------------------------------------------------------------------------------------
# Float64 batch references (plain loops, SciPy's least squares)
# --------------------------------------------------------------------------------------------


def offsets_reference(
    config,
    hcn: np.ndarray,
    nu_rel_hz: np.ndarray | None = None,
    linewidth_hz: float = DEFAULT_LINEWIDTH_HZ,
    search_hz: float = 3e9,
    fit_halfwidths: float = 3.0,
    min_depth: float = 0.05,
    max_lines: int | None = None,
    max_spread_hz: float | None = None,
    max_offset_hz: float = 100e9,
) -> np.ndarray:
    """Reference of HCNAligner.offsets_hz: shot by shot, line by line; the correlation of the
    coarse step summed directly (no FFT), SciPy's Levenberg-Marquardt for each dip."""
    from scipy.optimize import least_squares

    hcn = np.asarray(hcn)
    q = infer_oversampling(config, hcn, HCN_CHANNEL)
    plan = _Plan(config, q, linewidth_hz, search_hz, fit_halfwidths, max_lines, max_offset_hz)
    spread = linewidth_hz if max_spread_hz is None else max_spread_hz
    m = hcn.shape[1]
    x = np.arange(-plan.half, plan.half + 1, dtype=np.float64)
    idx = np.arange(m, dtype=np.float64)
    out = np.zeros(len(hcn))
    last = 0.0
    for i in range(len(hcn)):
        row = np.real(hcn[i])
        nu_rel = plan.grid if nu_rel_hz is None else np.asarray(nu_rel_hz)[i]
        offsets = []
        if np.isfinite(row).all():
            a = -np.log(np.clip(row.astype(np.float64), 1e-9, None))
            u = np.interp(plan.grid, nu_rel, a)
            lagged = np.lib.stride_tricks.sliding_window_view(plan.model, m)  # [2L+1, M]
            corr = lagged @ (u - u.mean())  # corr[j] = Σ_n model[n + j] a(g_n)
            coarse = (int(np.argmax(corr)) - plan.lags) * plan.step_hz
            for nu_j in plan.lines_nu:
                c0 = int(np.rint(np.interp(nu_j - coarse, nu_rel, idx)))
                if c0 - plan.search - plan.half < 0 or c0 + plan.search + plan.half >= m:
                    continue
                seg = a[c0 - plan.search : c0 + plan.search + 1]
                i0 = c0 - plan.search + int(np.argmax(seg))
                y = a[i0 - plan.half : i0 + plan.half + 1]
                p0 = _initial(y, x, plan.h0)
                fit = least_squares(
                    lambda p, y=y: _model(p, x) - y, p0, method="lm", xtol=1e-14, ftol=1e-14
                )
                p = fit.x.copy()
                p[4] = abs(p[4])
                if not _accept(p, plan, min_depth):
                    continue
                offsets.append(nu_j - np.interp(i0 + p[3], idx, nu_rel))
        if offsets:
            med = float(np.median(offsets))
            if np.median(np.abs(np.array(offsets) - med)) <= spread:
                last = med
        out[i] = last
    return out


def align_reference(
    config, shots, hcn, taps=DEFAULT_TAPS, kaiser_beta=DEFAULT_KAISER_BETA, **options
) -> tuple[np.ndarray, np.ndarray]:
    """Float64 reference of HCNAligner.process → (aligned shots complex128, offsets_hz)."""
    wf = config.waveform
    c = offsets_reference(config, hcn, **options)
    s = wf.samples_per_shot
    u = np.arange(s)[None, :] - (c / wf.chirp_rate_hz_per_s * wf.sample_rate_hz)[:, None]
    x = zero_nonfinite_rows(np.asarray(shots, np.complex128))[0]
    return resample_reference(x, u, taps, kaiser_beta), c
