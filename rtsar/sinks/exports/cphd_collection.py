"""The collection a CPHD export describes: per-vector geometry, channels and scene.

A strip-map recording: the platform's positions (``position_m`` where recorded, else the
configuration's straight track) and, for every vector, a scene reference point (SRP) on the
swath's centre line abeam of the platform, so the SRP follows the track as generic CPHD readers
expect of a strip map (one fixed SRP made FastSAR take the file for a spotlight collection and
use 131 of its 400 vectors); the scene a plane at the image's centre with rtsar's image grid.
A spotlight recording (rtsar.spot): the station on its arc and the SRP fixed at the scene
centre, the bistatic receiver a second channel (rtsar.sinks.exports.cphd).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...params import C_M_PER_S
from ...sources.formats.cphd_geometry import channel_config, spot_station_local, spot_to_local_m
from ...sources.formats.cphd_reader import srp_delay_s
from ...sources.formats.geometry import LocalFrame, platform_height_m, platform_positions_m
from ...sources.formats.phase_history import FxMapping, fx_mapping
from ...spot.pfa import PolarFormatPlan

try:
    import sarkit.wgs84 as skwgs84
except ImportError:  # the optional extra "formats": rtsar.sinks.exports.cphd says so
    skwgs84 = None

CHANNEL = "rtsar-main"


def collection_geometry(rec, frame: LocalFrame) -> dict:
    """Per-pulse platform positions and velocities (local frame) of a recording, and the scene
    reference point (SRP) of each pulse: on the swath's centre line (slant range R_c at closest
    approach), abeam of the platform."""
    cfg = rec.config
    geo = cfg.geometry
    r_c = cfg.processor.range_centre_m or geo.slant_range_m
    along = rec.start_along_track_m + geo.along_track_step_m * np.arange(rec.pulses)
    h = platform_height_m(r_c, geo.platform_height_m)
    pos = platform_positions_m(along, h, rec.position_m)
    if rec.pulses > 1:
        vel = np.gradient(pos, np.asarray(rec.time_s, np.float64), axis=0)
    else:
        vel = np.array([[geo.speed_mps, 0.0, 0.0]])
    if np.any(pos[:, 2] >= r_c):
        raise ValueError("the platform is higher than the centre range: no ground to image")
    n = cfg.processor.aperture_pulses
    x_first = rec.start_along_track_m + 0.5 * (n - 1) * geo.along_track_step_m
    x_last = rec.start_along_track_m + (rec.pulses - 1 - 0.5 * (n - 1)) * geo.along_track_step_m
    y_c = float(np.sqrt(r_c**2 - h**2))
    # The SRP follows the track: on the centre line, abeam of the platform at every vector (a
    # strip map; one fixed SRP would make the file read as a spotlight collection).
    srp = np.stack([pos[:, 0], np.full(len(pos), y_c), np.zeros(len(pos))], axis=-1)
    return {
        "pos": pos,
        "vel": vel,
        "srp": srp,
        "height_m": h,
        "range_centre_m": r_c,
        "x_first": x_first,
        "x_last": x_last,
    }


@dataclass(frozen=True, eq=False)
class ExportChannel:
    """One CPHD channel: its rtsar channel, shots, FX mapping and per-vector geometry (local)."""

    identifier: str
    name: str  # "main" or the recording's auxiliary channel
    shots: object  # [pulse, sample] array-like that slices into blocks
    mapping: FxMapping
    tx_m: np.ndarray  # [pulse, 3]
    tx_vel: np.ndarray
    rcv_m: np.ndarray
    rcv_vel: np.ndarray
    srp_m: np.ndarray  # [3] (fixed: a spotlight) or [pulse, 3] (following a strip map)
    reference_range_m: float | None  # the channel's LO delay as a one-way range (FMCW)

    def dtau_s(self, frame: LocalFrame) -> np.ndarray:
        """Each vector's SRP delay minus τ_c, from the ECF positions the PVPs will hold."""
        pv = {
            "TxPos": frame.to_ecf(self.tx_m),
            "RcvPos": frame.to_ecf(self.rcv_m),
            "SRPPos": np.atleast_2d(frame.to_ecf(self.srp_m)),
        }
        return srp_delay_s(pv, self.mapping.srp_range_m)


def strip_collection(rec, frame: LocalFrame):
    """(channels, SceneCoordinates, Dwell, mode, left out) of a strip-map recording."""
    g = collection_geometry(rec, frame)
    m = fx_mapping(rec.config)
    ch = ExportChannel(
        CHANNEL,
        "main",
        rec.shots,
        m,
        g["pos"],
        g["vel"],
        g["pos"],
        g["vel"],
        g["srp"],
        getattr(rec.config.waveform, "reference_range_m", None),  # pulsed: no LO
    )
    scene, dwell = _strip_scene(rec, m, g, frame)
    return [ch], scene, dwell, "STRIPMAP", sorted(rec.channels)


