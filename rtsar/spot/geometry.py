"""Spotlight collection geometry: the arc, the bistatic receiver, exact path lengths (Crouch ch. 9).

Frame (metres): x cross-range, y down-range (away from the sensor at θ = 0), z out of the
collection plane; the scene centre (the rotation axis of Crouch's Fig. 38) is the origin.  The
transmit/receive station sweeps an arc of radius R₀ about the centre, stepping by the arc length
``step_m`` per shot, so θ_n = θ_c + (n - (N-1)/2)·step/R₀ and the station sits at
P_n = -R₀ (sin θ_n, cos θ_n, 0), its beam always on the centre (spotlight).  A fixed bistatic
receiver sits at B = -R_b (sin θ_b, cos θ_b, 0).  Crouch writes the station at +R(sin θ, cos θ)
with scatterer (u, w); that is this frame with (u, w) = (-x, -y).

Path lengths are exact (Crouch eqs. 9.1a,b and 9.2a,b), never the expansions of eq. 9.3:
monostatic L = 2|P_n - p|, bistatic L = |P_n - p| + |B - p|.  The dechirped FMCW echo of a path
L is the simulator's (rtsar.scene.simulator) at the effective one-way range r = L/2; its phase
model ``echo_cycles`` below is the one the backprojection reference matches against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params import C_M_PER_S, FMCWChirp

MAX_SPOT_PULSES = 1 << 17


@dataclass(frozen=True)
class SpotlightGeometry:
    """The spotlight collection: arc radius, arc step, shots, centre angle, bistatic receiver.

    ``bistatic_range_m``/``bistatic_angle_rad`` place the fixed receiver (None: monostatic
    only); ``bistatic_lo_range_m`` is that receiver's LO delay as a one-way range (None: half
    the path to the scene centre, (R₀ + R_b)/2).
    """

    range_m: float
    step_m: float
    pulses: int
    centre_angle_rad: float = 0.0
    bistatic_range_m: float | None = None
    bistatic_angle_rad: float | None = None
    bistatic_lo_range_m: float | None = None

    def __post_init__(self):
        for name in ("range_m", "step_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"spotlight {name} must be a finite number > 0, got {v!r}")
        if not (isinstance(self.pulses, int) and 2 <= self.pulses <= MAX_SPOT_PULSES):
            raise ValueError(f"spotlight pulses must be an integer in 2..{MAX_SPOT_PULSES}")
        if not math.isfinite(self.centre_angle_rad):
            raise ValueError("spotlight centre_angle_rad must be finite")
        if self.sweep_rad >= math.pi / 3:
            raise ValueError(f"spotlight sweep {math.degrees(self.sweep_rad):.1f}° exceeds 60°")
        if (self.bistatic_range_m is None) != (self.bistatic_angle_rad is None):
            raise ValueError("give both bistatic_range_m and bistatic_angle_rad, or neither")
        if self.bistatic_range_m is not None:
            if not (math.isfinite(self.bistatic_range_m) and self.bistatic_range_m > 0):
                raise ValueError("bistatic_range_m must be finite and > 0")
            if not math.isfinite(self.bistatic_angle_rad):
                raise ValueError("bistatic_angle_rad must be finite")

    @property
    def step_rad(self) -> float:
        return self.step_m / self.range_m

    @property
    def sweep_rad(self) -> float:
        """Δθ, the angle swept by the N shots: (N - 1)·step/R₀."""
        return (self.pulses - 1) * self.step_rad

    @property
    def bistatic(self) -> bool:
        return self.bistatic_range_m is not None

    def angles_rad(self, pulses=None) -> np.ndarray:
        """θ_n of shots ``pulses`` (default all), float64."""
        n = np.arange(self.pulses) if pulses is None else np.asarray(pulses, np.float64)
        return self.centre_angle_rad + (n - 0.5 * (self.pulses - 1)) * self.step_rad

    def station_m(self, pulses=None) -> np.ndarray:
        """Tx/Rx station positions P_n [n, 3]."""
        th = self.angles_rad(pulses)
        return np.stack([-self.range_m * np.sin(th), -self.range_m * np.cos(th), 0 * th], -1)

    def receiver_m(self) -> np.ndarray:
        """Bistatic receiver position B [3] (ValueError without one)."""
        if not self.bistatic:
            raise ValueError("this spotlight geometry has no bistatic receiver")
        r, t = self.bistatic_range_m, self.bistatic_angle_rad
        return np.array([-r * math.sin(t), -r * math.cos(t), 0.0])

    def lo_range_m(self, wf: FMCWChirp, channel: str) -> float:
        """The LO delay of a channel as a one-way range ("main" or "bistatic")."""
        if channel == "main":
            return wf.reference_range_m
        if channel == "bistatic":
            if self.bistatic_lo_range_m is not None:
                return self.bistatic_lo_range_m
            return 0.5 * (self.range_m + float(np.linalg.norm(self.receiver_m())))
        raise ValueError(f"unknown spotlight channel {channel!r} (main, bistatic)")

    def half_path_m(self, points_m: np.ndarray, pulses=None, channel: str = "main") -> np.ndarray:
        """Exact effective one-way range L/2 [n, point] (Crouch eqs. 9.2a,b)."""
        p = np.atleast_2d(np.asarray(points_m, np.float64))
        tx = np.linalg.norm(self.station_m(pulses)[:, None, :] - p[None, :, :], axis=-1)
        if channel == "main":
            return tx
        if channel == "bistatic":
            rx = np.linalg.norm(self.receiver_m()[None, :] - p, axis=-1)
            return 0.5 * (tx + rx[None, :])
        raise ValueError(f"unknown spotlight channel {channel!r} (main, bistatic)")

    def look_vectors(self, pulses=None, channel: str = "main") -> tuple[np.ndarray, np.ndarray]:
        """(φ_n, g_n): direction angle and length of e_tx + e_rx, the unit vectors from the
        transmitter and the receiver towards the centre (L_p - L_c ≈ (e_tx + e_rx)·p, so the
        shot samples the scene's spectrum along that direction at radius g·k; g = 2
        monostatic, 2 cos(β/2) bistatic)."""
        st = self.station_m(pulses)[:, :2]
        e_tx = -st / np.linalg.norm(st, axis=-1, keepdims=True)
        if channel == "main":
            e = 2.0 * e_tx
        else:
            b = self.receiver_m()[:2]
            if channel != "bistatic":
                raise ValueError(f"unknown spotlight channel {channel!r}")
            e = e_tx - b[None, :] / np.linalg.norm(b)
        return np.arctan2(e[:, 0], e[:, 1]), np.hypot(e[:, 0], e[:, 1])

    def to_dict(self) -> dict:
        d = {
            "range_m": self.range_m,
            "step_m": self.step_m,
            "pulses": self.pulses,
            "centre_angle_rad": self.centre_angle_rad,
        }
        for k in ("bistatic_range_m", "bistatic_angle_rad", "bistatic_lo_range_m"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        return d


def geometry_from_dict(d: dict) -> SpotlightGeometry:
    known = {
        "range_m",
        "step_m",
        "pulses",
        "centre_angle_rad",
        "bistatic_range_m",
        "bistatic_angle_rad",
        "bistatic_lo_range_m",
    }
    if not isinstance(d, dict) or set(d) - known:
        raise ValueError(f"spotlight geometry: unknown keys {sorted(set(d) - known)}")
    try:
        return SpotlightGeometry(**d)
    except TypeError as exc:
        raise ValueError(f"spotlight geometry: {exc}") from None


def sample_times_s(wf: FMCWChirp) -> np.ndarray:
    """The simulator's FMCW sample times (s from mid-chirp): t_m = (m - M/2)/fs."""
    s = wf.samples_per_shot
    return (np.arange(s) - 0.5 * s) / wf.sample_rate_hz


