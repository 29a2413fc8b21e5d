"""Live demo: a scene simulated at its PRF, focused by the streaming engine as shots arrive.

The simulator plays the instrument: shot p is released at t0 + p/PRF (absolute schedule, so no
drift accumulates).  Shots are processed in micro-batches; a line's latency is measured from the
arrival of the last pulse it contains to the moment the engine returned it.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from .engine import StreamProcessor
from .scene import Scene, Simulator


def run_live(
    scene: Scene,
    duration_s: float | None = None,
    lens_backend: str = "opencl",
    device: str | None = None,
    output=None,
    stream=None,
) -> int:
    stream = stream or sys.stdout
    cfg = scene.config
    prf = cfg.geometry.prf_hz
    batch = cfg.processor.micro_batch
    sim = Simulator(scene)
    eng = StreamProcessor(cfg, lens_backend, device, scene.start_along_track_m)
    n_ap = cfg.processor.aperture_pulses
    print(
        f"rtsar run: scene '{scene.name}' ({len(scene.targets)} targets, "
        f"{scene.pulses} shots at {prf:g} Hz = {scene.pulses / prf:.1f} s), "
        f"CCD {n_ap} x {cfg.processor.range_bins}, micro-batch {batch}, "
        f"{cfg.processor.correlator} correlator, {lens_backend} lens",
        file=stream,
    )
    parts, latencies = [], []
    busy = 0.0
    late_batches = 0
    p = 0
    t0 = time.perf_counter()
    last_report = t0
    limit = scene.pulses if duration_s is None else min(scene.pulses, int(duration_s * prf))
    interrupted = False
    try:
        while p < limit:
            count = min(batch, limit - p)
            shots = sim.block(count)
            arrivals = t0 + (p + np.arange(count)) / prf
            wait = arrivals[-1] - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            else:
                late_batches += 1
            start = time.perf_counter()
            out = eng.push(shots)
            done = time.perf_counter()
            busy += done - start
            if len(out.lines):
                # Line j completes with pulse j + N - 1.
                last_pulse = out.first_line + np.arange(len(out.lines)) + n_ap - 1
                arrived = t0 + last_pulse / prf
                latencies.extend((done - arrived).tolist())
                if output:
                    parts.append(out.lines)
            p += count
            if done - last_report >= 0.5 or p >= limit:
                last_report = done
                elapsed = done - t0
                lat = np.array(latencies[-2000:]) * 1e3
                lat_txt = (
                    f"latency median {np.median(lat):6.2f} ms p99 {np.percentile(lat, 99):6.2f} ms"
                    if len(lat)
                    else "latency      -"
                )
                print(
                    f"t={elapsed:6.2f} s  pulses {p:7d}  lines {eng.lines_out:7d}  "
                    f"PRF {p / elapsed:8.1f} Hz  load {100 * busy / elapsed:5.1f} %  {lat_txt}  "
                    f"late batches {late_batches}",
                    file=stream,
                    flush=True,
                )
    except KeyboardInterrupt:  # stop cleanly: flush, write what was focused, summarise
        interrupted = True
        print("\ninterrupted: finishing", file=stream)
    tail = eng.flush()
    if output:
        parts.append(tail.lines)
        from .io import write_image

        image = np.concatenate(parts)
        write_image(
            output,
            image,
            eng.azimuth_m(0, len(image)),
            eng.range_m,
            cfg,
            source=f"live:{scene.name}",
            lens=lens_backend,
            correlator=cfg.processor.correlator,
            nonfinite_pulses=eng.nonfinite_pulses,
        )
        print(f"wrote {output}: {image.shape[0]} x {image.shape[1]}", file=stream)
    lat = np.array(latencies) * 1e3
    load = 100 * busy / max(time.perf_counter() - t0, 1e-9)
    summary = f"done: {p} pulses, {eng.lines_out} lines, processing load {load:.1f} % of real time"
    if len(lat):
        summary += f", latency median {np.median(lat):.2f} ms, p99 {np.percentile(lat, 99):.2f} ms"
    print(summary, file=stream)
    return 130 if interrupted else 0
