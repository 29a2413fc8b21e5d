"""Settings of the physical mode: the carrier, the CCD's well and bias, and opt-in named effects.

Every degradation is an effect that exists only when named (Psaltis & Wagner 1981, Table 1,
"limiting factors"); an effect that is not named is neither computed nor allocated.  A TOML table
(or a dict) reads into these frozen, self-validating dataclasses::

    [physical]
    carrier = "range"              # "range" (2 CCD columns per range cell) or "azimuth"
    full_well_e = 250000.0         # electrons a pixel holds
    bias_fraction = 0.5            # the bias frame fills this fraction of the well
    full_scale_amplitude = 1.0     # image amplitude whose swing fills the rest of the well
    seed = 0                       # seeds the noise and the fixed pattern
    [physical.ccd.shot_noise]      # CCD effects: shot_noise, read_noise, fixed_pattern,
    [physical.ccd.read_noise]      #   quantization, blooming
    sigma_e = 200.0
    [physical.ao.bandwidth]        # AO cell effects: bandwidth, time_aperture,
    bandwidth_hz = 40e6            #   diffraction_saturation, amplifier_noise
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import ClassVar

CARRIERS = ("range", "azimuth")


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise ValueError(msg)


def _finite(value, name: str, low: float | None = 0.0, strict: bool = True) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if ok and low is not None:
        ok = value > low if strict else value >= low
    bound = "" if low is None else (f" > {low:g}" if strict else f" >= {low:g}")
    _check(ok, f"{name} must be a finite number{bound}, got {value!r}")


# ---- CCD effects ------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShotNoise:
    """Poisson (quantum) noise of the collected charge, bias included (√125 000 ≈ 350 e-)."""

    name: ClassVar[str] = "shot_noise"


@dataclass(frozen=True)
class ReadNoise:
    """Dark and amplifier noise left after double-correlated sampling, per pixel read (e- rms)."""

    name: ClassVar[str] = "read_noise"
    sigma_e: float = 200.0

    def __post_init__(self):
        _finite(self.sigma_e, "read_noise.sigma_e", strict=False)


@dataclass(frozen=True)
class FixedPattern:
    """Pixel-to-pixel responsivity (gain_rms, fraction) and dark charge per exposure (e-).

    The pattern is drawn once from the settings' seed and does not change with time.
    """

    name: ClassVar[str] = "fixed_pattern"
    gain_rms: float = 0.01
    dark_e: float = 0.0
    dark_rms_e: float = 0.0

    def __post_init__(self):
        _finite(self.gain_rms, "fixed_pattern.gain_rms", strict=False)
        _check(self.gain_rms < 0.5, "fixed_pattern.gain_rms must be < 0.5")
        _finite(self.dark_e, "fixed_pattern.dark_e", strict=False)
        _finite(self.dark_rms_e, "fixed_pattern.dark_rms_e", strict=False)


@dataclass(frozen=True)
class Quantization:
    """ADC of ``bits`` bits over [0, full_scale_e] (None: the full well); codes clip at the ends."""

    name: ClassVar[str] = "quantization"
    bits: int = 12
    full_scale_e: float | None = None

    def __post_init__(self):
        _check(
            isinstance(self.bits, int) and not isinstance(self.bits, bool) and 1 <= self.bits <= 52,
            f"quantization.bits must be an integer in 1..52, got {self.bits!r}",
        )
        if self.full_scale_e is not None:
            _finite(self.full_scale_e, "quantization.full_scale_e")


@dataclass(frozen=True)
class Blooming:
    """Charge above the full well spills half into each neighbouring row of its column.

    Without this effect the excess is drained (an anti-blooming gate) and only counted.
    """

    name: ClassVar[str] = "blooming"


# ---- AO cell effects --------------------------------------------------------------------------
@dataclass(frozen=True)
class Bandwidth:
    """Transducer response: Gaussian in frequency, ``bandwidth_hz`` wide at -3 dB, at the centre."""

    name: ClassVar[str] = "bandwidth"
    bandwidth_hz: float = 40e6

    def __post_init__(self):
        _finite(self.bandwidth_hz, "bandwidth.bandwidth_hz")


@dataclass(frozen=True)
class TimeAperture:
    """The cell holds ``aperture_s`` of signal (centred in the shot); the acoustic wave loses
    ``attenuation_db`` from the transducer end to the far end."""

    name: ClassVar[str] = "time_aperture"
    aperture_s: float = 10e-6
    attenuation_db: float = 0.0

    def __post_init__(self):
        _finite(self.aperture_s, "time_aperture.aperture_s")
        _finite(self.attenuation_db, "time_aperture.attenuation_db", strict=False)


@dataclass(frozen=True)
class DiffractionSaturation:
    """Bragg diffraction: amplitude ∝ sin(π/2 · |s|/a_sat), linear only for |s| ≪ a_sat."""

    name: ClassVar[str] = "diffraction_saturation"
    saturation_amplitude: float = 1.0

    def __post_init__(self):
        _finite(self.saturation_amplitude, "diffraction_saturation.saturation_amplitude")


@dataclass(frozen=True)
class AmplifierNoise:
    """Thermal noise of the drive amplifier: circular complex Gaussian, ``rms`` per sample."""

    name: ClassVar[str] = "amplifier_noise"
    rms: float = 0.0

    def __post_init__(self):
        _finite(self.rms, "amplifier_noise.rms", strict=False)


CCD_EFFECTS = {c.name: c for c in (ShotNoise, ReadNoise, FixedPattern, Quantization, Blooming)}
AO_EFFECTS = {c.name: c for c in (Bandwidth, TimeAperture, DiffractionSaturation, AmplifierNoise)}
_TOP_KEYS = ("carrier", "full_well_e", "bias_fraction", "full_scale_amplitude", "seed")


def _effects(table, registry: dict, where: str) -> tuple:
    if table is None:
        return ()
    _check(isinstance(table, dict), f"{where} must be a table of effects")
    out = []
    for name, params in table.items():
        if name not in registry:
            raise ValueError(f"unknown {where} effect {name!r}; known: {sorted(registry)}")
        params = {} if params is None else params
        _check(isinstance(params, dict), f"{where}.{name} must be a table of parameters")
        cls = registry[name]
        known = {f.name for f in fields(cls)}
        unknown = set(params) - known
        _check(
            not unknown,
            f"{where}.{name}: unknown parameters {sorted(unknown)}; it takes {sorted(known)}",
        )
        out.append(cls(**params))
    return tuple(out)


@dataclass(frozen=True)
class PhysicalSettings:
    """The physical mode: carrier, well, bias, scale, seed and the named effects (opt-in).

    carrier               "range": each range cell uses 2 CCD columns (Table 1: range cells
                          halved); "azimuth": each pulse is exposed twice into 2 CCD rows
                          (azimuth samples doubled, so N rows integrate N/2 pulses)
    full_well_e           charge a pixel holds (250 000 e- in the paper's CCD)
    bias_fraction         the bias frame's share of the well (the paper: images on a bias,
                          half the well, "so the maximum signal is only 125 000 electrons")
    full_scale_amplitude  ideal-image amplitude whose charge swing equals the well above the
                          bias; the output is scaled back, so images match the ideal correlator
    ccd, ao               tuples of effect instances (CCD_EFFECTS, AO_EFFECTS); at most one each
    """

    carrier: str = "range"
    full_well_e: float = 250_000.0
    bias_fraction: float = 0.5
    full_scale_amplitude: float = 1.0
    seed: int = 0
    ccd: tuple = field(default=())
    ao: tuple = field(default=())

    def __post_init__(self):
        _check(
            self.carrier in CARRIERS,
            f"physical.carrier must be one of {CARRIERS}, got {self.carrier!r}",
        )
        _finite(self.full_well_e, "physical.full_well_e")
        _finite(self.bias_fraction, "physical.bias_fraction")
        _check(self.bias_fraction < 1.0, "physical.bias_fraction must be < 1")
        _finite(self.full_scale_amplitude, "physical.full_scale_amplitude")
        _check(
            isinstance(self.seed, int) and not isinstance(self.seed, bool) and self.seed >= 0,
            f"physical.seed must be an integer >= 0, got {self.seed!r}",
        )
        for group, registry in (("ccd", CCD_EFFECTS), ("ao", AO_EFFECTS)):
            items = getattr(self, group)
            _check(isinstance(items, tuple), f"physical.{group} must be a tuple of effects")
            names = [getattr(e, "name", None) for e in items]
            for e, n in zip(items, names, strict=True):
                _check(
                    n in registry and isinstance(e, registry[n]),
                    f"physical.{group}: {e!r} is not one of {sorted(registry)}",
                )
            _check(len(set(names)) == len(names), f"physical.{group}: an effect is named twice")

    def ccd_effect(self, name: str):
        """The CCD effect of that name, or None when it is not enabled."""
        return next((e for e in self.ccd if e.name == name), None)

    def ao_effect(self, name: str):
        """The AO-cell effect of that name, or None when it is not enabled."""
        return next((e for e in self.ao if e.name == name), None)

    def to_dict(self) -> dict:
        d = {k: getattr(self, k) for k in _TOP_KEYS}
        d["ccd"] = {e.name: asdict(e) for e in self.ccd}
        d["ao"] = {e.name: asdict(e) for e in self.ao}
        return d


def settings_from_dict(d: dict | None) -> PhysicalSettings:
    """Read a ``[physical]`` table (see the module docstring); unknown keys raise ValueError."""
    d = dict(d or {})
    unknown = set(d) - set(_TOP_KEYS) - {"ccd", "ao"}
    _check(not unknown, f"physical: unknown keys {sorted(unknown)}")
    top = {k: d[k] for k in _TOP_KEYS if k in d}
    return PhysicalSettings(
        **top,
        ccd=_effects(d.get("ccd"), CCD_EFFECTS, "physical.ccd"),
        ao=_effects(d.get("ao"), AO_EFFECTS, "physical.ao"),
    )


def paper_ccd(carrier: str = "range", seed: int = 0, adc_bits: int = 12) -> PhysicalSettings:
    """The experimental processor's detector (Psaltis & Wagner 1981, text after Table 1).

    Full well 250 000 e-, images on a bias at half the well, 200 e- after double-correlated
    sampling, quantum noise, blooming.  The ADC is not given in the paper: ``adc_bits`` (12 bits:
    61 e- per code, 18 e- rms of quantization noise) is an assumption of this emulation.
    """
    return PhysicalSettings(
        carrier=carrier,
        seed=seed,
        ccd=(ShotNoise(), ReadNoise(200.0), Quantization(adc_bits), Blooming()),
    )
