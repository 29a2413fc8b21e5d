"""Cross-track receivers for interferometric SAL (Zhao 2014, Fig. 1; Crouch 2012, ch. 6).

Frame of the cross-track plane: y horizontal, away from the track (ground range), z up from the
reference plane.  The scene's main channel is receiver 0: the transmitter and the first receiver
share the phase centre (0, H), H = ``geometry.platform_height_m``.  Receiver k (k = 1 … n-1)
sits at (0, H) + k·b with b = B (cos α, sin α): α = 0 is a horizontal cross-track baseline, α = 90°
a vertical one.  Receivers are aligned along track, so every channel sees the scatterer at the
same along-track offset x.

One pass (Zhao's two apertures, Crouch's fibre array): the light goes out from the main aperture
and comes back to receiver k, so its echo has the bistatic half path
    R_eff = (R_tx + R_rx,k) / 2,        R_rx,k = sqrt(x² + (y - k b_y)² + (H + k b_z - h)²)
and the two-way phase -4π R_eff/λ of the convention in rtsar.params; the interferogram of
receivers 0 and k then holds 2π (R_rx,k - R_tx)/λ (one-way path difference, Zhao eq. 1).

Two pass (Crouch's penny): pass k is a monostatic scan from the offset position, R_eff = R_rx,k,
(interferometric phase 4π (R_rx,k - R_tx)/λ), with its own shot-to-shot phase error: a piston
random walk ψ_k[p] (radians, steps of standard deviation ``piston_step_rad``, drawn from a
Generator seeded by ``seed``; ``truth(pulses)`` returns it) and an along-track offset of the
track ``k · along_track_offset_m`` (a registration error in azimuth).

The scatterers must carry ``ground_range_m`` and ``height_m`` (rtsar.scene.surfaces builds such
scenes) and ``slant_range_m = hypot(ground_range_m, H - height_m)``.  ``snr_db`` adds the
receiver noise of rtsar.scene.effects.noise to every auxiliary channel (independent draws from
the simulator's generator; the main channel's noise is the "noise" effect's).

The scene's platform and transmitter errors reach every receiver (rtsar.scene.effects.base):
along-track position errors through each receiver's own geometry (x = ctx.along_offset_m),
chirp deviations and the common shot phase (``piston``, the reference region's target path)
through ``ctx.echo``, identically on every receiver, so the one-pass interferogram cancels a
piston.  In two-pass mode pass k repeats the scene's errors, and ψ_k / along_track_offset_m
are its errors relative to pass 0 (``truth`` row 0 is zeros).
"""

from __future__ import annotations

import math

import numpy as np

from .base import Effect

MODES = ("one_pass", "two_pass")
MAX_RECEIVERS = 16  # phase centres; the papers' interferometers have two


