"""Platform phase errors: piston (Crouch eq. 4.12) and along-track step jitter (Crouch eq. 4.13).

Both are errors of the platform, common to every receiver of a pass: piston reaches each
receiver's echo as the same phase (``common_to_receivers``), the along-track error moves the
platform, which each receiver sees through its own geometry.

Both are driven by ``PulseProcess``, a seeded random sequence indexed by pulse number: white
(independent per pulse) + random walk + integrated random walk ("drift", the smooth, roughly
quadratic wander under the fast errors of Crouch Fig. 20) + a sinusoidal vibration.  The sequence
is generated in fixed chunks, each from its own seed (seed, stream, chunk), so any pulse's value
can be regenerated later (``truth``) in any order with bounded memory; the simulator's own RNG
(noise) is not touched, so adding an error leaves every other random draw of a scene unchanged.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

from .base import Effect


def _non_negative(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return value


def check_seed(name: str, seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {seed!r}")
    return int(seed)


class PulseProcess:
    """A reproducible error sequence e(p), one value per pulse p >= 0 (in the caller's unit).

    e(p) = white·z0(p) + Σ_{m≤p} walk·z1(m) + Σ_{m≤p} Σ_{k≤m} drift·z2(k)
           + vibration · sin(2π vibration_hz · p / prf_hz + θ0)

    with z0, z1, z2 independent standard normal sequences and θ0 uniform, all drawn from
    ``seed`` and ``stream`` (two processes of one effect use different streams).  ``walk`` is the
    standard deviation of one random-walk step, ``drift`` that of one step of the rate of change
    (integrated random walk: after n pulses its standard deviation is ≈ drift·n^1.5/√3).
    The vibration is sampled once per pulse, at the shot time p / prf_hz: the error is constant
    within a shot (Crouch ch. 4, "Piston Error").
    """

    CHUNK = 4096

    def __init__(
        self,
        prf_hz: float,
        white: float = 0.0,
        walk: float = 0.0,
        drift: float = 0.0,
        vibration: float = 0.0,
        vibration_hz: float = 0.0,
        seed: int = 0,
        stream: int = 0,
        name: str = "process",
    ):
        self.prf_hz = float(prf_hz)
        self.white = _non_negative(f"{name} white", white)
        self.walk = _non_negative(f"{name} walk", walk)
        self.drift = _non_negative(f"{name} drift", drift)
        self.vibration = _non_negative(f"{name} vibration", vibration)
        self.vibration_hz = _non_negative(f"{name} vibration_hz", vibration_hz)
        self.seed = check_seed(f"{name} seed", seed)
        self.stream = check_seed(f"{name} stream", stream)
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.stream]))
        self.vibration_phase_rad = float(2.0 * math.pi * rng.random())
        # State (walk, rate, drift) before chunk k; values of the last few chunks.
        self._starts: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)]
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()

    @property
    def is_zero(self) -> bool:
        return not (self.white or self.walk or self.drift or self.vibration)

    def _chunk_parts(self, k: int) -> tuple[np.ndarray, tuple[float, float, float]]:
        seq = np.random.SeedSequence([self.seed, self.stream, 1 + k])
        z = np.random.default_rng(seq).standard_normal((3, self.CHUNK))
        walk0, rate0, drift0 = self._starts[k]
        walk = walk0 + np.cumsum(self.walk * z[1])
        rate = rate0 + np.cumsum(self.drift * z[2])
        drift = drift0 + np.cumsum(rate)
        return self.white * z[0] + walk + drift, (walk[-1], rate[-1], drift[-1])

    def _chunk(self, k: int) -> np.ndarray:
        if k in self._cache:
            self._cache.move_to_end(k)
            return self._cache[k]
        while len(self._starts) <= k:  # states are cumulative: walk the chunks in order once
            _, end = self._chunk_parts(len(self._starts) - 1)
            self._starts.append(end)
        values, _ = self._chunk_parts(k)
        self._cache[k] = values
        if len(self._cache) > 4:
            self._cache.popitem(last=False)
        return values

    def values(self, pulses) -> np.ndarray:
        """e(p) for an int or array of pulse numbers (float64, same shape)."""
        p = np.asarray(pulses)
        if not np.issubdtype(p.dtype, np.integer):
            raise ValueError("pulse numbers must be integers")
        if p.size and p.min() < 0:
            raise ValueError("pulse numbers must be >= 0")
        flat = p.reshape(-1).astype(np.int64)
        out = np.zeros(flat.shape, np.float64)
        if self.white or self.walk or self.drift:
            chunks = flat // self.CHUNK
            for k in np.unique(chunks):
                sel = chunks == k
                out[sel] = self._chunk(int(k))[flat[sel] - k * self.CHUNK]
        if self.vibration:
            arg = np.mod(self.vibration_hz * flat / self.prf_hz, 1.0)  # cycles mod 1, float64
            out += self.vibration * np.sin(2.0 * math.pi * arg + self.vibration_phase_rad)
        return out.reshape(p.shape)


class PistonError(Effect):
    """Piston phase error: a shot-to-shot phase constant within each shot (Crouch eq. 4.12).

    Crouch writes the shot as E_n ∝ exp[-iφ(n)]·Σ_j exp[-i(μu_j + ξw_j)] with
    φ(n) = PistonError(n)·2π/λ.  Here the effect multiplies the shot by exp(iε(n)),
    ε(n) = -φ(n) the *phase added to the shot* (the processes are symmetric, so only the sign
    convention differs); ``truth(pulses)`` returns ε(n) in radians and ``displacement_m`` the
    line-of-sight platform displacement λε/(4π) that causes it in rtsar's two-way convention.
    The range shift of that displacement (tens of µm against c/2B) is neglected, as in Crouch
    eq. 4.12.  Parameters (radians, per pulse; see PulseProcess): ``white_rad``,
    ``random_walk_rad`` (step standard deviation), ``drift_rad`` (integrated random walk),
    ``vibration_rad`` amplitude at ``vibration_hz``; ``seed`` of the error sequence.
    Crouch Fig. 20 scale (several hundred radians over 2048 shots, fast content on top):
    drift_rad ≈ 5e-3, random_walk_rad ≈ 0.3, vibration_rad of a few radians.

    A platform error, common to every receiver of the pass (``common_to_receivers``): the main
    channel and each auxiliary receiver (second InSAL receiver, SAM masks) get the same ε(n), so
    an interferogram between them cancels it (Zhao 2014: one transmitter, both receivers on the
    platform; INO 3D patent: S0, S1, S2 share every pulse).
    """

    name = "piston"
    common_to_receivers = True

    def __init__(
        self,
        config,
        white_rad: float = 0.0,
        random_walk_rad: float = 0.0,
        drift_rad: float = 0.0,
        vibration_rad: float = 0.0,
        vibration_hz: float = 0.0,
        seed: int = 0,
    ):
        self.wavelength_m = config.geometry.wavelength_m
        self.process = PulseProcess(
            config.geometry.prf_hz,
            white_rad,
            random_walk_rad,
            drift_rad,
            vibration_rad,
            vibration_hz,
            seed,
            stream=0,
            name="piston",
        )

    def truth(self, pulses) -> np.ndarray:
        """ε(p): the phase (rad) added to each shot, unwrapped (float64)."""
        return self.process.values(pulses)

    def displacement_m(self, pulses) -> np.ndarray:
        """Line-of-sight displacement (m) giving ε two-way: λε/(4π) (Crouch eq. 4.12, two-way)."""
        return self.truth(pulses) * self.wavelength_m / (4.0 * math.pi)

    def apply_to_shot(self, pulse, samples, rng):
        eps = float(self.process.values(pulse))
        samples *= np.exp(1j * math.fmod(eps, 2.0 * math.pi))


class AlongTrackJitter(Effect):
    """Along-track step uncertainty Δ: the shot is taken at x_p + Δ(p) (Crouch eq. 4.13, Fig. 15).

    A target at along-track offset x from the platform and range R then sees its phase change by
    about 4π x Δ / (λ R) (two-way; Crouch eq. 4.13 writes the one-way 2π x Δ / (λ R)), which
    grows with x: unlike piston it cannot be removed by one phase per shot.  ``std_m``: standard
    deviation of Δ; ``accumulate`` = False: Δ independent per pulse (a lead screw's position
    error), True: the step errors add up (a random walk of the position, step std ``std_m``).
    ``truth(pulses)`` returns Δ in metres.
    """

    name = "along_track_jitter"

    def __init__(self, config, std_m: float = 0.0, accumulate: bool = False, seed: int = 0):
        if not isinstance(accumulate, bool):
            raise ValueError("along_track_jitter.accumulate must be true or false")
        std_m = _non_negative("along_track_jitter.std_m", std_m)
        self.wavelength_m = config.geometry.wavelength_m
        self.process = PulseProcess(
            config.geometry.prf_hz,
            white=0.0 if accumulate else std_m,
            walk=std_m if accumulate else 0.0,
            seed=seed,
            stream=1,
            name="along_track_jitter",
        )

    def truth(self, pulses) -> np.ndarray:
        """Δ(p): along-track position error of each shot (m)."""
        return self.process.values(pulses)

    def phase_change_rad(self, pulses, along_offset_m: float, slant_range_m: float) -> np.ndarray:
        """Crouch eq. 4.13, two-way: 4π x Δ(p) / (λ R) for a target at offset x, range R."""
        return (
            4.0
            * math.pi
            * along_offset_m
            * self.truth(pulses)
            / (self.wavelength_m * slant_range_m)
        )

    def along_track_error_m(self, pulse):
        return float(self.process.values(pulse))
