"""Export a recording as a CPHD 1.0.1 file (NGA.STND.0068-1, Compensated Phase History Data).

Written with sarkit's CPHD writer (the NGA reference implementation); rtsar supplies only the
mapping.  One channel, FX domain (Global/SGN = -1): each shot becomes one signal vector by the
exact, invertible transform of rtsar.sources.formats.phase_history (pulsed: range compressed in
the frequency domain by a phase-only matched filter; FMCW: the dechirped samples), referenced to
a scene reference point (SRP) on the swath's centre line, broadside of the platform (per-vector
SRPPos).  Per-vector parameters: every one CPHD 1.0.1 requires (TxTime, TxPos, TxVel, RcvTime,
RcvPos, RcvVel, SRPPos, aFDOP, aFRR1, aFRR2, FX1, FX2, TOA1, TOA2, TDTropoSRP, SC0, SCSS) from
the recording's telemetry (``position_m`` where recorded, else the configuration's straight
track; stop-and-hop as in rtsar's signal model: RcvPos = TxPos), plus the added PVP
``rtsar_pulse_index``.  ReferenceGeometry is computed by sarkit from the PVPs.  The recording's
configuration and scene travel in ProductInfo parameters ``rtsar:config`` / ``rtsar:scene`` so
that rtsar reads the file back into the very same shots (rtsar.sources.formats.cphd_reader).
Auxiliary channels are not exported (they are not phase histories of the scene).
"""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import numpy as np

from ... import __version__
from ...params import C_M_PER_S
from ...sources.formats.cphd_reader import srp_delay_s
from ...sources.formats.geometry import LocalFrame, platform_height_m, platform_positions_m
from ...sources.formats.phase_history import fx_mapping, shots_to_fx
from ...sources.formats.requirements import require_formats
from ..io import replace_when_complete

try:
    import lxml.etree as etree
    import sarkit.cphd as skcphd
    import sarkit.wgs84 as skwgs84
except ImportError:  # the optional extra "formats": the CLI says how to install it
    skcphd = None

CPHD_NS = "http://api.nsgreg.nga.mil/schema/cphd/1.0.1"
CHANNEL = "rtsar-main"
# (name, words of 8 bytes, format): the PVP layout, in the order CPHD 1.0.1 lists them.
PVP_LAYOUT = [
    ("TxTime", 1, "F8"),
    ("TxPos", 3, "X=F8;Y=F8;Z=F8;"),
    ("TxVel", 3, "X=F8;Y=F8;Z=F8;"),
    ("RcvTime", 1, "F8"),
    ("RcvPos", 3, "X=F8;Y=F8;Z=F8;"),
    ("RcvVel", 3, "X=F8;Y=F8;Z=F8;"),
    ("SRPPos", 3, "X=F8;Y=F8;Z=F8;"),
    ("aFDOP", 1, "F8"),
    ("aFRR1", 1, "F8"),
    ("aFRR2", 1, "F8"),
    ("FX1", 1, "F8"),
    ("FX2", 1, "F8"),
    ("TOA1", 1, "F8"),
    ("TOA2", 1, "F8"),
    ("TDTropoSRP", 1, "F8"),
    ("SC0", 1, "F8"),
    ("SCSS", 1, "F8"),
]
ADDED_PVP = ("rtsar_pulse_index", 1, "I8")


def collection_geometry(rec, frame: LocalFrame) -> dict:
    """Per-pulse platform positions and velocities (local frame) of a recording, and the scene
    reference point (SRP): on the swath's centre line (slant range R_c at closest approach),
    abeam of the middle of the image."""
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
    x_c = 0.5 * (x_first + x_last)
    y_c = float(np.sqrt(r_c**2 - h**2))
    srp = np.array([x_c, y_c, 0.0])
    return {
        "pos": pos,
        "vel": vel,
        "srp": srp,
        "height_m": h,
        "range_centre_m": r_c,
        "x_first": x_first,
        "x_last": x_last,
    }


