"""Chirp defects and their corrections: the figures issue 5 asks for, as a Markdown table.

    python tools/chirp_report.py [--preset crouch-sal|zhao-insal] [--aperture N] [--json FILE]

For one point target near the far edge of the range swath (where the phase errors, ∝ Δτ, are
largest), each case is simulated, corrected in the stream (micro-batches of the processor's
``micro_batch``) and focused by the engine (NumPy lens).  Columns:

* residual phase: 2π Δτ_edge · rms over pulses and samples of ν_true(τ_k) - K t_k, the injected
  instantaneous frequency at the instants the (corrected) shot samples minus the linear chirp,
  as phase at the swath edge; one constant over the whole run is removed (it only rotates the
  image).  Uncorrected: τ_k = t_k.
* IRW / PSLR of the focused target, azimuth and range, and the IRW ratio to the error-free run.
* cost of each correction in pulses/s (best of 3 over 256 shots, this machine).

Errors of Crouch's size: start-frequency jitter 10 GHz rms (~1 ms at 10 THz/s, Crouch ch. 3
"HCN Cell"); 1 % non-linearity (peak instantaneous-frequency deviation from the best straight
line = 1 % of B, rtsar.scene.effects.chirp; Crouch: early SAL "not better than 1 %").
crouch-sal runs with 50 µm steps and a 128-pulse aperture (5x fewer pulses per azimuth cell
than the preset; the range axis is the preset's).  Takes about a minute.

Limit shown by zhao-insal: its range window spans the whole beat band (256 of 256 bins), so
the far-edge target beats at 0.44 fs; a 1 % sine of 5 periods raises the local chirp rate by
31 % and aliases the raw samples, which no resampling undoes (counter shots_beat_aliased).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace

import numpy as np

from ...analysis import analyse_point_target
from ...focus.hcn_align import HCNAligner
from ...focus.linearize import ChirpLinearizer
from ...lens.plan import make_plan
from ...params import C_M_PER_S
from ...presets import preset
from ...scene import Simulator, point_scene
from ...stream.engine import focus_batches

JITTER = ("start_frequency_jitter", {"std_hz": 10e9, "seed": 3})
SINE = ("chirp_nonlinearity", {"sine_fraction": 0.01, "sine_periods": 5.0})
QUAD = ("chirp_nonlinearity", {"poly_fraction": [0.0, 0.0, 0.015]})
RI = ("reference_interferometer", {})
HCN = ("hcn_cell", {})
HCN_NOISY = ("hcn_cell", {"snr_db": 30.0})


def config_for(name: str, aperture: int | None):
    cfg = preset(name)
    if name == "crouch-sal":
        cfg = cfg.with_processor(aperture_pulses=aperture or 128)
        cfg = replace(cfg, geometry=replace(cfg.geometry, along_track_step_m=50e-6))
    elif aperture:
        cfg = cfg.with_processor(aperture_pulses=aperture)
    return cfg


def cases():
    """(label, effects, correction) with correction in {None, 'hcn', 'lin', 'lin+hcn'}."""
    return [
        ("error-free", [], None),
        ("jitter 10 GHz", [JITTER, HCN], None),
        ("jitter 10 GHz", [JITTER, HCN], "hcn"),
        ("jitter 10 GHz, HCN at 30 dB SNR", [JITTER, HCN_NOISY], "hcn"),
        ("1 % sine (5 periods)", [SINE, RI], None),
        ("1 % sine (5 periods)", [SINE, RI], "lin"),
        ("1 % quadratic", [QUAD, RI], None),
        ("1 % quadratic", [QUAD, RI], "lin"),
        ("jitter + 1 % quadratic", [JITTER, QUAD, RI, HCN], None),
        ("jitter + 1 % quadratic", [JITTER, QUAD, RI, HCN], "lin"),
        ("jitter + 1 % quadratic", [JITTER, QUAD, RI, HCN], "lin+hcn"),
    ]


def make_stage(cfg, correction):
    if correction == "hcn":
        return HCNAligner(cfg)
    if correction == "lin":
        return ChirpLinearizer(cfg)
    if correction == "lin+hcn":
        return ChirpLinearizer(cfg, aligner=HCNAligner(cfg))
    return None


def sample_instants(cfg, stage, n_shots):
    """τ_k of each shot after the stage (s from mid-chirp; NaN where zeroed)."""
    wf = cfg.waveform
    t = (np.arange(wf.samples_per_shot) - 0.5 * wf.samples_per_shot) / wf.sample_rate_hz
    if stage is None:
        return np.tile(t, (n_shots, 1))
    if isinstance(stage, HCNAligner):
        return t[None, :] - (stage.last_offsets_hz / wf.chirp_rate_hz_per_s)[:, None]
    return stage.last_times_s


def true_nu_hz(sim, pulse, t):
    nu = sim.config.waveform.chirp_rate_hz_per_s * t
    for e in sim.effects:
        if e.name == "chirp_nonlinearity":
            nu = nu + e.frequency_deviation_hz(pulse, t)
        elif e.name == "start_frequency_jitter":
            nu = nu + e.offset_hz(pulse)
    return nu


def run_case(cfg, effects, correction):
    plan = make_plan(cfg)
    dr = plan.range_m[1] - plan.range_m[0]
    r = plan.range_m[-1 - max(10, len(plan.range_m) // 16)] - 0.36 * dr
    dtau_edge = 2 * (plan.range_m[-1] - cfg.waveform.reference_range_m) / C_M_PER_S
    n, step = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    az_irw = 0.886 * cfg.azimuth_resolution_m(r)
    chip = max(32, math.ceil(12 * az_irw / step))
    margin = chip + 8
    x = 0.31 * step
    start = x - (0.5 * (n - 1) + margin) * step
    scene = point_scene(
        cfg, [x], [r], effects=effects, seed=5, start_along_track_m=start, pulses=n + 2 * margin
    )
    sim = Simulator(scene)
    stage = make_stage(cfg, correction)
    residual = []
    b = cfg.processor.micro_batch
    first = [0]

    def batches():
        while first[0] < scene.pulses:
            main, aux = sim.block_with_aux(min(b, scene.pulses - first[0]))
            out = main if stage is None else stage.process(main, aux)
            tau = sample_instants(cfg, stage, len(main))
            t = (np.arange(main.shape[1]) - 0.5 * main.shape[1]) / cfg.waveform.sample_rate_hz
            for i in range(len(main)):
                ok = np.isfinite(tau[i])
                nu = true_nu_hz(sim, first[0] + i, tau[i][ok])
                residual.append(nu - cfg.waveform.chirp_rate_hz_per_s * t[ok])
            first[0] += len(main)
            yield out

    image, az, rg = focus_batches(cfg, batches(), "numpy", start)
    rep = analyse_point_target(
        image,
        az,
        rg,
        x,
        r,
        (3 * cfg.azimuth_resolution_m(r), 3 * cfg.waveform.range_resolution_m),
        chip=chip,
    )
    e = np.concatenate(residual)
    phase_rms = 2 * math.pi * dtau_edge * float(np.sqrt(np.mean((e - e.mean()) ** 2)))
    counters = {}
    if isinstance(stage, HCNAligner):
        counters["shots_not_aligned"] = stage.shots_not_aligned
    elif stage is not None:
        counters["shots_not_linearized"] = stage.shots_not_linearized
        if stage.aligner is not None:
            counters["shots_not_aligned"] = stage.aligner.shots_not_aligned
        counters["samples_zeroed"] = stage.samples_zeroed
        counters["shots_beat_aliased"] = stage.shots_beat_aliased
    return {
        "phase_rms_rad": phase_rms,
        "az_irw_m": rep.azimuth.irw_m,
        "az_pslr_db": rep.azimuth.pslr_db,
        "rg_irw_m": rep.range.irw_m,
        "rg_pslr_db": rep.range.pslr_db,
        "target_range_m": r,
        "counters": counters,
    }


def cost_pulses_per_s(cfg, correction, shots=256):
    """Throughput of one correction's ``process`` on simulated shots (best of 3)."""
    effects = {"hcn": [JITTER, HCN], "lin": [QUAD, RI], "lin+hcn": [JITTER, QUAD, RI, HCN]}
    scene = point_scene(
        cfg,
        [0.0],
        [cfg.geometry.slant_range_m],
        effects=effects[correction],
        pulses=shots,
        start_along_track_m=0.0,
    )
    main, aux = Simulator(scene).block_with_aux(shots)
    b = cfg.processor.micro_batch
    best = math.inf
    for _ in range(3):
        stage = make_stage(cfg, correction)
        stage.process(main[:2], {k: v[:2] for k, v in aux.items()})  # warm-up (numba, plans)
        t0 = time.perf_counter()
        for i in range(0, shots, b):
            stage.process(main[i : i + b], {k: v[i : i + b] for k, v in aux.items()})
        best = min(best, time.perf_counter() - t0)
    return shots / best


