"""Point-target acceptance: focus targets at the swath centre and edges, compare with theory.

Shared by the test suite and ``tools/focus_report.py``.  Theory, per axis:

* range: resolution ρR = c/2B (Psaltis eq. 6, Crouch eq. 3.6);
* azimuth: ρA = λR/(2L), L = N·d the synthetic aperture (Crouch eq. 4.8; = L_illum/N, Psaltis
  eq. 7, for the Psaltis presets);
* the -3 dB impulse response width of an unweighted aperture is 0.886·ρ (the half-power width of
  a sinc); a taper broadens it by the factor ``theoretical_irw_factor`` of its weights;
* azimuth, measured on the correlator's own response (rtsar.analysis.azimuth_response): the
  mask's window stays on the aperture while the two-way antenna pattern, when simulated, moves
  with the line, so the beam is not a fixed taper (without it, the same figures as the window).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..ccd.base import beam_look_back_m
from ..lens.plan import range_axis_m
from ..params import Config
from ..scene import Simulator, point_scene
from ..scene.effects import load_effects
from ..stream.engine import focus_batches
from ..windows import window
from .azimuth_response import SINC_IRW, antenna_gain, azimuth_theory
from .point_target import analyse_point_target, image_centres
from .theory import theoretical_irw_factor, theoretical_pslr_db


@dataclass(frozen=True)
class TargetResult:
    label: str
    true_azimuth_m: float
    true_range_m: float
    azimuth_error_cells: float  # |measured - true| / ρA
    range_error_cells: float  # |measured - true| / ρR
    azimuth_irw_m: float
    azimuth_irw_theory_m: float
    range_irw_m: float
    range_irw_theory_m: float
    azimuth_pslr_db: float
    range_pslr_db: float
    azimuth_pslr_theory_db: float
    range_pslr_theory_db: float
    azimuth_islr_db: float
    range_islr_db: float

    @property
    def azimuth_irw_ratio(self) -> float:
        return self.azimuth_irw_m / self.azimuth_irw_theory_m

    @property
    def range_irw_ratio(self) -> float:
        return self.range_irw_m / self.range_irw_theory_m


def acceptance_targets(cfg: Config) -> list[tuple[str, float, float]]:
    """(label, along_track_m, slant_range_m): centre and near both swath edges, off-grid."""
    rm = range_axis_m(cfg)
    dr = rm[1] - rm[0]
    n = len(rm)
    edge = max(10, n // 16)  # bins between an edge target and the swath edge (room for sidelobes)
    wf = cfg.waveform
    if getattr(wf, "window_start_s", None) is not None:
        # an instrument's fixed window: the outer P/2 bins hold echoes cut by the window (a
        # wider response by design); the edge targets stand where echoes are whole, plus the
        # squinted walk's half-aperture and room for sidelobes
        edge = max(edge, wf.pulse_samples // 2 + 16 + n // 64)
    step = cfg.geometry.along_track_step_m
    return [
        ("near edge", 0.31 * step, rm[edge] + 0.27 * dr),
        ("centre", 0.0, rm[n // 2] + 0.41 * dr),
        ("far edge", -0.17 * step, rm[n - 1 - edge] - 0.36 * dr),
    ]


def range_weights(cfg: Config) -> np.ndarray:
    """The range window over the pulse (pulsed) or the shot (FMCW): the range IRW's taper."""
    wf = cfg.waveform
    n = wf.pulse_samples if wf.kind == "pulsed" else wf.samples_per_shot
    return window(cfg.processor.range_window, n)


def azimuth_weights(cfg: Config) -> np.ndarray:
    """The azimuth window over the aperture: the azimuth IRW's taper without an antenna pattern
    (with one, the correlator's response: rtsar.analysis.azimuth_response)."""
    return window(cfg.processor.azimuth_window, cfg.processor.aperture_pulses)