def _pvps(rec, m, g: dict, frame: LocalFrame, dtype, dtau: np.ndarray) -> np.ndarray:
    pv = np.zeros(rec.pulses, dtype)
    tx = np.asarray(rec.time_s, np.float64)
    pos, vel, srp = frame.to_ecf(g["pos"]), frame.vectors_to_ecf(g["vel"]), frame.to_ecf(g["srp"])
    pv["TxPos"] = pv["RcvPos"] = pos
    pv["TxVel"] = pv["RcvVel"] = vel
    pv["SRPPos"] = srp
    r = np.linalg.norm(pv["TxPos"] - pv["SRPPos"], axis=-1)
    pv["TxTime"], pv["RcvTime"] = tx, tx + 2.0 * r / C_M_PER_S
    unit = (pos - srp) / r[:, None]
    pv["aFDOP"] = -2.0 / C_M_PER_S * np.sum(vel * unit, axis=-1)  # CPHD 1.0.1 §6.3: -2 Ṙ/c
    wf = rec.config.waveform
    afrr2 = 2.0 / (C_M_PER_S * wf.chirp_rate_hz_per_s)
    pv["aFRR2"], pv["aFRR1"] = afrr2, m.fxc_hz * afrr2
    pv["FX1"], pv["FX2"] = m.fx1_hz, m.fx2_hz
    pv["TOA1"], pv["TOA2"] = m.toa1_s - dtau, m.toa2_s - dtau  # the range window, per vector
    pv["TDTropoSRP"] = 0.0
    pv["SC0"], pv["SCSS"] = m.sc0_hz, m.scss_hz
    pv[ADDED_PVP[0]] = np.asarray(rec.pulse_index, np.int64)
    return pv


