"""Height from spatially amplitude-modulated SA images (INO 3D patent, eqs. 5-15).

Three co-registered complex images of one scene, image[azimuth, range]: S0 unmodulated, S1 and
S2 received through cosine and sine masks of the return angle φ in the receiver's back focal
plane (patent eqs. 3-4; simulated by rtsar.scene.effects.sam3d).  Per pixel:

1. wrapped phase ψ_PW,0 = arg[(S1/S0 - a) + i (S2/S0 - a)] = 2πφ/P_φ           (eq. 5)
2. flat-earth phase removed, ψ_PW = ψ_PW,0 - ψ_FE, with ψ_FE from the geometry (eq. 7) or
   from images of a flat reference (eq. 15)                                      (eq. 6)
3. looks averaged, dark (S0 ≈ 0) and incoherent pixels masked and counted
4. unwrapped, ψ_PU = unwrap[ψ_PW] = 2π δφ / P_φ                                  (eq. 8)
5. height h ≈ P_φ R0 sin φ0 ψ_PU / 2π                                            (eq. 13)
   (or exactly by eq. 9: φ = φ_FE(R) + δφ, h = H0 - R cos φ)

Step 1 is written without a division: with S1 = S0 T1 the ratio S1/S0 is real, so
(S1/S0 - a) = [Re(S1 S0*) - a|S0|²] / |S0|², and because arg ignores the positive factor |S0|²,
ψ_PW,0 = arg z with z = [Re(S1 S0*) - a|S0|²] + i [Re(S2 S0*) - a|S0|²] = b |S0|² e^{iψ_PW,0}.
A dark pixel then gives z ≈ 0 rather than a 0/0, and averaging z over looks weights each pixel
by its intensity (the least-squares phase of the look window).  The modulation coherence
γ = |<z>| / (|b| <|S0|²>) is 1 for one return angle per window without noise and falls with
noise (to S/(S + N0) on average) and mixed angles; it masks the pixels the phase cannot be
trusted at.

Receiver noise of power N0 per pixel in S0 leaves <Re(S1 S0*)> unbiased (the channels' noises
are independent) but adds N0 to <|S0|²>: z then carries -a N0 (1 + i), which pulls the phase
towards -3π/4 and makes a noise-only pixel look coherent (γ = a√2/|b|).  Given N0
(``noise_power``: measured with no return, or from the known receiver noise through the engine)
z uses |S0|² - N0 instead (γ keeps the total power), and a pixel is dark when its averaged
signal power <|S0|²> - N0 is at or below the floor.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage

from ..phase import TWO_PI, wrap
from .looks import box_mean
from .unwrap import unwrap_quality

HEIGHT_MODELS = ("eq13", "exact")
MAX_COHERENCE = 1.25  # see _classify


@dataclass(frozen=True)
class ModulationGeometry:
    """What the height inversion needs to know about the platform and the masks.

    platform_height_m   H0, platform height above the reference plane (patent Fig. 2)
    reference_range_m   R0, slant range along the nominal illumination axis (eq. 7)
    angular_period_rad  P_φ = P_y / f, angular period of the masks (eqs. 3-4)
    mask_offset_a, mask_depth_b   a, b of eq. 1
    mask_phase_rad      θ_mask, phase of the mask pattern at φ = 0 (0 in the patent; a lateral
                        shift Δy of the mask gives 2πΔy/P_y): ψ_PW,0 = 2πφ/P_φ + θ_mask.  Eq. 7
                        adds it; the reference calibration of eq. 15 measures it.
    """

    platform_height_m: float
    reference_range_m: float
    angular_period_rad: float
    mask_offset_a: float = 0.5
    mask_depth_b: float = 0.5
    mask_phase_rad: float = 0.0

    def __post_init__(self):
        for name, value in asdict(self).items():
            if not math.isfinite(value):
                raise ValueError(f"ModulationGeometry.{name} must be finite")
        if not 0 < self.platform_height_m < self.reference_range_m:
            raise ValueError("ModulationGeometry needs 0 < platform_height_m < reference_range_m")
        if not self.angular_period_rad > 0:
            raise ValueError("ModulationGeometry.angular_period_rad must be > 0")
        if self.mask_depth_b == 0:
            raise ValueError("ModulationGeometry.mask_depth_b must be non-zero")

    @classmethod
    def from_config(cls, config, angular_period_rad: float, **kwargs) -> ModulationGeometry:
        """H0 from ``geometry.platform_height_m``, R0 from ``geometry.slant_range_m``."""
        g = config.geometry
        kwargs.setdefault("reference_range_m", g.slant_range_m)
        return cls(g.platform_height_m, angular_period_rad=angular_period_rad, **kwargs)

    @property
    def look_angle_rad(self) -> float:
        """φ0 with H0 = R0 cos φ0 (patent eq. 7)."""
        return math.acos(self.platform_height_m / self.reference_range_m)

    @property
    def ambiguity_height_m(self) -> float:
        """h_2π = P_φ R0 sin φ0, the height of one 2π cycle (patent [0047])."""
        return self.angular_period_rad * self.reference_range_m * math.sin(self.look_angle_rad)

    @property
    def elevation_resolution_m(self) -> float:
        """Δh ≈ P_φ R0 sin φ0 / 20, for a phase resolution of 2π/20 (patent eq. 14)."""
        return self.ambiguity_height_m / 20.0


# ---- per-pixel phase (eqs. 5-7, 15) ---------------------------------------------------------
def modulation_phasor(s0, s1, s2, mask_offset_a: float, noise_power: float = 0.0) -> np.ndarray:
    """z = [Re(S1 S0*) - a P] + i[Re(S2 S0*) - a P], P = |S0|² - N0: eq. 5's ψ_PW,0 is arg z.

    INO 3D patent, eq. 5 multiplied through by |S0|² (see the module docstring), with the noise
    power N0 of S0 removed from |S0|² (``noise_power``, 0: none); complex128.
    """
    s0 = np.asarray(s0, np.complex128)
    s1 = np.asarray(s1, np.complex128)
    s2 = np.asarray(s2, np.complex128)
    if not s0.shape == s1.shape == s2.shape:
        raise ValueError(f"S0, S1, S2 shapes differ: {s0.shape}, {s1.shape}, {s2.shape}")
    for name, s in (("S0", s0), ("S1", s1), ("S2", s2)):
        if not np.isfinite(s).all():
            raise ValueError(f"{name} holds NaN or Inf")
    c0 = np.conj(s0)
    power = (s0 * c0).real - noise_power
    return ((s1 * c0).real - mask_offset_a * power) + 1j * ((s2 * c0).real - mask_offset_a * power)


def wrapped_phase_rad(s0, s1, s2, mask_offset_a: float) -> np.ndarray:
    """ψ_PW,0 = arg[(S1/S0 - a) + i(S2/S0 - a)] per pixel (INO 3D patent, eq. 5), in (-π, π].

    Pixels with S0 = 0 have no phase and return 0 (``sam_height`` masks and counts them).
    """
    return np.angle(modulation_phasor(s0, s1, s2, mask_offset_a))


def flat_earth_phase_rad(range_m, geometry: ModulationGeometry) -> tuple[np.ndarray, np.ndarray]:
    """ψ_FE(R) = 2π arccos(H0/R) / P_φ + θ_mask (INO 3D patent, eq. 7; θ_mask = 0 there).

    Returns (phase wrapped to [-π, π), float64[range], valid): bins nearer than H0 see no ground
    and are invalid (phase 0).  Formed in cycles in float64 and reduced mod 1.
    """
    r = np.asarray(range_m, np.float64)
    valid = np.isfinite(r) & (r > geometry.platform_height_m)
    phi = np.arccos(geometry.platform_height_m / np.where(valid, r, np.inf))
    cycles = phi / geometry.angular_period_rad + geometry.mask_phase_rad / TWO_PI
    return np.where(valid, wrap(TWO_PI * np.mod(cycles, 1.0)), 0.0), valid


def flat_earth_from_reference(
    s0_ref,
    s1_ref,
    s2_ref,
    mask_offset_a: float,
    along_azimuth: bool = True,
    looks: tuple[int, int] = (1, 1),
    min_fraction: float = 1e-3,
    noise_power: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """ψ_FE from images of a flat reference target (INO 3D patent, eq. 15).

    The reference phasor z_ref (eq. 5 times |S0,ref|²) is averaged over the whole azimuth extent
    (``along_azimuth``: the flat-earth phase depends on range only for a straight track; result
    [1, range]) or over ``looks`` (result [azimuth, range]).  Bins whose averaged |z_ref| is
    below ``min_fraction`` of its 99th percentile (no reference return) are invalid, phase 0.
    ``noise_power``: N0 of S0,ref (see ``modulation_phasor``).  Returns (phase in (-π, π],
    valid), both broadcastable against the images.
    """
    z = modulation_phasor(s0_ref, s1_ref, s2_ref, mask_offset_a, noise_power)
    z = z.mean(axis=0, keepdims=True) if along_azimuth else box_mean(z, looks)
    mag = np.abs(z)
    scale = np.percentile(mag, 99) if mag.size else 0.0
    valid = mag > min_fraction * scale if scale > 0 else np.zeros(mag.shape, bool)
    return np.where(valid, np.angle(z), 0.0), valid


# ---- height (eqs. 9, 13) --------------------------------------------------------------------
def height_eq13_m(unwrapped_rad, geometry: ModulationGeometry) -> np.ndarray:
    """h ≈ (P_φ R0 sin φ0 / 2π) ψ_PU (INO 3D patent, eq. 13)."""
    return geometry.ambiguity_height_m / TWO_PI * np.asarray(unwrapped_rad, np.float64)


def height_exact_m(unwrapped_rad, range_m, geometry: ModulationGeometry) -> np.ndarray:
    """h = H0 - R cos φ with φ = arccos(H0/R) + P_φ ψ_PU / 2π (INO 3D patent, eqs. 8-9).

    Without the first-order steps of eqs. 10-12.  ``range_m`` broadcasts along the last axis;
    bins nearer than H0 give 0.
    """
    r = np.asarray(range_m, np.float64)
    ok = r > geometry.platform_height_m
    phi_flat = np.arccos(geometry.platform_height_m / np.where(ok, r, np.inf))
    phi = phi_flat + geometry.angular_period_rad * np.asarray(unwrapped_rad, np.float64) / TWO_PI
    return np.where(ok, geometry.platform_height_m - r * np.cos(phi), 0.0)


# ---- helpers --------------------------------------------------------------------------------


def anchor_cycles(unwrapped_rad, wrapped_rad, valid, reference_mask=None) -> np.ndarray:
    """Fix the constant left free by unwrapping, per connected region of valid pixels.

    First the offset that makes the region congruent with the wrapped phase on average (the
    circular mean of wrapped - unwrapped; zero for congruent unwrappers), then the 2π multiple
    that puts the median phase of the region's reference pixels (``reference_mask``: pixels
    known to lie on the reference plane; default all its pixels) in [-π, π): the flat-earth-
    corrected phase of the reference plane is zero (eq. 6).  Invalid pixels stay 0.
    """
    out = np.where(valid, np.asarray(unwrapped_rad, np.float64), 0.0)
    labels, count = ndimage.label(valid)
    for k in range(1, count + 1):
        region = labels == k
        offset = np.angle(np.exp(1j * (wrapped_rad[region] - out[region])).mean())
        out[region] += offset
        ref = region if reference_mask is None else region & reference_mask
        if not ref.any():
            ref = region
        cycles = np.floor(np.median(out[ref]) / TWO_PI + 0.5)
        out[region] -= TWO_PI * cycles
    return out


# ---- the whole chain ------------------------------------------------------------------------
def check_thresholds(dark_floor, min_coherence, noise_power) -> None:
    if not (math.isfinite(noise_power) and noise_power >= 0):
        raise ValueError("noise_power must be finite and >= 0")
    if dark_floor is not None and not (math.isfinite(dark_floor) and dark_floor >= 0):
        raise ValueError("dark_floor must be finite and >= 0")
    if not (math.isfinite(min_coherence) and 0 <= min_coherence <= 1):
        raise ValueError("min_coherence must lie in [0, 1]")


def classify(z_ml, power_ml, noise_power, fe_valid, depth_b, dark_floor, min_coherence):
    """Coherence γ and the masks (geometric, dark, incoherent, valid) of averaged pixels.

    Dark: signal power <|S0|²> - N0 at or below the floor.  Incoherent: γ = |<z>| / (|b|
    <|S0|²>) below ``min_coherence``, or above MAX_COHERENCE (returns alone give γ ≤ 1, since
    |Σ w_j b e^{iψ_j}| ≤ |b| Σ w_j; more is noise the N0 correction missed).
    """
    lit = power_ml - noise_power > dark_floor
    coherence = np.zeros(z_ml.shape)
    np.divide(np.abs(z_ml), abs(depth_b) * power_ml, out=coherence, where=lit)
    geometric = ~fe_valid
    dark = ~geometric & ~lit
    incoherent = ~geometric & lit & ((coherence < min_coherence) | (coherence > MAX_COHERENCE))
    valid = ~(geometric | dark | incoherent)
    return coherence, geometric, dark, incoherent, valid


def resolve_flat_earth(flat_earth, range_m, geometry):
    if isinstance(flat_earth, str):
        if flat_earth != "geometry":
            raise ValueError("flat_earth must be 'geometry' or a (phase, valid) pair")
        return flat_earth_phase_rad(range_m, geometry)
    phase, valid = (np.asarray(a) for a in flat_earth)
    if not np.isfinite(phase).all():
        raise ValueError("flat-earth phase holds NaN or Inf")
    return phase, valid.astype(bool)


@dataclass
class SamPhase:
    """Steps 1-3 of the module docstring; arrays image[azimuth, range], 0 where not ``valid``."""

    wrapped_rad: np.ndarray  # ψ_PW, flat-earth removed (eq. 6), from the averaged phasor
    coherence: np.ndarray  # modulation coherence γ
    valid: np.ndarray
    masked_dark: int  # S0 ≈ 0: averaged intensity at or below the floor
    masked_incoherent: int  # γ below min_coherence
    masked_geometry: int  # no flat-earth phase there (range < H0, no reference return)
    dark_floor: float  # the intensity floor used

    @property
    def masked(self) -> int:
        return self.masked_dark + self.masked_incoherent + self.masked_geometry


def sam_phase(
    s0,
    s1,
    s2,
    range_m,
    geometry: ModulationGeometry,
    flat_earth: str | tuple[np.ndarray, np.ndarray] = "geometry",
    looks: tuple[int, int] = (5, 3),
    dark_floor: float | None = None,
    dark_fraction: float = 0.01,
    min_coherence: float = 0.3,
    noise_power: float = 0.0,
) -> SamPhase:
    """Flat-earth-corrected wrapped phase, coherence and masks (INO 3D patent, eqs. 5-7, 15).

    flat_earth      "geometry" (eq. 7, from ``range_m`` and ``geometry``) or the (phase, valid)
                    pair of ``flat_earth_from_reference`` (eq. 15), broadcast to the images
    looks           (azimuth, range) window of the averaged phasor and intensity (odd sizes)
    dark_floor      absolute floor of the averaged signal power <|S0|²> - N0; None:
                    ``dark_fraction`` of its 99th percentile.  Pixels at or below it (S0 ≈ 0)
                    are masked and counted
    min_coherence   pixels whose modulation coherence γ is below it are masked and counted
    noise_power     N0, the noise power of a pixel of S0 (module docstring; 0: ignore noise)
    """
    check_thresholds(dark_floor, min_coherence, noise_power)
    if not (math.isfinite(dark_fraction) and dark_fraction >= 0):
        raise ValueError("dark_fraction must be finite and >= 0")
    z = modulation_phasor(s0, s1, s2, geometry.mask_offset_a, noise_power)
    if z.ndim != 2:
        raise ValueError(f"images must be 2-D [azimuth, range], got shape {z.shape}")
    range_m = np.asarray(range_m, np.float64)
    if range_m.shape != (z.shape[1],):
        raise ValueError(f"range_m must have {z.shape[1]} entries, got shape {range_m.shape}")
    fe_phase, fe_valid = resolve_flat_earth(flat_earth, range_m, geometry)
    fe_phase = np.broadcast_to(fe_phase, z.shape)
    fe_valid = np.broadcast_to(fe_valid, z.shape)
    sign_b = math.copysign(1.0, geometry.mask_depth_b)
    z_ml = box_mean(sign_b * z * np.exp(-1j * fe_phase), looks)  # eq. 6, on the phasor
    power_ml = box_mean(np.abs(np.asarray(s0, np.complex128)) ** 2, looks)
    if dark_floor is None:
        dark_floor = dark_fraction * float(np.percentile(power_ml - noise_power, 99))
    coherence, geometric, dark, incoherent, valid = classify(
        z_ml, power_ml, noise_power, fe_valid, geometry.mask_depth_b, dark_floor, min_coherence
    )
    return SamPhase(
        wrapped_rad=np.where(valid, np.angle(z_ml), 0.0),
        coherence=np.where(valid, coherence, 0.0),
        valid=valid,
        masked_dark=int(dark.sum()),
        masked_incoherent=int(incoherent.sum()),
        masked_geometry=int(geometric.sum()),
        dark_floor=float(dark_floor),
    )


@dataclass
class SamHeight:
    """Result of ``sam_height``: the phase step's fields plus the height map."""

    phase: SamPhase
    unwrapped_rad: np.ndarray  # ψ_PU (eq. 8), anchored; 0 where not valid
    height_m: np.ndarray  # h (eq. 13 or eq. 9); 0 where not valid
    unwrap_method: str
    elevation_resolution_m: float  # Δh, eq. 14
    ambiguity_height_m: float  # h_2π, [0047]

    @property
    def valid(self) -> np.ndarray:
        return self.phase.valid