def receiver_offsets_m(
    baseline_m: float, baseline_angle_deg: float, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Cross-track offsets (Δy, Δz) of receivers 0 … count-1 from the main phase centre, metres."""
    k = np.arange(count, dtype=np.float64)
    a = math.radians(baseline_angle_deg)
    return k * baseline_m * math.cos(a), k * baseline_m * math.sin(a)


class InterferometricReceivers(Effect):
    """Auxiliary receive channels "rx1" … "rx{n-1}" offset cross-track by a baseline."""

    name = "interferometric_receivers"

    def __init__(
        self,
        config,
        baseline_m: float = 1.6e-3,
        baseline_angle_deg: float = 0.0,
        receivers: int = 2,
        mode: str = "one_pass",
        snr_db: float | None = None,
        piston_step_rad: float = 0.0,
        along_track_offset_m: float = 0.0,
        seed: int = 0,
    ):
        g = config.geometry
        if not g.platform_height_m > 0:
            raise ValueError(
                "interferometric_receivers needs geometry.platform_height_m > 0 (the height of "
                "the main phase centre above the reference plane)"
            )
        for name, value in (
            ("baseline_m", baseline_m),
            ("baseline_angle_deg", baseline_angle_deg),
            ("piston_step_rad", piston_step_rad),
            ("along_track_offset_m", along_track_offset_m),
        ):
            if isinstance(value, bool) or not (
                isinstance(value, (int, float)) and math.isfinite(value)
            ):
                raise ValueError(f"interferometric_receivers.{name} must be a finite number")
        if not baseline_m > 0:
            raise ValueError("interferometric_receivers.baseline_m must be > 0")
        if piston_step_rad < 0:
            raise ValueError("interferometric_receivers.piston_step_rad must be >= 0")
        if not (isinstance(receivers, int) and not isinstance(receivers, bool) and receivers >= 2):
            raise ValueError("interferometric_receivers.receivers must be an integer >= 2")
        if receivers > MAX_RECEIVERS:  # each one is a channel as long as the main one
            raise ValueError(
                f"interferometric_receivers.receivers must be at most {MAX_RECEIVERS} (each is "
                f"a channel of its own), got {receivers:,}"
            )
        if mode not in MODES:
            raise ValueError(f"interferometric_receivers.mode must be one of {MODES}, got {mode!r}")
        if mode == "one_pass" and (piston_step_rad or along_track_offset_m):
            raise ValueError(
                "piston_step_rad and along_track_offset_m describe a second pass: mode='two_pass'"
            )
        if snr_db is not None and not math.isfinite(snr_db):
            raise ValueError("interferometric_receivers.snr_db must be finite (or None)")
        if not isinstance(seed, int):
            raise ValueError("interferometric_receivers.seed must be an integer")
        self.platform_height_m = float(g.platform_height_m)
        self.dy_m, self.dz_m = receiver_offsets_m(float(baseline_m), baseline_angle_deg, receivers)
        self.receivers = receivers
        self.mode = mode
        self.piston_step_rad = float(piston_step_rad)
        self.along_track_offset_m = float(along_track_offset_m)
        self.seed = seed
        self.sigma = None if snr_db is None else math.sqrt(0.5 * 10.0 ** (-snr_db / 10.0))
        self._walk = np.zeros((receivers, 0))  # ψ_k[p] for the pulses drawn so far
        self._checked_targets = None  # the Targets whose slant ranges were checked

    def channel_names(self) -> list[str]:
        return [f"rx{k}" for k in range(1, self.receivers)]

    def truth(self, pulses: int) -> np.ndarray:
        """Piston phase ψ_k[p] (radians) of every receiver k (row 0 = main: zeros), pulses 0…n-1.

        Regenerated from ``seed`` (steps drawn pulse-major, so any length gives the same
        prefix): the same sequence the simulation applied.
        """
        if pulses > self._walk.shape[1]:
            n = max(pulses, 2 * self._walk.shape[1], 64)
            rng = np.random.default_rng(self.seed)
            steps = rng.standard_normal((n, self.receivers - 1)).T * self.piston_step_rad
            walk = np.zeros((self.receivers, n))
            walk[1:] = np.cumsum(steps, axis=1)
            self._walk = walk
        return self._walk[:, :pulses].copy()

    def aux_channels(self, ctx) -> dict[str, np.ndarray]:
        tg = ctx.targets
        if tg.ground_range_m is None or tg.height_m is None:
            raise ValueError(
                "interferometric_receivers needs targets with ground_range_m and height_m "
                "(see rtsar.scene.surfaces)"
            )
        x = ctx.along_offset_m
        y = np.asarray(tg.ground_range_m, np.float64)
        z = self.platform_height_m - np.asarray(tg.height_m, np.float64)
        if self._checked_targets is not tg:
            if not np.allclose(np.hypot(y, z), tg.slant_range_m, rtol=0.0, atol=1e-9):
                raise ValueError(
                    "targets: slant_range_m must equal hypot(ground_range_m, "
                    "platform_height_m - height_m) for interferometric_receivers"
                )
            self._checked_targets = tg
        r_tx = ctx.slant_range_m
        if self.mode == "two_pass" and self.piston_step_rad:
            self.truth(ctx.pulse + 1)
            piston = self._walk[:, ctx.pulse]
        else:
            piston = np.zeros(self.receivers)
        out = {}
        for k, name in enumerate(self.channel_names(), start=1):
            if self.mode == "one_pass":
                r_rx = np.sqrt(x * x + (y - self.dy_m[k]) ** 2 + (z + self.dz_m[k]) ** 2)
                r_eff = 0.5 * (r_tx + r_rx)
            else:
                xk = x - k * self.along_track_offset_m
                r_eff = np.sqrt(xk * xk + (y - self.dy_m[k]) ** 2 + (z + self.dz_m[k]) ** 2)
            samples = ctx.echo(r_eff, ctx.gain)
            if piston[k]:
                samples = samples * np.exp(1j * math.remainder(piston[k], 2.0 * math.pi))
            if self.sigma is not None:
                noise = ctx.rng.standard_normal((2, samples.shape[-1]))
                samples = samples + self.sigma * (noise[0] + 1j * noise[1])
            out[name] = samples
        return out