def _focus_one(
    cfg: Config, x: float, r: float, effects: list, lens_backend: str, margin_lines: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One isolated target, with margin_lines image lines either side of it."""
    n, step = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    # line j focuses at start + (j + (N-1)/2) d - u_mid (rtsar.ccd.base.line_azimuth_m)
    start = x + beam_look_back_m(cfg) - (0.5 * (n - 1) + margin_lines) * step
    scene = point_scene(
        cfg,
        [x],
        [r],
        effects=effects,
        seed=11,
        start_along_track_m=start,
        pulses=n + 2 * margin_lines,
    )
    sim = Simulator(scene)
    b = cfg.processor.micro_batch
    batches = (sim.block(b) for _ in range(0, scene.pulses, b))
    return focus_batches(cfg, batches, lens_backend, scene.start_along_track_m)


def run_point_targets(
    cfg: Config,
    lens_backend: str = "auto",
    antenna: bool | dict = False,
    noise_snr_db: float | None = None,
) -> list[TargetResult]:
    """Focus each acceptance target alone with the streaming engine and measure it.

    ``antenna``: simulate the two-way antenna pattern (a dict: the antenna_pattern effect's
    parameters, e.g. ``{"antenna_length_m": 58.75, "main_lobe_only": True}``).
    """
    effects = []
    if antenna:
        effects.append(("antenna_pattern", dict(antenna) if isinstance(antenna, dict) else {}))
    if noise_snr_db is not None:
        effects.append(("noise", {"snr_db": noise_snr_db}))
    rho_r = cfg.waveform.range_resolution_m
    rw = range_weights(cfg)
    step = cfg.geometry.along_track_step_m
    gain = antenna_gain(load_effects(effects[:1], cfg)[0]) if antenna else None
    results = []
    for label, x, r in acceptance_targets(cfg):
        rho_a = cfg.azimuth_resolution_m(r)
        az_theory = azimuth_theory(cfg, r, gain)
        az_irw = az_theory.irw_m
        rg_irw = SINC_IRW * rho_r * theoretical_irw_factor(rw)
        # Room for ±12 IRW of sidelobes on each axis (the ISLR extent is ±10 IRW), at least 64
        # pixels.  Per axis: psaltis-max's azimuth chip is 5,400 lines, and one as wide in range
        # made each evaluation of the 2-D interpolant 9x the work for nothing it measures.
        chip = max(64, int(np.ceil(12 * az_irw / step)))
        image, az, rg = _focus_one(cfg, x, r, effects, lens_backend, chip + 8)
        chip_rg = max(64, int(np.ceil(12 * rg_irw / abs(rg[1] - rg[0]))))
        rep = analyse_point_target(
            image,
            az,
            rg,
            near_azimuth_m=x,
            near_range_m=r,
            search_radius_m=(3 * rho_a, 3 * rho_r),
            chip=(chip, chip_rg),
            **image_centres(cfg),
        )
        results.append(
            TargetResult(
                label,
                x,
                r,
                abs(rep.azimuth_m - x) / rho_a,
                abs(rep.range_m - r) / rho_r,
                rep.azimuth.irw_m,
                az_irw,
                rep.range.irw_m,
                rg_irw,
                rep.azimuth.pslr_db,
                rep.range.pslr_db,
                az_theory.pslr_db,
                theoretical_pslr_db(rw),
                rep.azimuth.islr_db,
                rep.range.islr_db,
            )
        )
    return results


def markdown_table(rows: list[tuple[str, str, TargetResult]]) -> str:
    """rows: (preset, windows, result) → a Markdown table of measured vs theory."""
    head = (
        "| preset | windows | target | az. error [cells] | rg. error [cells] | "
        "az. IRW meas / theory | ratio | rg. IRW meas / theory | ratio | "
        "az. PSLR meas / theory [dB] | rg. PSLR meas / theory [dB] | az. / rg. ISLR [dB] |"
    )
    lines = [head, "|" + "---|" * 12]

    def fmt_len(v):
        for unit, s in (("km", 1e3), ("m", 1.0), ("mm", 1e-3), ("µm", 1e-6)):
            if abs(v) >= s or unit == "µm":
                return f"{v / s:.4g} {unit}"
        return f"{v:g}"  # pragma: no cover

    for preset_name, windows, t in rows:
        lines.append(
            f"| {preset_name} | {windows} | {t.label} | {t.azimuth_error_cells:.3f} | "
            f"{t.range_error_cells:.3f} | {fmt_len(t.azimuth_irw_m)} / "
            f"{fmt_len(t.azimuth_irw_theory_m)} | {t.azimuth_irw_ratio:.3f} | "
            f"{fmt_len(t.range_irw_m)} / {fmt_len(t.range_irw_theory_m)} | "
            f"{t.range_irw_ratio:.3f} | {t.azimuth_pslr_db:.1f} / {t.azimuth_pslr_theory_db:.1f} | "
            f"{t.range_pslr_db:.1f} / {t.range_pslr_theory_db:.1f} | "
            f"{t.azimuth_islr_db:.1f} / {t.range_islr_db:.1f} |"
        )
    return "\n".join(lines)
