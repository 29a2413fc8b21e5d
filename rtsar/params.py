"""Frozen, self-validating parameter sets: waveform, strip-map geometry, processor; presets.

Conventions (used everywhere in rtsar)
--------------------------------------
* SI units; names carry the unit where it could be doubted (``prf_hz``, ``slant_range_m``).
* Complex baseband with carrier ``exp(+i 2π f0 t)``; a return from slant range R carries the
  two-way phase ``-4π R / λ`` with λ = c / f0 and f0 the *centre* frequency of the chirp (pulsed
  radar, after heterodyne and matched filter); FMCW lidar, after dechirp on receive against a
  local oscillator delayed to ``reference_range_m`` = R_ref, carries ``-4π (R - R_ref) / λ``
  (Crouch eq. 3.4: the delay counts from the LO path), a constant offset that focusing ignores.
* Array axes: ``echo[pulse, sample]``, ``line[pulse, range_bin]``, ``image[azimuth, range]``.
* Along-track: pulse ``p`` is taken at ``x_p = p * along_track_step_m`` (stop-and-hop).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace

from .fft_lengths import is_fast_fft_length

C_M_PER_S = 299_792_458.0

WINDOWS = ("rect", "hann", "hamming", "taylor")
PRECISIONS = ("complex64", "complex128")

# Size guards: a configuration beyond these is refused with its name and the limit, before any
# buffer is allocated (a typo of a few digits must not ask for tens of GiB).
MAX_SAMPLES_PER_SHOT = 1 << 22  # 4 Mi complex samples, 32 MiB per shot
MAX_APERTURE_PULSES = 1 << 16
MAX_RANGE_BINS = 1 << 16
MAX_MICRO_BATCH = 1 << 16
MAX_FFT_LENGTH = 1 << 20
MAX_RANGE_OVERSAMPLING = 64


def _positive(obj, *names):
    for name in names:
        value = getattr(obj, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(
                f"{type(obj).__name__}.{name} must be a finite number > 0, got {value!r}"
            )


def _shot_size(wf, duration_s: float) -> None:
    """The shot (``duration_s`` × sample_rate_hz samples) within MAX_SAMPLES_PER_SHOT, checked
    in floating point before any property rounds it to an int (1e308 × 1e308 is inf, which no
    int holds: a configuration file must not end in OverflowError)."""
    samples = wf.sample_rate_hz * duration_s
    if not samples <= MAX_SAMPLES_PER_SHOT:
        raise ValueError(
            f"{type(wf).__name__}: {samples:g} samples per shot (sample_rate_hz × duration) "
            f"exceed the limit of {MAX_SAMPLES_PER_SHOT}"
        )


@dataclass(frozen=True)
class PulsedChirp:
    """Pulsed linear-FM radar (Psaltis & Wagner 1981, eq. 1: s(t) = a(t) exp j(ω0 t + α t²)).

    The receive window is the acousto-optic cell's time aperture: the samples of one pulse that
    the AO cell holds at the instant the laser fires.  Range compression is a matched filter.
    """

    bandwidth_hz: float
    pulse_duration_s: float
    sample_rate_hz: float  # complex (I/Q) samples per second
    receive_window_s: float  # AO cell time aperture
    down_chirp: bool = False  # True: the frequency falls during the pulse (rate -B/T)
    # Two-way delay of the first sample of every shot, counted from the centre of the
    # transmitted pulse (an instrument's fixed receive window); None: the window is placed so
    # that its middle lag sits at the processor's range centre (the simulated presets).
    window_start_s: float | None = None
    kind: str = field(default="pulsed", init=False)

    def __post_init__(self):
        _positive(self, "bandwidth_hz", "pulse_duration_s", "sample_rate_hz", "receive_window_s")
        if not isinstance(self.down_chirp, bool):
            raise ValueError(
                f"PulsedChirp.down_chirp must be true or false, got {self.down_chirp!r}"
            )
        if self.window_start_s is not None:
            _positive(self, "window_start_s")
        _shot_size(self, max(self.receive_window_s, self.pulse_duration_s))
        if self.sample_rate_hz < self.bandwidth_hz:
            raise ValueError(
                f"sample_rate_hz {self.sample_rate_hz:g} < bandwidth_hz {self.bandwidth_hz:g}: "
                "complex sampling must cover the chirp bandwidth"
            )
        if self.pulse_samples >= self.samples_per_shot:
            raise ValueError("pulse_duration_s must be shorter than receive_window_s")

    @property
    def chirp_rate_hz_per_s(self) -> float:
        """K, signed: -B/T for a down-chirp."""
        rate = self.bandwidth_hz / self.pulse_duration_s
        return -rate if self.down_chirp else rate

    @property
    def samples_per_shot(self) -> int:
        return int(round(self.receive_window_s * self.sample_rate_hz))

    @property
    def pulse_samples(self) -> int:
        return int(round(self.pulse_duration_s * self.sample_rate_hz))

    @property
    def range_resolution_m(self) -> float:
        """c / 2B (Psaltis eq. 6)."""
        return C_M_PER_S / (2.0 * self.bandwidth_hz)


@dataclass(frozen=True)
class FMCWChirp:
    """FMCW chirp with dechirp on receive (Crouch 2012, ch. 3, eqs. 3.1-3.5).

    The local oscillator is delayed to ``reference_range_m`` so the beat frequency
    f = K (τ - τ_ref) spans only the range window: with complex sampling at ``sample_rate_hz`` the
    unambiguous range window is ``samples_per_shot`` cells of c/2B (stretch processing).
    """

    bandwidth_hz: float
    chirp_duration_s: float
    sample_rate_hz: float  # complex (I/Q) samples per second of the beat signal
    reference_range_m: float  # range matched by the LO delay
    kind: str = field(default="fmcw", init=False)

    def __post_init__(self):
        _positive(self, "bandwidth_hz", "chirp_duration_s", "sample_rate_hz", "reference_range_m")
        _shot_size(self, self.chirp_duration_s)
        if self.samples_per_shot < 8:
            raise ValueError(
                "FMCW shot must hold at least 8 samples (sample_rate_hz * chirp_duration_s)"
            )

    @property
    def chirp_rate_hz_per_s(self) -> float:
        return self.bandwidth_hz / self.chirp_duration_s

    @property
    def samples_per_shot(self) -> int:
        return int(round(self.chirp_duration_s * self.sample_rate_hz))

    @property
    def range_resolution_m(self) -> float:
        """c / 2B (Crouch eq. 3.6)."""
        return C_M_PER_S / (2.0 * self.bandwidth_hz)

    @property
    def unambiguous_range_m(self) -> float:
        """Range extent covered by the beat bandwidth fs: c fs / (2K)."""
        return C_M_PER_S * self.sample_rate_hz / (2.0 * self.chirp_rate_hz_per_s)


Waveform = PulsedChirp | FMCWChirp


@dataclass(frozen=True)
class Geometry:
    """Broadside strip-map geometry, straight track (Crouch Fig. 8; Psaltis Fig. 1).

    ``slant_range_m`` is the closest-approach range to the scene centre; ``antenna_length_m`` is
    the real aperture D along track, whose footprint λR/D is the illuminated length L (Crouch
    eq. 4.9).  ``platform_height_m`` is only needed for scatterers given in ground range.
    """

    wavelength_m: float
    slant_range_m: float
    along_track_step_m: float  # platform advance per pulse
    prf_hz: float
    antenna_length_m: float
    platform_height_m: float = 0.0
    # Absolute Doppler centroid f_dc (with its PRF ambiguity) of a squinted beam: the beam
    # centre sees a scatterer at sin θ = -λ f_dc / (2 V) off broadside (0: broadside).
    doppler_centroid_hz: float = 0.0

    def __post_init__(self):
        _positive(
            self,
            "wavelength_m",
            "slant_range_m",
            "along_track_step_m",
            "prf_hz",
            "antenna_length_m",
        )
        if not (
            math.isfinite(self.platform_height_m)
            and 0 <= self.platform_height_m < self.slant_range_m
        ):
            raise ValueError("platform_height_m must be in [0, slant_range_m)")
        f_dc = self.doppler_centroid_hz
        if not (isinstance(f_dc, (int, float)) and math.isfinite(f_dc)):
            raise ValueError(f"Geometry.doppler_centroid_hz must be finite, got {f_dc!r}")
        if abs(self.squint_sin) >= 0.5:
            raise ValueError(
                f"Geometry.doppler_centroid_hz {f_dc:g} means a squint of "
                f"{math.degrees(math.asin(min(1.0, abs(self.squint_sin)))):.0f}° or more "
                f"(|λ f_dc / 2V| = {abs(self.squint_sin):.3g} >= 0.5): not a strip-map beam"
            )

    @property
    def squint_sin(self) -> float:
        """sin θ of the beam's squint, -λ f_dc / (2 V): > 0 when the beam looks back (f_dc < 0)."""
        return -self.wavelength_m * self.doppler_centroid_hz / (2.0 * self.speed_mps)

    @property
    def squint_tan(self) -> float:
        s = self.squint_sin
        return s / math.sqrt(1.0 - s * s)

    @property
    def squinted(self) -> bool:
        return self.doppler_centroid_hz != 0.0

    def beam_centre_offset_m(self, slant_range_m):
        """Along-track offset u_c = R0 tan θ of the platform from a scatterer's closest approach
        when the beam centre crosses it (R0 the closest-approach range; 0 at broadside)."""
        return slant_range_m * self.squint_tan

    def squint_range_excess_m(self, slant_range_m):
        """R_c - R0 = R0 (1/cos θ - 1): how much further than closest approach the beam centre
        sees a scatterer (formed without cancellation as R0 tan²θ / (1/cos θ + 1))."""
        t = self.squint_tan
        return slant_range_m * t * t / (math.sqrt(1.0 + t * t) + 1.0)

    @property
    def speed_mps(self) -> float:
        return self.along_track_step_m * self.prf_hz

    @property
    def carrier_hz(self) -> float:
        return C_M_PER_S / self.wavelength_m

    @property
    def illuminated_length_m(self) -> float:
        """Real-aperture footprint L = λR/D (Crouch eq. 4.9)."""
        return self.wavelength_m * self.slant_range_m / self.antenna_length_m


