"""The INO phase-error patent's geometry: a collimated beam on a uniform reference region.

Turbide (INO patent, Figs. 3-4, eqs. 2-4).  On the platform, across track: the target
transmitter G, the first receiver H at distance d from it (H is the main channel's receiver),
and a collimated reference transceiver R (reference transmitter + second receiver) at distance D
from H on the other side.  Uncompensated optical-path fluctuations change the one-way paths as
(eqs. 3a-3c)

    R(x) = R + α(x) - Dβ(x),   G(x) = G + … + α(x) + dβ(x),   H(x) = H + … + α(x),

α the common error (every path: platform altitude/lateral motion, air) and β the non-common one
(a roll angle: the path changes by lever arm × β).  Hence the round trips carry

    main   S1t  G → H   2α + dβ      (eq. 10: phase φ1t = -2π/λ (2α + dβ))
    aux    S1r  R → H   2α - Dβ      (eq. 4a)
    aux    S2r  R → R   2α - 2Dβ     (eq. 4b).

This effect owns that motion (α, β: PulseProcess sequences, seeded) and synthesises the two
reference channels ``reference_rx1`` (S1r) and ``reference_rx2`` (S2r) from a uniform,
speckled reference region: scatterers of random complex amplitude spread uniformly over an
along-track strip and a slant-range interval ``region_depth_m`` around ``region_range_m``
(the footprint of an oblique collimated beam spans range; the patent's Fig. 7A band).  The
collimated beam (1/e² intensity diameter F = ``beam_diameter_m``, field exp(-u²/(F/2)²) at
along-track offset u) sees a flat wavefront: the transceiver's path to a scatterer does not
change with x (no quadratic term in eq. 3a), only the weights move with the beam.  Receiver 1 is
a point receiver at D across track: its path sqrt(R_l² + D² + u²) keeps the quadratic term of
eq. 4a, which the patent neglects when πF²/(4λH) < 2π (checked).  The reference scatterers are
generated in along-track tiles seeded by (seed, tile), so the region is unbounded and the
memory is bounded.  The aux receivers mix with an LO delayed to ``lo_range_m`` (default: the
region centre), so the region sits in the middle of their range window.

The errors are applied as phases (the patent's eq. 4 assumption: fluctuations small against the
range cell).  The target path's 2α + dβ is common to the receivers of the target returns
(``common_to_receivers``): the main channel and any auxiliary target receiver (SAM masks behind
the same aperture H; a second InSAL receiver, whose own roll lever arm — its cross-track
baseline × β — is not modelled).  The reference channels model their own paths (eqs. 4a-4b) and
are synthesised without the common effects (``ctx.bare_echo``): a ``piston`` effect in the same
scene stays a target-path error (e.g. fibre length), unseen by the reference.
Truth: ``alpha_m``, ``beta_rad``, ``target_phase_rad`` (φ1t, also ``truth``).  Only FMCW
waveforms.  A gradient estimate of α and β needs each reference channel's round-trip path error
to change by less than λ/2 per pulse; choose the processes accordingly.
"""

from __future__ import annotations

import math

import numpy as np

from ...instrument import REFERENCE_CHANNELS
from ...params import FMCWChirp
from .base import Effect
from .platform import PulseProcess, _non_negative, check_seed

CHANNELS = REFERENCE_CHANNELS
_BEAM_REACH = 1.5  # scatterers within ±1.5 F of the beam centre (field below e^-9 beyond)
# A tile's scatterers (two tiles are in the beam at once): rtsar.scene.model.MAX_TARGETS's
# figure, checked when the effect is made, before any tile is.
MAX_TILE_SCATTERERS = 100_000


