"""Spotlight runs: simulate to a recording, form images (batch or progressive), publish them.

Progressive images go out on their own ZeroMQ topic ``spot`` (the strip-map topics are
untouched): frame 0 b"spot", frame 1 a JSON header, frame 2 the image complex64 little-endian
[x, y].  Header: seq, shots (in the image so far), pulses (planned), sweep_rad (look-angle span
so far), resolution_m (the cross-range -3 dB width: w·λ/(2Δθ_so_far), eq. 9.5, with w the
azimuth window's factor, 0.886 unweighted, rtsar.windows.impulse_response_width),
range_resolution_m (w·c/(2B), the range window's), final (the last, equal to the batch image),
shape, x0_m, dx_m, y0_m, dy_m, frame_angle_rad, channel, look.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..samples import nonfinite_rows, zero_nonfinite_rows
from ..sinks.image_file import read_image, write_image
from ..sinks.io import RecordingWriter, open_recording, replace_when_complete
from ..sources.formats.cphd_reader import open_cphd
from ..sources.formats.sigmf_reader import open_sigmf, sigmf_base
from ..spot.backprojection import backproject
from ..spot.geometry import geometry_from_dict
from ..spot.pfa import PfaSettings, PolarFormatPlan, ProgressivePolarFormat, polar_format
from ..spot.scene import SpotScene
from ..spot.simulate import BISTATIC_CHANNEL, SpotlightSimulator
from ..windows import impulse_response_width

TOPIC = "spot"
SPOT_KEY = "spotlight"  # the recording's scene attribute holds {"spotlight": SpotScene.to_dict()}


def simulate_to(scene: SpotScene, output: str | Path, batch: int = 64) -> int:
    """Every shot of a spotlight scene into an rtsar recording (main + ``bistatic`` channel);
    along_track_m holds the arc position R₀θ_n.  Returns the number of shots."""
    sim = SpotlightSimulator(scene)
    with (
        replace_when_complete(output) as tmp,
        RecordingWriter(tmp, scene.config, {SPOT_KEY: scene.to_dict()}, batch) as rec,
    ):
        while True:
            shots = list(sim.shots(batch))
            if not shots:
                break
            prf = scene.config.geometry.prf_hz
            rec.write(
                [s.samples for s in shots],
                [s.index for s in shots],
                [s.index / prf for s in shots],
                [s.arc_m for s in shots],
                {k: np.stack([s.aux[k] for s in shots]) for k in shots[0].aux},
            )
    return sim.pulses


def open_spot_input(path: str | Path):
    """A recording by its name: ``*.cphd`` → CPHD, a SigMF file (or the base name of one whose
    ``.sigmf-meta`` exists) → SigMF, anything else → an rtsar recording (HDF5)."""
    path = Path(path)
    if path.suffix.lower() == ".cphd":
        return open_cphd(path)
    if sigmf_base(path) is not None:
        return open_sigmf(path)
    if not path.exists() and path.with_name(path.name + ".sigmf-meta").exists():
        return open_sigmf(path.with_name(path.name + ".sigmf-meta"))
    return open_recording(path)


class SpotRecording:
    """A spotlight recording, checked: its configuration, geometry, rotation and channels.
    Read from rtsar's .h5 or from the CPHD / SigMF that ``rtsar export`` made of one."""

    def __init__(self, path: str | Path):
        self.rec = open_spot_input(path)
        spot = self.rec.scene.get(SPOT_KEY)
        if not isinstance(spot, dict) or "spotlight_geometry" not in spot:
            self.rec.close()
            raise ValueError(
                f"{path}: not a spotlight recording (no spotlight geometry): a strip-map "
                "recording is imaged by `rtsar process`"
            )
        self.config = self.rec.config
        self.geometry = geometry_from_dict(spot["spotlight_geometry"])
        self.rotation_rad = float(spot.get("rotation_rad", 0.0))
        if self.rec.pulses != self.geometry.pulses:
            n, p = self.rec.pulses, self.geometry.pulses
            self.rec.close()
            raise ValueError(f"{path}: {n} shots recorded, the spotlight geometry plans {p}")

    def blocks(self, channel: str, size: int) -> Iterator[np.ndarray]:
        if channel == "main":
            yield from self.rec.batches(size)
            return
        if channel not in self.rec.channels:
            raise ValueError(f"{self.rec.path}: no {channel!r} channel recorded")
        ds = self.rec.channels[channel]
        for i in range(0, self.rec.pulses, size):
            yield ds[i : i + size]

    def close(self) -> None:
        self.rec.close()


def live_blocks(scene: SpotScene, channel: str, size: int) -> Iterator[np.ndarray]:
    """Shots of a live simulation, ``size`` at a time, as they are generated."""
    if channel == BISTATIC_CHANNEL and not scene.geometry.bistatic:
        raise ValueError("the scene has no bistatic receiver ([spotlight] bistatic_angle_deg)")
    sim = SpotlightSimulator(scene)
    while True:
        main, aux = sim.block(size)
        if not len(main):
            return
        yield main if channel == "main" else aux[channel]


def declared_resolution_m(plan: PolarFormatPlan, shots: int | None = None) -> tuple[float, float]:
    """(cross-range, range) -3 dB widths of an image of the first ``shots`` shots (all: None):
    each window's factor (rect 0.886) times the cell 2π/Δk of the inscribed rectangle the image
    is formed from (rtsar.spot.pfa.PolarFormatPlan.cell_m; λ/2Δθ (Crouch eq. 9.5) and c/2B
    for a narrow sweep and band)."""
    s = plan.settings
    cell_x, cell_y = plan.cell_m(shots)
    return (
        impulse_response_width(s.azimuth_window) * cell_x,
        impulse_response_width(s.range_window) * cell_y,
    )