def spot_collection(rec, geometry, frame: LocalFrame):
    """(channels, SceneCoordinates, Dwell, mode, left out) of a spotlight recording: the main
    channel on the arc and, when recorded, the bistatic receiver as its own channel."""
    cfg = rec.config
    if rec.pulses != geometry.pulses:
        raise ValueError(
            f"{rec.path}: {rec.pulses} shots recorded, the spotlight geometry plans "
            f"{geometry.pulses}"
        )
    time_s = np.asarray(rec.time_s, np.float64)
    pos, vel = spot_station_local(geometry, time_s)
    srp = np.zeros(3)
    wf = cfg.waveform
    main_ref = geometry.lo_range_m(wf, "main")
    chans = [
        ExportChannel(
            CHANNEL, "main", rec.shots, fx_mapping(cfg), pos, vel, pos, vel, srp, main_ref
        )
    ]
    left_out = []
    for name in sorted(rec.channels):
        if name != "bistatic" or not geometry.bistatic:
            left_out.append(name)
            continue
        lo = geometry.lo_range_m(wf, name)
        rcv = np.broadcast_to(spot_to_local_m(geometry.receiver_m()), pos.shape)
        chans.append(
            ExportChannel(
                f"rtsar-{name}",
                name,
                rec.channels[name],
                fx_mapping(channel_config(cfg, lo)),
                pos,
                vel,
                np.array(rcv),
                np.zeros_like(vel),
                srp,
                lo,
            )
        )
    # The image area: a square about the SRP enclosing the default PFA image (rtsar.spot.pfa).
    plan = PolarFormatPlan(cfg, geometry)
    half = float(np.hypot(np.abs(plan.x_m).max(), np.abs(plan.y_m).max()))
    corners = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0]])
    corners = np.vstack([corners, [[-half, -half, 0.0]]])  # clockwise seen from above
    scene = {
        "EarthModel": "WGS_84",
        "IARP": {
            "ECF": frame.to_ecf(srp),
            "LLH": skwgs84.cartesian_to_geodetic(frame.to_ecf(srp)),
        },
        # The collection plane: IAX = spotlight x (cross-range, east), IAY = spotlight y
        # (down-range), so image coordinates are the spotlight frame's.
        "ReferenceSurface": {
            "Planar": {
                "uIAX": frame.vectors_to_ecf(spot_to_local_m([1.0, 0.0, 0.0])),
                "uIAY": frame.vectors_to_ecf(spot_to_local_m([0.0, 1.0, 0.0])),
            }
        },
        "ImageArea": {"X1Y1": [-half, -half], "X2Y2": [half, half]},
        "ImageAreaCornerPoints": skwgs84.cartesian_to_geodetic(
            frame.to_ecf(spot_to_local_m(corners))
        )[:, :2],
    }
    # Every image point is seen over the whole collection: one COD time (mid-collection, +
    # the SRP's one-way delay as for the strip map) and one dwell, the collection's length.
    t_cod = 0.5 * (time_s[0] + time_s[-1]) + geometry.range_m / C_M_PER_S
    dwell = (np.array([[t_cod]]), np.array([[float(time_s[-1] - time_s[0])]]))
    return chans, scene, dwell, "SPOTLIGHT", left_out


def _strip_scene(rec, m, g: dict, frame: LocalFrame):
    """SceneCoordinates and (COD, dwell) polynomials of a strip-map recording."""
    geo, proc = rec.config.geometry, rec.config.processor
    tx = np.asarray(rec.time_s, np.float64)
    # Scene: a plane at the image's centre; IAX along track, IAY north (away from the platform:
    # IAX × IAY is up), so a scene point at cross-track y has IAY = -(y - y_c).
    n = proc.aperture_pulses
    step = geo.along_track_step_m
    x_first = rec.start_along_track_m + 0.5 * (n - 1) * step  # first and last image line
    x_last = rec.start_along_track_m + (rec.pulses - 1 - 0.5 * (n - 1)) * step
    h = g["height_m"]
    ground = np.sqrt(
        np.maximum(
            np.array([m.srp_range_m + 0.5 * C_M_PER_S * t for t in (m.toa1_s, m.toa2_s)]) ** 2
            - h**2,
            0.0,
        )
    )
    y_c = float(np.sqrt(m.srp_range_m**2 - h**2))
    x_c = 0.5 * (x_first + x_last)
    iarp = frame.to_ecf([x_c, y_c, 0.0])
    lines, bins = max(rec.pulses - n + 1, 1), proc.range_bins  # rtsar's image: lines × bins
    spacing = float(ground[1] - ground[0]) / max(bins - 1, 1)
    corners_local = [  # clockwise seen from above (east, south, up is a mirror image)
        [x_first, ground[1], 0.0],
        [x_first, ground[0], 0.0],
        [x_last, ground[0], 0.0],
        [x_last, ground[1], 0.0],
    ]
    corners_llh = skwgs84.cartesian_to_geodetic(frame.to_ecf(np.array(corners_local)))
    scene = {
        "EarthModel": "WGS_84",
        "IARP": {"ECF": iarp, "LLH": skwgs84.cartesian_to_geodetic(iarp)},
        "ReferenceSurface": {
            "Planar": {"uIAX": frame.axes[0], "uIAY": -frame.axes[1]},
        },
        "ImageArea": {
            "X1Y1": [x_first - x_c, y_c - ground[1]],
            "X2Y2": [x_last - x_c, y_c - ground[0]],
        },
        "ImageAreaCornerPoints": corners_llh[:, :2],
        "ImageGrid": {
            "Identifier": "rtsar-image",
            "IARPLocation": [0.5 * (lines - 1), (ground[1] - y_c) / spacing],
            "IAXExtent": {"LineSpacing": step, "FirstLine": 0, "NumLines": lines},
            "IAYExtent": {"SampleSpacing": spacing, "FirstSample": 0, "NumSamples": bins},
        },
    }
    # Centre of aperture of an image point at IAX: when the platform is abeam of it (+ the
    # SRP's one-way delay, the reference time of sarkit's t_ref); the dwell spans the aperture.
    speed = geo.speed_mps
    t_abeam = float(tx[0]) + (x_c - rec.start_along_track_m) / speed + m.srp_range_m / C_M_PER_S
    return scene, (np.array([[t_abeam], [1.0 / speed]]), np.array([[(n - 1) / geo.prf_hz]]))