class ReferenceRegion(Effect):
    """Reference channels S1r, S2r of a speckled uniform region; α (common) and β (roll) errors.

    Parameters (SI): ``d_m``, ``D_m`` the patent's spacings; ``region_range_m`` (default: the
    geometry's slant range), ``region_depth_m`` (default 32 c/2B), ``beam_diameter_m`` (default
    a quarter of the patent's limit sqrt(8λR)), ``scatterers_per_cell`` (per range cell and beam
    diameter, default 4), ``amplitude`` (scatterer rms amplitude × sqrt(scatterers_per_cell):
    the mean S2r power per range bin is amplitude²·sqrt(π)/4 with the two-way Gaussian beam),
    ``lo_range_m``, ``noise_snr_db`` (aux receivers' per-sample SNR as in ``noise``; None: none);
    α process (metres of one-way path): ``alpha_walk_m``, ``alpha_drift_m``, ``alpha_vibration_m``,
    ``alpha_vibration_hz``; β process (radians of roll): ``roll_walk_rad``, ``roll_drift_rad``,
    ``roll_vibration_rad``, ``roll_vibration_hz``; ``seed`` (errors and scatterers).
    """

    name = "reference_region"
    common_to_receivers = True  # apply_to_shot: the target path's phase, on every target receiver

    def __init__(
        self,
        config,
        d_m: float = 0.01,
        D_m: float = 0.05,  # the patent's symbol D
        region_range_m: float | None = None,
        region_depth_m: float | None = None,
        beam_diameter_m: float | None = None,
        scatterers_per_cell: float = 4.0,
        amplitude: float = 1.0,
        lo_range_m: float | None = None,
        noise_snr_db: float | None = None,
        alpha_walk_m: float = 0.0,
        alpha_drift_m: float = 0.0,
        alpha_vibration_m: float = 0.0,
        alpha_vibration_hz: float = 0.0,
        roll_walk_rad: float = 0.0,
        roll_drift_rad: float = 0.0,
        roll_vibration_rad: float = 0.0,
        roll_vibration_hz: float = 0.0,
        seed: int = 0,
    ):
        wf, g = config.waveform, config.geometry
        if not isinstance(wf, FMCWChirp):
            raise ValueError("reference_region needs an FMCW (dechirp-on-receive) waveform")
        self.wavelength_m = lam = g.wavelength_m
        self.d_m = _non_negative("reference_region.d_m", d_m)
        self.D_m = _non_negative("reference_region.D_m", D_m)
        if self.D_m == 0:
            raise ValueError("reference_region.D_m must be > 0 (β is solved through D)")
        self.region_range_m = _positive(
            "region_range_m", g.slant_range_m if region_range_m is None else region_range_m
        )
        rho = wf.range_resolution_m
        self.region_depth_m = _positive(
            "region_depth_m", 32 * rho if region_depth_m is None else region_depth_m
        )
        limit_m = math.sqrt(8.0 * lam * self.region_range_m)  # πF²/(4λH) < 2π (patent, eq. 5)
        self.beam_diameter_m = _positive(
            "beam_diameter_m", 0.25 * limit_m if beam_diameter_m is None else beam_diameter_m
        )
        if self.beam_diameter_m >= limit_m:
            raise ValueError(
                f"reference_region.beam_diameter_m {self.beam_diameter_m:g} m breaks the "
                f"patent's narrow-beam condition πF²/(4λH) < 2π (F < {limit_m:.3g} m)"
            )
        self.scatterers_per_cell = _positive("scatterers_per_cell", scatterers_per_cell)
        self.amplitude = _positive("amplitude", amplitude)
        self.lo_range_m = _positive(
            "lo_range_m", self.region_range_m if lo_range_m is None else lo_range_m
        )
        half_window = 0.5 * wf.unambiguous_range_m
        far = abs(self.region_range_m - self.lo_range_m) + 0.5 * self.region_depth_m
        if far + 4 * rho > half_window:
            raise ValueError(
                f"reference region (±{0.5 * self.region_depth_m:g} m about "
                f"{self.region_range_m:g} m) leaves the aux channels' range window "
                f"±{half_window:g} m about lo_range_m {self.lo_range_m:g} m"
            )
        if noise_snr_db is not None and not math.isfinite(noise_snr_db):
            raise ValueError("reference_region.noise_snr_db must be finite or None")
        self.noise_sigma = (
            None if noise_snr_db is None else math.sqrt(0.5 * 10.0 ** (-noise_snr_db / 10.0))
        )
        self.seed = check_seed("reference_region.seed", seed)
        prf = g.prf_hz
        self.alpha = PulseProcess(
            prf,
            0.0,
            alpha_walk_m,
            alpha_drift_m,
            alpha_vibration_m,
            alpha_vibration_hz,
            self.seed,
            stream=2,
            name="reference_region alpha",
        )
        self.beta = PulseProcess(
            prf,
            0.0,
            roll_walk_rad,
            roll_drift_rad,
            roll_vibration_rad,
            roll_vibration_hz,
            self.seed,
            stream=3,
            name="reference_region roll",
        )
        # Scatterers: Poisson-free fixed count per tile, density from scatterers_per_cell.
        self.tile_m = 4.0 * self.beam_diameter_m
        per_m2 = self.scatterers_per_cell / (rho * self.beam_diameter_m)
        per_tile = per_m2 * self.tile_m * self.region_depth_m
        if not per_tile <= MAX_TILE_SCATTERERS:  # (inf too)
            raise ValueError(
                f"reference_region: {per_tile:.4g} scatterers a tile ({4 * self.beam_diameter_m:g}"
                f" m along track) exceed {MAX_TILE_SCATTERERS:,}: a lower scatterers_per_cell or "
                "region_depth_m"
            )
        self.per_tile = max(1, int(round(per_tile)))
        self.scatterer_rms = self.amplitude / math.sqrt(self.scatterers_per_cell)
        self._tiles: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    # -- truth ---------------------------------------------------------------------------------
    def alpha_m(self, pulses) -> np.ndarray:
        """α(p): common one-way path error (m), eq. 3."""
        return self.alpha.values(pulses)

    def beta_rad(self, pulses) -> np.ndarray:
        """β(p): non-common error, a roll angle (rad): lever arm × β is a path (eq. 3)."""
        return self.beta.values(pulses)

    def path_errors_m(self, pulses) -> dict[str, np.ndarray]:
        """Round-trip path errors of the three signals (eqs. 3, 4, 10), metres."""
        a, b = self.alpha_m(pulses), self.beta_rad(pulses)
        return {
            "target": 2 * a + self.d_m * b,
            CHANNELS[0]: 2 * a - self.D_m * b,
            CHANNELS[1]: 2 * a - 2 * self.D_m * b,
        }

    def target_phase_rad(self, pulses) -> np.ndarray:
        """φ1t(p) = -2π/λ (2α + dβ), the phase added to the main channel (patent eq. 10)."""
        return -2.0 * math.pi * self.path_errors_m(pulses)["target"] / self.wavelength_m

    def truth(self, pulses) -> np.ndarray:
        """The phase added to each main-channel shot (rad): φ1t, as ``target_phase_rad``."""
        return self.target_phase_rad(pulses)

    def _phasor(self, path_m: float) -> complex:
        cycles = math.fmod(path_m / self.wavelength_m, 1.0)  # float64, reduced before exp
        return complex(np.exp(-2j * math.pi * cycles))

    # -- the reference region --------------------------------------------------------------------
    def _tile(self, k: int):
        if k not in self._tiles:
            ident = 2 * k if k >= 0 else -2 * k - 1
            rng = np.random.default_rng(np.random.SeedSequence([self.seed, 7, ident]))
            n = self.per_tile
            x = (k + rng.random(n)) * self.tile_m
            r = self.region_range_m + (rng.random(n) - 0.5) * self.region_depth_m
            a = (
                self.scatterer_rms
                * np.sqrt(0.5)
                * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
            )
            self._tiles[k] = (x, r, a)
        return self._tiles[k]

    def scatterers_near(self, along_track_m: float):
        """Reference scatterers within the beam's reach of a platform position: (x, R, a)."""
        reach = _BEAM_REACH * self.beam_diameter_m
        lo = math.floor((along_track_m - reach) / self.tile_m)
        hi = math.floor((along_track_m + reach) / self.tile_m)
        for k in [k for k in self._tiles if k < lo - 1 or k > hi + 1]:
            del self._tiles[k]  # bounded memory: only the tiles around the beam are kept
        parts = [self._tile(k) for k in range(lo, hi + 1)]
        x, r, a = (np.concatenate(p) for p in zip(*parts, strict=True))
        keep = np.abs(x - along_track_m) <= reach
        return x[keep], r[keep], a[keep]

    # -- effect hooks ----------------------------------------------------------------------------
    def apply_to_shot(self, pulse, samples, rng):
        samples *= self._phasor(float(self.path_errors_m(pulse)["target"]))

    def aux_channels(self, ctx):
        x, r, a = self.scatterers_near(ctx.platform_along_track_m)
        u = x - ctx.platform_along_track_m
        w = np.exp(-((2.0 * u / self.beam_diameter_m) ** 2))  # collimated beam field
        # S2r: collimated out and back, flat wavefront: path 2R_l whatever x (eq. 2d).
        # S1r: collimated out, point receiver H at D across track back (eq. 2b).
        h = np.sqrt(r * r + self.D_m**2 + u * u)
        errors = self.path_errors_m(ctx.pulse)
        out = {}
        for name, half_path, gain in (
            (CHANNELS[0], 0.5 * (r + h), a * w),
            (CHANNELS[1], r, a * w * w),
        ):
            s = ctx.bare_echo(half_path, gain, self.lo_range_m) * self._phasor(float(errors[name]))
            if self.noise_sigma is not None:
                z = ctx.rng.standard_normal((2, s.shape[-1]))
                s = s + self.noise_sigma * (z[0] + 1j * z[1])
            out[name] = s
        return out


def _positive(name: str, value) -> float:
    value = _non_negative(f"reference_region.{name}", value)
    if value == 0:
        raise ValueError(f"reference_region.{name} must be > 0")
    return value