def image_header(plan: PolarFormatPlan, seq: int, shots: int, sweep: float, final: bool) -> dict:
    cross, along = declared_resolution_m(plan, shots) if sweep > 0 else (None, None)
    return {
        "seq": seq,
        "shots": shots,
        "pulses": len(plan.psi),
        "sweep_rad": sweep,
        "resolution_m": cross,
        "range_resolution_m": along,
        "final": final,
        "shape": [len(plan.x_m), len(plan.y_m)],
        "x0_m": float(plan.x_m[0]),
        "dx_m": plan.dx,
        "y0_m": float(plan.y_m[0]),
        "dy_m": plan.dy,
        "frame_angle_rad": plan.alpha_rad,
        "channel": plan.channel,
    }


def progressive(blocks, plan: PolarFormatPlan, every: int, publish=None) -> np.ndarray:
    """Feed shot blocks to a ProgressivePolarFormat; every ``every`` shots (and at the end) form
    the image of the aperture so far and hand it to ``publish(header, image)``.  Returns the
    final image (equal to the batch PFA of the same shots)."""
    if every < 2:
        raise ValueError(f"--every must be >= 2 shots, got {every}")
    stream = ProgressivePolarFormat(plan)
    seq, next_at = 0, every
    total = len(plan.psi)
    image = None
    for block in blocks:
        i = 0
        while i < len(block):  # cut where an image is due: a source's blocks (1,024 shots from
            due = next_at - stream.count  # a recording) put one there at 1,024, 2,048, … for 1,000
            take = min(len(block) - i, due if due > 0 else 1)  # (not ready: shot by shot)
            stream.push(block[i : i + take])
            i += take
            if (stream.count >= next_at and stream.ready()) or stream.count == total:
                image = stream.image()
                final = stream.count == total
                if publish is not None:
                    publish(image_header(plan, seq, stream.count, stream.sweep_rad(), final), image)
                seq += 1
                next_at = stream.count + every
    if stream.count != total:
        raise ValueError(f"{stream.count} shots arrived of the {total} planned")
    if stream.nonfinite_shots:
        warnings.warn(f"{stream.nonfinite_shots} shots held NaN/Inf and were zeroed", stacklevel=2)
    return image


def batch_image(data: np.ndarray, plan: PolarFormatPlan, method: str, upsample: int = 16):
    """The image of all shots by ``method``: "pfa" or "backprojection" (fast, same aperture)."""
    bad = int(nonfinite_rows(data).sum())
    if bad:
        warnings.warn(f"{bad} shots held NaN/Inf and were zeroed", stacklevel=2)
        data = zero_nonfinite_rows(data)[0]
    if method == "pfa":
        return polar_format(data, plan)
    if method == "backprojection":
        w = plan.polar_weights(0, len(data))
        values = backproject(
            data, plan.config, plan.geometry, plan.scene_points(), plan.channel, w, 0, upsample
        )
        return plan.baseband(values, 0, len(data))
    raise ValueError(f"unknown method {method!r} (pfa, backprojection)")


def write_spot_image(path, image, plan: PolarFormatPlan, rotation_rad: float, **attrs) -> None:
    """An rtsar image file: /image [x, y] on the frame turned by α, with the spotlight geometry."""
    spot = {
        "geometry": plan.geometry.to_dict(),
        "frame_angle_rad": plan.alpha_rad,
        "channel": plan.channel,
        "look": plan.look,
        "rotation_rad": rotation_rad,
        "settings": plan.settings.__dict__,
    }
    with replace_when_complete(path) as tmp:
        write_image(
            tmp, image, plan.x_m, plan.y_m, plan.config, spotlight=json.dumps(spot), **attrs
        )


def read_spot_image(path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """(image [x, y], x_m, y_m, spotlight attributes) of a spotlight image file."""
    image, x, y, attrs = read_image(path)
    if "spotlight" not in attrs:
        raise ValueError(f"{path}: not a spotlight image (no spotlight attribute)")
    return image, x, y, json.loads(attrs["spotlight"])


def settings_from(args) -> PfaSettings:
    ext = None if args.extent_mm is None else tuple(1e-3 * e for e in args.extent_mm)
    return PfaSettings(
        oversampling=args.oversampling,
        extent_m=ext,
        range_window=args.window,
        azimuth_window=args.window,
        range_interpolation=args.range_interpolation,
    )


def timed(fn, *a, **k):
    t0 = time.perf_counter()
    out = fn(*a, **k)
    return out, time.perf_counter() - t0


def describe(plan: PolarFormatPlan) -> str:
    g, s = plan.geometry, plan.settings
    rho_x, rho_y = declared_resolution_m(plan)
    w_x, w_y = (impulse_response_width(w) for w in (s.azimuth_window, s.range_window))
    return (
        f"{g.pulses} shots over {math.degrees(g.sweep_rad):.3f}°, channel {plan.channel}: "
        f"ρx = {w_x:.3f}·2π/Δkx = {1e6 * rho_x:.2f} µm, "
        f"ρy = {w_y:.3f}·2π/Δky = {1e6 * rho_y:.2f} µm (the inscribed rectangle); "
        f"image {len(plan.x_m)} x {len(plan.y_m)} px of {1e6 * plan.dx:.2f} x "
        f"{1e6 * plan.dy:.2f} µm"
    )
