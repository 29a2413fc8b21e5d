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


# A spotlight collection (rtsar.spot.geometry) in rtsar's local frame, for the exports and their
# reader.  The spotlight frame is right-handed: x cross-range, y down-range (away from the
# station at θ = 0), z out of the collection plane, origin at the scene centre.  The local frame
# is x east, y south, z up with its origin on the ellipsoid.  The bench has no "up": the
# collection plane is placed through the local origin (the scene centre, the CPHD's SRP) with
# x east and y pointing north and down at SPOT_GRAZE_DEG (CPHD's schema needs an incidence
# below 90°, i.e. a station above the ground), so the station at θ = 0 sits south of the scene
# and above it.  A rotation: every distance, hence every path length, is kept.
SPOT_GRAZE_DEG = 30.0
_G = np.radians(SPOT_GRAZE_DEG)
SPOT_TO_LOCAL = np.array(  # rows: spotlight x, y, z in local (east, south, up) coordinates
    [[1.0, 0.0, 0.0], [0.0, -np.cos(_G), -np.sin(_G)], [0.0, -np.sin(_G), np.cos(_G)]]
)
SPOT_CHANNELS_PARAMETER = "rtsar:channels"  # ProductInfo: CPHD identifier → rtsar channel


def spot_to_local_m(points_m: np.ndarray) -> np.ndarray:
    """Spotlight-frame points or vectors [..., 3] → rtsar's local frame (x east, y south, z up)."""
    return np.asarray(points_m, np.float64) @ SPOT_TO_LOCAL


def spot_station_local(geometry, time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(positions, velocities) [pulse, 3] of the spotlight Tx/Rx station in the local frame:
    P_n = -R₀ (sin θ_n, cos θ_n, 0) (rtsar.spot.geometry) and its exact derivative along the arc,
    dθ/dt from the shots' times (constant: θ advances by step/R₀ each shot)."""
    pos = spot_to_local_m(geometry.station_m())
    t = np.asarray(time_s, np.float64)
    th = geometry.angles_rad()
    rate = geometry.step_rad * (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 else 0.0
    vel = -geometry.range_m * rate * np.stack([np.cos(th), -np.sin(th), 0 * th], -1)
    return pos, spot_to_local_m(vel)


def channel_config(cfg, reference_range_m: float):
    """``cfg`` with the dechirp reference (LO delay as a one-way range) and the range centre at
    ``reference_range_m``: the configuration of a receive channel with its own LO (the
    spotlight's bistatic receiver), whose range window is centred on that reference."""
    d = cfg.to_dict()
    d["waveform"]["reference_range_m"] = float(reference_range_m)
    d["processor"]["range_centre_m"] = float(reference_range_m)
    return config_from_dict(d)