def build_xml(rec, m, g: dict, frame: LocalFrame, core_name: str, dtau: np.ndarray):
    """The CPHD XML (without ReferenceGeometry) of a recording."""
    cfg = rec.config
    geo, proc = cfg.geometry, cfg.processor
    root = etree.Element(f"{{{CPHD_NS}}}CPHD", nsmap={None: CPHD_NS})
    ew = skcphd.ElementWrapper(root)
    tx = np.asarray(rec.time_s, np.float64)
    start = datetime.datetime(2000, 1, 1)  # rtsar's times are relative: an arbitrary epoch
    ew["CollectionID"] = {
        "CollectorName": "rtsar",
        "CoreName": core_name,
        "CollectType": "MONOSTATIC",
        "RadarMode": {"ModeType": "STRIPMAP"},
        "Classification": "UNCLASSIFIED",
        "ReleaseInfo": "UNRESTRICTED",
    }
    toa1, toa2 = m.toa1_s - dtau, m.toa2_s - dtau  # per vector: the SRP's delay varies
    tau_span = (float(toa1.min()), float(toa2.max()))
    ew["Global"] = {
        "DomainType": "FX",
        "SGN": -1,
        "Timeline": {
            "CollectionStart": start,
            "TxTime1": float(tx[0]),
            "TxTime2": float(tx[-1]),
        },
        "FxBand": {"FxMin": m.fx1_hz, "FxMax": m.fx2_hz},
        "TOASwath": {"TOAMin": tau_span[0], "TOAMax": tau_span[1]},
    }
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
    ew["SceneCoordinates"] = {
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
    words = sum(w for _, w, _ in PVP_LAYOUT) + ADDED_PVP[1]
    ew["Data"] = {
        "SignalArrayFormat": "CF8",
        "NumBytesPVP": 8 * words,
        "NumCPHDChannels": 1,
        "Channel": [
            {
                "Identifier": CHANNEL,
                "NumVectors": rec.pulses,
                "NumSamples": m.num_samples,
                "SignalArrayByteOffset": 0,
                "PVPArrayByteOffset": 0,
            }
        ],
        "NumSupportArrays": 0,
    }
    ew["Channel"] = {
        "RefChId": CHANNEL,
        "FXFixedCPHD": True,
        "TOAFixedCPHD": rec.pulses == 1,
        "SRPFixedCPHD": True,
        "Parameters": [
            {
                "Identifier": CHANNEL,
                "RefVectorIndex": rec.pulses // 2,
                "FXFixed": True,
                "TOAFixed": rec.pulses == 1,
                "SRPFixed": True,
                "Polarization": {"TxPol": "UNSPECIFIED", "RcvPol": "UNSPECIFIED"},
                "FxC": m.fxc_hz,
                "FxBW": m.fx2_hz - m.fx1_hz,
                "TOASaved": tau_span[1] - tau_span[0],
                "DwellTimes": {"CODId": "cod", "DwellId": "dwell"},
            }
        ],
    }
    offset, pvp = 0, {}
    for name, size, fmt in PVP_LAYOUT:
        pvp[name] = {
            "Offset": offset,
            "Size": size,
            "dtype": skcphd.binary_format_string_to_dtype(fmt),
        }
        offset += size
    ew["PVP"] = pvp
    ew["PVP"]["AddedPVP"] = [
        {
            "Name": ADDED_PVP[0],
            "Offset": offset,
            "Size": ADDED_PVP[1],
            "dtype": skcphd.binary_format_string_to_dtype(ADDED_PVP[2]),
        }
    ]
    # Centre of aperture of an image point at IAX: when the platform is abeam of it (+ the
    # SRP's one-way delay, the reference time of sarkit's t_ref); the dwell spans the aperture.
    speed = geo.speed_mps
    t_abeam = float(tx[0]) + (x_c - rec.start_along_track_m) / speed + m.srp_range_m / C_M_PER_S
    ew["Dwell"] = {
        "NumCODTimes": 1,
        "CODTime": [{"Identifier": "cod", "CODTimePoly": np.array([[t_abeam], [1.0 / speed]])}],
        "NumDwellTimes": 1,
        "DwellTime": [{"Identifier": "dwell", "DwellTimePoly": np.array([[(n - 1) / geo.prf_hz]])}],
    }
    info = etree.SubElement(root, f"{{{CPHD_NS}}}ProductInfo")
    creation = etree.SubElement(info, f"{{{CPHD_NS}}}CreationInfo")
    etree.SubElement(creation, f"{{{CPHD_NS}}}Application").text = f"rtsar {__version__}"
    etree.SubElement(creation, f"{{{CPHD_NS}}}DateTime").text = datetime.datetime.now(
        datetime.timezone.utc
    ).strftime("%Y-%m-%dT%H:%M:%SZ")
    for name, value in (
        ("rtsar:config", json.dumps(cfg.to_dict())),
        ("rtsar:scene", json.dumps(rec.scene or {})),
        ("rtsar:start_along_track_m", repr(float(rec.start_along_track_m))),
        ("rtsar:origin_lat_lon_deg", f"{frame.lat_deg!r},{frame.lon_deg!r}"),
    ):
        etree.SubElement(info, f"{{{CPHD_NS}}}Parameter", name=name).text = value
    return etree.ElementTree(root)


def write_cphd(rec, path: str | Path, frame: LocalFrame | None = None) -> dict:
    """Write recording ``rec`` (rtsar.sinks.io.Recording) as CPHD 1.0.1 to ``path``; returns
    a summary (vectors, samples, domain)."""
    require_formats(skcphd, "CPHD export")
    frame = frame or LocalFrame()
    if rec.pulses < 1:
        raise ValueError(f"{rec.path}: no shots to export")
    m = fx_mapping(rec.config)
    g = collection_geometry(rec, frame)
    pos = frame.to_ecf(g["pos"])
    dtau = srp_delay_s(  # as the reader will compute it from the stored PVPs
        {"TxPos": pos, "RcvPos": pos, "SRPPos": frame.to_ecf(g["srp"])[None, :]}, m.srp_range_m
    )
    tree = build_xml(rec, m, g, frame, Path(path).stem, dtau)
    pvps = _pvps(rec, m, g, frame, skcphd.get_pvp_dtype(tree), dtau)
    if not np.array_equal(srp_delay_s(pvps, m.srp_range_m), dtau):
        raise RuntimeError("CPHD export: the stored PVPs do not reproduce the SRP delays")
    root = tree.getroot()
    root.append(skcphd.compute_reference_geometry(tree, pvps))
    # ReferenceGeometry's place in the schema's sequence: before SupportArray/…/ProductInfo.
    info = root.find(f"{{{CPHD_NS}}}ProductInfo")
    root.remove(info)
    root.append(info)
    signal = np.empty((rec.pulses, m.num_samples), np.complex64)
    for i in range(0, rec.pulses, 1024):
        signal[i : i + 1024] = shots_to_fx(m, rec.shots[i : i + 1024], dtau[i : i + 1024])
    meta = skcphd.Metadata(xmltree=tree)
    # Written beside ``path`` and renamed when complete: a run that dies leaves no partial CPHD.
    with replace_when_complete(path) as tmp, open(tmp, "wb") as f, skcphd.Writer(f, meta) as w:
        w.write_signal(CHANNEL, signal)
        w.write_pvp(CHANNEL, pvps)
    return {"vectors": rec.pulses, "samples": m.num_samples, "domain": "FX"}