def echo_cycles(
    half_path_m: np.ndarray, lo_range_m: float, wf: FMCWChirp, wavelength_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Phase model of a dechirped echo at effective range r = L/2 (Crouch eqs. 3.3-3.5, exact).

    cycles(t) = c0 + f·t with c0 = -2(r - r_lo)/λ + K Δτ (τ + τ_lo)/2 (reduced mod 1, float64)
    and f = -K Δτ, Δτ = 2(r - r_lo)/c: the same synthesis as rtsar.scene.simulator.  Returns
    (c0, f) with the shape of ``half_path_m``.
    """
    r = np.asarray(half_path_m, np.float64)
    k = wf.chirp_rate_hz_per_s
    tau = 2.0 * r / C_M_PER_S
    tau_lo = 2.0 * lo_range_m / C_M_PER_S
    dtau = 2.0 * (r - lo_range_m) / C_M_PER_S
    c0 = np.fmod(-2.0 * (r - lo_range_m) / wavelength_m + 0.5 * k * dtau * (tau + tau_lo), 1.0)
    return c0, -k * dtau


def wavenumbers(wf: FMCWChirp, wavelength_m: float) -> tuple[float, float]:
    """(k_c, dk): k(t_m) = 2π(f0 + K t_m)/c = k_c + dk·(m - M/2), dk = 2πK/(c fs)."""
    return (
        2.0 * math.pi / wavelength_m,
        2.0 * math.pi * wf.chirp_rate_hz_per_s / (C_M_PER_S * wf.sample_rate_hz),
    )


def cross_range_resolution_m(wavelength_m: float, sweep_rad: float) -> float:
    """ρ = λ/(2Δθ), Crouch eq. 9.5 (monostatic; the -3 dB width is 0.886 ρ unweighted)."""
    return wavelength_m / (2.0 * sweep_rad)