@dataclass(frozen=True)
class Processor:
    """Processor settings: the CCD size, windows, micro-batch and correlator mode.

    aperture_pulses   N, rows of the shifting CCD (synthetic aperture in pulses)
    range_bins        columns of the CCD (range cells kept after the AO lens)
    range_centre_m    slant range of the middle column (None: the geometry's scene centre)
    range_oversampling  FFT zero-padding factor of the lens (power of two)
    range_window, azimuth_window   one of WINDOWS ("taylor": n̄ = 4, -35 dB)
    per_bin_mask      True: mask chirp rate per range bin (Psaltis eq. 5, k1/y0); False: one mask
    correlator        one of CORRELATORS: "direct" (shift register, numba: one line per pulse,
                      N multiply-adds per pixel per line), "fft" (overlap-save blocks of
                      M - N + 1 lines: fastest, latency ~N pulses) or "partitioned"
                      (partitioned overlap-save: lines leave in blocks of partition_lines)
                      or "nonuniform" (non-uniformly partitioned: a head block of
                      partition_lines, tail blocks up to tail_block_lines in the partition of
                      least modelled cost; the partitioned latency at fewer multiply-adds)
    fft_length        FFT correlator transform length M (>= N, a product of 2, 3 and 5; None:
                      2N to a power of two); blocks of M - N + 1 lines: "fft"'s latency knob
    partition_lines   L, the block of the "partitioned" correlator: a power of two, at most N
                      (checked when that correlator is chosen).  A line leaves at most L - 1
                      pulses after its last pulse, plus one block's compute time; each line
                      costs 2N/L complex multiply-adds per pixel and its share of two 2L-point
                      transforms, so halving L halves the wait and doubles the multiply-adds.
                      16 at 10 kHz PRF: ≤ 1.5 ms wait, 64 multiply-adds per pixel (N = 512)
    tail_block_lines  the largest block of the "nonuniform" correlator's tail (a power of two;
                      the block sizes up to it and their partitions are chosen by a cost model,
                      rtsar.ccd.nonuniform.plan_segments): 2·(partitions) multiply-adds per
                      pixel and line instead of 2N/L (N = 512, L = 16, 128: 8 partitions of 16
                      and 6 of 64, 28 instead of 64) for one more pair of transforms per block
                      size
    micro_batch       pulses per AO-lens launch
    precision         one of PRECISIONS: the sample type of the AO lens and the CCD.
                      "complex64" (default): float32 arithmetic, the real-time setting, within
                      1e-5 relative RMS of float64 in every stage (measured 5e-8 to 8e-7);
                      "complex128": float64 end to end (the OpenCL lens needs a device with
                      cl_khr_fp64; ~1.8x the lens time on PoCL), for accuracy references
    range_migration_taps  T, range-cell-migration correction (Psaltis & Wagner eq. 3 with a
                      two-dimensional mask, rtsar.migration): 0 = off, every aperture row reads
                      the target's closest-approach bin (crouch-sal: 0.23-cell range bias,
                      azimuth IRW 1.022 x theory); T >= 1: row k reads the line at its migrated
                      range through T taps across range bins (1 nearest, 2 linear, >= 3
                      Lanczos a = T/2).  Use range_oversampling >= 2 with it: critically sampled
                      lines interpolate badly (crouch-sal, T = 4: bias 0.04 cell but IRW
                      1.054 x at oversampling 1; 0.001 cell and 1.001 x at 2).  Cost: T plus
                      the migration span in bins range offsets; "fft" shares its transforms
                      (2.3-2.7x the time at 5 offsets), "direct"/"partitioned" run one
                      correlator per offset (~5x)
    range_migration_domain  where the taps read: "time" (exact 2-D mask, ccd.migration),
                      "doppler" ("fft" only: a T-tap read per azimuth frequency of each block,
                      ccd.doppler_migration) or "walk" ("nonuniform" only: pulses shifted by
                      the linear walk into a turning ring, curvature left out, ccd.walk_deskew)
    """

    CORRELATORS = ("direct", "fft", "partitioned", "nonuniform")  # a constant, not a field
    MIGRATION_DOMAINS = ("time", "doppler", "walk")  # a constant, not a field

    aperture_pulses: int
    range_bins: int
    range_centre_m: float | None = None
    range_oversampling: int = 1
    range_window: str = "rect"
    azimuth_window: str = "rect"
    per_bin_mask: bool = True
    correlator: str = "fft"
    fft_length: int | None = None
    partition_lines: int = 16
    tail_block_lines: int = 128
    micro_batch: int = 64
    precision: str = "complex64"
    range_migration_taps: int = 0
    range_migration_domain: str = "time"

    def __post_init__(self):
        for name in ("aperture_pulses", "range_bins", "range_oversampling", "micro_batch"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise ValueError(f"Processor.{name} must be an integer >= 1, got {value!r}")
        if self.aperture_pulses < 2:
            raise ValueError("Processor.aperture_pulses must be >= 2")
        for name, most in (
            ("aperture_pulses", MAX_APERTURE_PULSES),
            ("range_bins", MAX_RANGE_BINS),
            ("micro_batch", MAX_MICRO_BATCH),
            ("range_oversampling", MAX_RANGE_OVERSAMPLING),
        ):
            if getattr(self, name) > most:
                raise ValueError(f"Processor.{name} = {getattr(self, name)} exceeds {most}")
        if self.fft_length is not None and (
            not isinstance(self.fft_length, int) or self.fft_length > MAX_FFT_LENGTH
        ):
            raise ValueError(
                f"Processor.fft_length must be an integer <= {MAX_FFT_LENGTH}, got "
                f"{self.fft_length!r}"
            )
        if self.range_oversampling & (self.range_oversampling - 1):
            raise ValueError("Processor.range_oversampling must be a power of two")
        for name in ("range_window", "azimuth_window"):
            if getattr(self, name) not in WINDOWS:
                raise ValueError(
                    f"Processor.{name} must be one of {WINDOWS}, got {getattr(self, name)!r}"
                )
        if self.correlator not in self.CORRELATORS:
            raise ValueError(
                f"Processor.correlator must be one of {self.CORRELATORS}, got {self.correlator!r}"
            )
        lines = self.partition_lines
        if not (isinstance(lines, int) and lines >= 1 and not lines & (lines - 1)):
            raise ValueError(f"Processor.partition_lines must be a power of two, got {lines!r}")
        tail = self.tail_block_lines
        if not (isinstance(tail, int) and tail >= 1 and not tail & (tail - 1)):
            raise ValueError(f"Processor.tail_block_lines must be a power of two, got {tail!r}")
        if self.correlator in ("partitioned", "nonuniform") and lines > self.aperture_pulses:
            raise ValueError(
                f"Processor.partition_lines {lines} exceeds aperture_pulses {self.aperture_pulses}"
            )
        m = self.fft_length
        if m is not None and not (m >= self.aperture_pulses and is_fast_fft_length(m)):
            why = "must be >= aperture_pulses and a product of 2, 3 and 5 (1000, 1024, 1080, …)"
            raise ValueError(f"Processor.fft_length {why}, got {m}")
        if self.precision not in PRECISIONS:
            raise ValueError(
                f"Processor.precision must be one of {PRECISIONS}, got {self.precision!r}"
            )
        taps = self.range_migration_taps
        if not (isinstance(taps, int) and not isinstance(taps, bool) and 0 <= taps <= 64):
            raise ValueError(
                f"Processor.range_migration_taps must be an integer in 0..64 (0: off), got {taps!r}"
            )
        if self.range_migration_domain not in self.MIGRATION_DOMAINS:
            raise ValueError(
                f"Processor.range_migration_domain must be one of {self.MIGRATION_DOMAINS}, "
                f"got {self.range_migration_domain!r}"
            )
        needs = {"doppler": "fft", "walk": "nonuniform"}.get(domain := self.range_migration_domain)
        if needs not in (None, self.correlator):
            raise ValueError(
                f"Processor.range_migration_domain = {domain!r} needs correlator = {needs!r} "
                f"(the taps' read is that correlator's), got {self.correlator!r}"
            )
        if self.range_centre_m is not None and not (
            math.isfinite(self.range_centre_m) and self.range_centre_m > 0
        ):
            raise ValueError("Processor.range_centre_m must be > 0")


@dataclass(frozen=True)
class Config:
    """Everything the simulator and the processor need, validated as a whole."""

    waveform: Waveform
    geometry: Geometry
    processor: Processor

    def __post_init__(self):
        g, p = self.geometry, self.processor
        # The mask chirp must be sampled: across the aperture the Doppler frequency of the
        # azimuth history, f(u) = 2 V u / (λ sqrt(R² + u²)) at platform offset u, may change by
        # less than the PRF (broadside: the phase advances by less than π per pulse at the
        # aperture's edge, 4π/λ · d · (A/2)/R < π).  A squinted beam's centroid f_dc may lie
        # many PRFs away: only the spread about it must fit.
        half_aperture_m = 0.5 * p.aperture_pulses * g.along_track_step_m
        centre_m = p.range_centre_m or g.slant_range_m
        u_mid = g.beam_centre_offset_m(centre_m)

        def doppler_cycles_per_pulse(u):
            return (
                2.0 * g.along_track_step_m * u / (g.wavelength_m * math.hypot(g.slant_range_m, u))
            )

        spread = doppler_cycles_per_pulse(u_mid + half_aperture_m) - doppler_cycles_per_pulse(
            u_mid - half_aperture_m
        )
        phase_step = math.pi * spread
        if phase_step >= math.pi:
            raise ValueError(
                f"azimuth chirp aliased: phase advances {phase_step:.2f} rad per pulse at the "
                f"edge of the {p.aperture_pulses}-pulse aperture (limit π); shorten the aperture "
                "or the step"
            )
        if g.squinted and not p.range_migration_taps:
            # the echo walks λ|f_dc|/2 m/s; over the aperture that exceeds a quarter cell
            walk_m = abs(g.squint_sin) * p.aperture_pulses * g.along_track_step_m
            if walk_m > 0.25 * self.waveform.range_resolution_m:
                raise ValueError(
                    f"a Doppler centroid of {g.doppler_centroid_hz:g} Hz walks the echo "
                    f"{walk_m:.3g} m across the aperture: set range_migration_taps "
                    "(--range-migration-taps, e.g. 16) so that the CCD's rows follow it"
                )
        if isinstance(self.waveform, FMCWChirp):
            if self.waveform.reference_range_m <= 0:
                raise ValueError("FMCW reference_range_m must be > 0")

    # ---- derived quantities used by theory tables ---------------------------------------
    @property
    def synthetic_aperture_m(self) -> float:
        return self.processor.aperture_pulses * self.geometry.along_track_step_m

    def azimuth_resolution_m(self, slant_range_m: float | None = None) -> float:
        """λR/(2L) with L the synthetic aperture (Crouch eq. 4.8), unweighted."""
        r = self.geometry.slant_range_m if slant_range_m is None else slant_range_m
        return self.geometry.wavelength_m * r / (2.0 * self.synthetic_aperture_m)

    @property
    def range_curvature_m(self) -> float:
        """Range migration across the aperture, sqrt(R² + (A/2)²) - R."""
        r = self.geometry.slant_range_m
        return math.hypot(r, 0.5 * self.synthetic_aperture_m) - r

    def to_dict(self) -> dict:
        d = {
            "waveform": asdict(self.waveform),
            "geometry": asdict(self.geometry),
            "processor": asdict(self.processor),
        }
        return d

    def with_processor(self, **changes) -> Config:
        return replace(self, processor=replace(self.processor, **changes))


def _build(cls, section: str, d) -> object:
    """``cls(**d)`` with ValueError naming the section for a missing or unknown key."""
    if not isinstance(d, dict):
        raise ValueError(f"{section} must be a table of settings, got {type(d).__name__}")
    names = {f.name for f in fields(cls) if f.init}
    unknown = sorted(set(d) - names)
    if unknown:
        raise ValueError(f"unknown key(s) {unknown} in {section} (known: {sorted(names)})")
    try:
        return cls(**d)
    except TypeError as exc:  # a missing key
        raise ValueError(f"{section}: {exc}") from None


def waveform_from_dict(d: dict) -> Waveform:
    if not isinstance(d, dict):
        raise ValueError(f"waveform must be a table of settings, got {type(d).__name__}")
    d = dict(d)
    kind = d.pop("kind", None)
    if kind == "pulsed":
        return _build(PulsedChirp, "waveform (pulsed)", d)
    if kind == "fmcw":
        return _build(FMCWChirp, "waveform (fmcw)", d)
    raise ValueError(f"waveform.kind must be 'pulsed' or 'fmcw', got {kind!r}")


def config_from_dict(d: dict) -> Config:
    """Inverse of Config.to_dict; ValueError naming the key for anything else."""
    if not isinstance(d, dict):
        raise ValueError(f"a configuration is a table of settings, got {type(d).__name__}")
    missing = [k for k in ("waveform", "geometry", "processor") if k not in d]
    unknown = sorted(set(d) - {"waveform", "geometry", "processor"})
    if missing or unknown:
        raise ValueError(f"configuration: missing {missing}, unknown {unknown}")
    return Config(
        waveform_from_dict(d["waveform"]),
        _build(Geometry, "geometry", d["geometry"]),
        _build(Processor, "processor", d["processor"]),
    )