def fmt_db(v):
    return "–" if not math.isfinite(v) else f"{v:.1f}"


def markdown(name, cfg, rows, costs) -> str:
    base = rows[0][3]
    lines = [
        f"### {name}: B = {cfg.waveform.bandwidth_hz / 1e12:.3g} THz, "
        f"T = {cfg.waveform.chirp_duration_s * 1e3:.0f} ms, aperture "
        f"{cfg.processor.aperture_pulses} pulses × {cfg.geometry.along_track_step_m * 1e6:.0f} µm, "
        f"target at {base['target_range_m']:.4f} m (far swath edge)",
        "",
        "| case | correction | residual phase rms [rad] | az. IRW [µm] (ratio) | "
        "az. PSLR [dB] | rg. IRW [µm] (ratio) | rg. PSLR [dB] | counters |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, _, corr, m in rows:
        lines.append(
            f"| {label} | {corr or 'none'} | {m['phase_rms_rad']:.3g} | "
            f"{m['az_irw_m'] * 1e6:.1f} ({m['az_irw_m'] / base['az_irw_m']:.3f}) | "
            f"{fmt_db(m['az_pslr_db'])} | "
            f"{m['rg_irw_m'] * 1e6:.2f} ({m['rg_irw_m'] / base['rg_irw_m']:.3f}) | "
            f"{fmt_db(m['rg_pslr_db'])} | "
            + (", ".join(f"{k} {v}" for k, v in m["counters"].items()) or "–")
            + " |"
        )
    lines += ["", "| correction | stage | pulses/s |", "|---|---|---|"]
    where = {
        "hcn": "raw shots (before the AO lens)",
        "lin": "raw shots (before the AO lens)",
        "lin+hcn": "raw shots (before the AO lens)",
    }
    for corr, rate in costs.items():
        lines.append(f"| {corr} | {where[corr]} | {rate:.0f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--preset", default="crouch-sal", choices=("crouch-sal", "zhao-insal"))
    ap.add_argument("--aperture", type=int, help="aperture_pulses (default: 128 / the preset's)")
    ap.add_argument("--json", help="write the figures as JSON here too")
    args = ap.parse_args(argv)
    cfg = config_for(args.preset, args.aperture)
    rows = []
    for label, effects, corr in cases():
        t0 = time.perf_counter()
        rows.append((label, effects, corr, run_case(cfg, effects, corr)))
        print(f"{label} / {corr}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    costs = {c: cost_pulses_per_s(cfg, c) for c in ("hcn", "lin", "lin+hcn")}
    print(markdown(args.preset, cfg, rows, costs))
    if args.json:
        out = {
            "preset": args.preset,
            "config": cfg.to_dict(),
            "cases": [
                {
                    "case": label,
                    "effects": [{"name": n, **p} for n, p in eff],
                    "correction": corr,
                    **m,
                }
                for label, eff, corr, m in rows
            ],
            "cost_pulses_per_s": costs,
        }
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