def sam_height(
    s0,
    s1,
    s2,
    range_m,
    geometry: ModulationGeometry,
    unwrap_method: str = "mcf",
    height_model: str = "eq13",
    reference_mask: np.ndarray | None = None,
    **phase_options,
) -> SamHeight:
    """Height map h(x, R) from S0, S1, S2 (INO 3D patent, eqs. 5-13; module docstring).

    ``phase_options`` are the keywords of ``sam_phase`` (flat_earth, looks, dark_floor,
    dark_fraction, min_coherence, noise_power).  unwrap_method: "mcf", "ls" or "skimage"
    (rtsar.topo.unwrap), weighted by the coherence; reference_mask: pixels known to lie on the
    reference plane, for ``anchor_cycles``; height_model: "eq13" (patent eq. 13) or "exact"
    (eq. 9 with the unwrapped angle).  Masked pixels are 0 in every map, never NaN.
    """
    if height_model not in HEIGHT_MODELS:
        raise ValueError(f"height_model must be one of {HEIGHT_MODELS}, got {height_model!r}")
    ph = sam_phase(s0, s1, s2, range_m, geometry, **phase_options)
    unwrapped = unwrap_quality(ph.wrapped_rad, ph.valid, unwrap_method, ph.coherence)
    unwrapped = anchor_cycles(unwrapped, ph.wrapped_rad, ph.valid, reference_mask)
    if height_model == "eq13":
        height = height_eq13_m(unwrapped, geometry)
    else:
        height = height_exact_m(unwrapped, np.asarray(range_m, np.float64)[None, :], geometry)
    return SamHeight(
        phase=ph,
        unwrapped_rad=unwrapped,
        height_m=np.where(ph.valid, height, 0.0),
        unwrap_method=unwrap_method,
        elevation_resolution_m=geometry.elevation_resolution_m,
        ambiguity_height_m=geometry.ambiguity_height_m,
    )


# ---- in the stream ----------------------------------------------------------------------
