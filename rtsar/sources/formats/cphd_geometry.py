"""A processing configuration for a CPHD file that carries none (a collection made elsewhere).

The subset rtsar's geometry covers (rtsar.params.Geometry): an FX-domain channel with fixed
frequency sampling, and a straight track at a constant step, broadside of a scene reference
point.  rtsar's local frame is rebuilt from the PVPs: z along the ellipsoid normal at the middle
vector's SRP, x the horizontal direction of flight, y across towards the scene, origin below the
track so the platform flies at (x_p, 0, h) over the plane z = 0 through the SRP.

The FX vectors become shots of an FMCW (stretch) waveform with the same frequency samples:
rtsar's FMCW model (rtsar.sources.formats.phase_history) has sample n at f_n = f0 + K(t_n -
τ_ref), t_n = (n - S/2)/fs; taking fs = 1 Hz, K = SCSS, τ_ref = the SRP's delay and
f0 = SC0 + SCSS (S/2 + τ_ref) maps sample n to SC0 + n·SCSS exactly, and the FMCW lens (window +
DFT over frequency) is then range compression of the phase history (Crouch eqs. 3.4-3.7), with
the range window the file's TOA1…TOA2.  Azimuth: the antenna is unknown, so the CCD's aperture
gives square resolution, λR / (2 N d) = c / 2B (at most half the vectors; antenna length twice
the step), rectangular windows, the FFT correlator.
"""

from __future__ import annotations

import numpy as np

from ...lens.plan import next_pow2
from ...params import C_M_PER_S, config_from_dict
from .geometry import WGS84_A_M, WGS84_F

MAX_APERTURE_PULSES = 4096  # the CCD rtsar builds for a file without a configuration
STRAIGHT_FRACTION_OF_WAVELENGTH = 0.125  # largest deviation from a straight track (λ/8)


def _ellipsoid_up(ecf: np.ndarray) -> np.ndarray:
    b = WGS84_A_M * (1 - WGS84_F)
    n = ecf / np.array([WGS84_A_M**2, WGS84_A_M**2, b**2])
    return n / np.linalg.norm(n)


def local_axes(pvp) -> tuple[np.ndarray, np.ndarray]:
    """(origin ECF, axes [3, 3] as ECF rows x, y, z) of rtsar's frame for these PVPs."""
    arp = 0.5 * (np.asarray(pvp["TxPos"], float) + np.asarray(pvp["RcvPos"], float))
    mid = len(arp) // 2
    srp = np.asarray(pvp["SRPPos"][mid], float)
    z = _ellipsoid_up(srp)
    flight = arp[-1] - arp[0]
    x = flight - (flight @ z) * z
    if np.linalg.norm(x) == 0:
        raise ValueError("the platform does not move: no synthetic aperture")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    if (srp - arp[mid]) @ y < 0:  # the scene on the other side: a mirror frame keeps distances
        y = -y
    axes = np.array([x, y, z])
    rel = (arp - srp) @ axes.T
    origin = srp + np.mean(rel[:, 1]) * y  # below the track: platform at y = 0
    return origin, axes


def derived_config(pvp, num_samples: int):
    """(Config, along_track_m [vector], position_m [vector, 3]) of an FX-domain CPHD channel;
    ValueError naming what falls outside rtsar's geometry."""
    sc0, scss = np.asarray(pvp["SC0"], float), np.asarray(pvp["SCSS"], float)
    if len(sc0) < 2:
        raise ValueError("one vector: no synthetic aperture")
    if np.ptp(sc0) > 1e-6 * abs(sc0[0]) or np.ptp(scss) > 1e-9 * scss[0]:
        raise ValueError("SC0/SCSS change from vector to vector: rtsar needs fixed sampling")
    origin, axes = local_axes(pvp)
    arp = 0.5 * (np.asarray(pvp["TxPos"], float) + np.asarray(pvp["RcvPos"], float))
    local = (arp - origin) @ axes.T
    srp = (np.asarray(pvp["SRPPos"], float) - origin) @ axes.T
    s, f_step = int(num_samples), float(scss[0])
    tau_ref = 2.0 * float(np.median(np.linalg.norm(arp - np.asarray(pvp["SRPPos"]), axis=-1)))
    tau_ref /= C_M_PER_S
    f0 = float(sc0[0]) + f_step * (s / 2 + tau_ref)
    wavelength = C_M_PER_S / f0
    off_line = np.abs(local[:, 1:] - np.median(local[:, 1:], axis=0)).max()
    if off_line > STRAIGHT_FRACTION_OF_WAVELENGTH * wavelength:
        raise ValueError(
            f"the track leaves a straight line by {off_line:.3g} m (more than λ/8 = "
            f"{wavelength / 8:.3g} m): rtsar's geometry is a straight track"
        )
    step = np.diff(local[:, 0])
    if np.any(step <= 0):
        raise ValueError("the platform does not advance along track at every vector")
    step_m = float(np.mean(step))
    times = np.asarray(pvp["TxTime"], float)
    prf = float((len(times) - 1) / (times[-1] - times[0]))
    height = float(np.median(local[:, 2]))
    range_m = float(np.hypot(np.median(srp[:, 1]), height))
    nfft = next_pow2(s)
    toa = (np.asarray(pvp["TOA1"], float), np.asarray(pvp["TOA2"], float))
    span = float(np.max(toa[1]) - np.min(toa[0]))
    bins = int(min(max(8, round(span * nfft * f_step)), nfft - 2))
    # Square resolution: λR / (2 N d) = c / 2B (the antenna is unknown), at most half the track.
    range_resolution_m = C_M_PER_S / (2 * s * f_step)
    aperture = int(round(wavelength * range_m / (2 * step_m * range_resolution_m)))
    aperture = max(2, min(aperture, MAX_APERTURE_PULSES, len(times) // 2))
    cfg = config_from_dict(
        {
            "waveform": {
                "kind": "fmcw",
                "bandwidth_hz": s * f_step,
                "chirp_duration_s": float(s),
                "sample_rate_hz": 1.0,
                "reference_range_m": 0.5 * C_M_PER_S * tau_ref,
            },
            "geometry": {
                "wavelength_m": wavelength,
                "slant_range_m": range_m,
                "along_track_step_m": step_m,
                "prf_hz": prf,
                "antenna_length_m": 2 * step_m,
                "platform_height_m": height if 0 < height < range_m else 0.0,
            },
            "processor": {
                "aperture_pulses": aperture,
                "range_bins": bins,
                "range_window": "rect",
                "azimuth_window": "rect",
                "correlator": "fft",
            },
        }
    )
    return cfg, local[:, 0], local
