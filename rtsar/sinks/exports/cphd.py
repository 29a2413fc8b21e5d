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
``rtsar_pulse_index``.  ReferenceGeometry is computed by sarkit from the PVPs; TxRcv holds the
chirp (pulse length, bandwidth, rate) and the receiver (window, sample rate, LO sweep), each
channel naming both; Global/Timeline/CollectionStart is the recording's collection start
(rtsar.sources.formats.timebase; UNKNOWN_EPOCH where the recording kept none, and ProductInfo
``rtsar:collection_start_utc`` then says "unknown").  The geometry of the collection is
rtsar.sinks.exports.cphd_collection's.  The recording's
configuration and scene travel in ProductInfo parameters ``rtsar:config`` / ``rtsar:scene`` so
that rtsar reads the file back into the very same shots (rtsar.sources.formats.cphd_reader).
A strip-map recording's auxiliary channels (interferometric receivers, reference
interferometers) are left out, and the summary names them (the .h5 and the SigMF export keep
them).

A spotlight recording (rtsar.spot, Crouch ch. 9) is written on its own geometry: RadarMode
SPOTLIGHT, the SRP fixed at the scene centre, TxPos = RcvPos = the station on its arc
P_n = -R₀(sin θ_n, cos θ_n, 0) per vector (rtsar.sources.formats.cphd_geometry places the
collection plane through the scene centre at the local origin, tilted 30° so that the station
is above ground), so |TxPos - SRP| = R₀ at
every vector; the fixed bistatic receiver, when recorded, is a second CPHD channel
``rtsar-bistatic`` with TxPos on the arc, RcvPos = B and its own LO delay (ProductInfo
``rtsar:channels`` maps identifiers to rtsar channels and their LO ranges).
"""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import numpy as np

from ... import __version__
from ...params import C_M_PER_S
from ...sources.formats.cphd_geometry import SPOT_CHANNELS_PARAMETER
from ...sources.formats.cphd_reader import spot_geometry_of, srp_delay_s
from ...sources.formats.geometry import LocalFrame
from ...sources.formats.phase_history import shots_to_fx
from ...sources.formats.requirements import require_formats
from ...sources.formats.timebase import UNKNOWN_EPOCH, format_utc
from ..io import replace_when_complete
from .cphd_collection import ExportChannel, spot_collection, strip_collection
from .screen import require_full_aperture, require_increasing_times, zero_nonfinite

try:
    import lxml.etree as etree
    import sarkit.cphd as skcphd
except ImportError:  # the optional extra "formats": the CLI says how to install it
    skcphd = None

CPHD_NS = "http://api.nsgreg.nga.mil/schema/cphd/1.0.1"
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
TX_WAVEFORM, RECEIVER = "rtsar-chirp", "rtsar-receiver"  # TxRcv identifiers
TOA_ROUNDING = 1e-9  # SRP-delay spreads below this fraction of the TOA window: rounding


def _pvps(rec, ch: ExportChannel, frame: LocalFrame, dtype, dtau: np.ndarray) -> np.ndarray:
    m = ch.mapping
    pv = np.zeros(rec.pulses, dtype)
    tx = np.asarray(rec.time_s, np.float64)
    srp = frame.to_ecf(ch.srp_m)
    pv["TxPos"], pv["RcvPos"] = frame.to_ecf(ch.tx_m), frame.to_ecf(ch.rcv_m)
    pv["TxVel"], pv["RcvVel"] = frame.vectors_to_ecf(ch.tx_vel), frame.vectors_to_ecf(ch.rcv_vel)
    pv["SRPPos"] = srp
    r_tx = np.linalg.norm(pv["TxPos"] - srp, axis=-1)
    r_rcv = np.linalg.norm(pv["RcvPos"] - srp, axis=-1)
    pv["TxTime"], pv["RcvTime"] = tx, tx + (r_tx + r_rcv) / C_M_PER_S
    u_tx = (pv["TxPos"] - srp) / r_tx[:, None]
    u_rcv = (pv["RcvPos"] - srp) / r_rcv[:, None]
    # CPHD 1.0.1 §6.3: aFDOP = -(Ṙ_tx + Ṙ_rcv)/c (monostatic: -2 Ṙ/c)
    pv["aFDOP"] = -(np.sum(pv["TxVel"] * u_tx, -1) + np.sum(pv["RcvVel"] * u_rcv, -1)) / C_M_PER_S
    wf = rec.config.waveform
    afrr2 = 2.0 / (C_M_PER_S * wf.chirp_rate_hz_per_s)
    pv["aFRR2"], pv["aFRR1"] = afrr2, m.fxc_hz * afrr2
    pv["FX1"], pv["FX2"] = m.fx1_hz, m.fx2_hz
    pv["TOA1"], pv["TOA2"] = toa_window_s(m, dtau)  # the range window, per vector
    pv["TDTropoSRP"] = 0.0
    pv["SC0"], pv["SCSS"] = m.sc0_hz, m.scss_hz
    pv[ADDED_PVP[0]] = np.asarray(rec.pulse_index, np.int64)
    return pv


def toa_window_s(m, dtau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(TOA1, TOA2) per vector: the processor's range window relative to each vector's SRP
    delay (τ_c + ``dtau``).  A strip map's SRP keeps its range, so ``dtau`` is 0 but for the
    rounding of ECF positions (~1e-17 s); a spread below TOA_ROUNDING of the window is written
    as the reference vector's exact value, so TOA1/TOA2 are exactly constant (TOAFixed) where
    they are meant to be; the signal's phase still uses each vector's own ``dtau``."""
    dtau = np.asarray(dtau, np.float64)
    if dtau.size and np.ptp(dtau) <= TOA_ROUNDING * (m.toa2_s - m.toa1_s):
        dtau = np.full(dtau.shape, dtau[dtau.size // 2])
    return m.toa1_s - dtau, m.toa2_s - dtau


def _fixed(arrays) -> bool:
    """Whether every row of every array equals the first array's first row (exact equality:
    what CPHD's *Fixed flags declare and the consistency checkers test)."""
    first = np.asarray(arrays[0])[0]
    return all(bool(np.all(np.asarray(a) == first)) for a in arrays)


def tx_rcv(cfg) -> dict:
    """CPHD TxRcv: the transmitted chirp and the receiver.  Pulsed: a pulse of Tp, the AO
    window's length, a fixed LO at the carrier (no LFMRate: CPHD's is a stretch receiver's,
    never 0); FMCW: the sweep of T, a dechirp
    receiver whose LO sweeps at the chirp rate over the same T.  The receiver's band is its
    complex sample rate (IFFilterBW: rtsar models no narrower filter).  Polarisation is not
    modelled: UNSPECIFIED."""
    wf, f0 = cfg.waveform, cfg.geometry.carrier_hz
    fmcw = wf.kind == "fmcw"
    length = wf.chirp_duration_s if fmcw else wf.pulse_duration_s
    return {
        "NumTxWFs": 1,
        "TxWFParameters": [
            {
                "Identifier": TX_WAVEFORM,
                "PulseLength": length,
                "RFBandwidth": wf.bandwidth_hz,
                "FreqCenter": f0,
                "LFMRate": wf.chirp_rate_hz_per_s,
                "Polarization": "UNSPECIFIED",
            }
        ],
        "NumRcvs": 1,
        "RcvParameters": [
            {
                "Identifier": RECEIVER,
                "WindowLength": length if fmcw else wf.receive_window_s,
                "SampleRate": wf.sample_rate_hz,
                "IFFilterBW": wf.sample_rate_hz,
                "FreqCenter": f0,
                **({"LFMRate": wf.chirp_rate_hz_per_s} if fmcw else {}),
                "Polarization": "UNSPECIFIED",
            }
        ],
    }


def build_xml(rec, chans, scene: dict, dwell, mode: str, frame, core_name: str, dtaus):
    """The CPHD XML (without ReferenceGeometry) of a recording's channels."""
    cfg = rec.config
    root = etree.Element(f"{{{CPHD_NS}}}CPHD", nsmap={None: CPHD_NS})
    ew = skcphd.ElementWrapper(root)
    tx = np.asarray(rec.time_s, np.float64)
    start = getattr(rec, "collection_start", None)  # (None: not kept; UNKNOWN_EPOCH written)
    ew["CollectionID"] = {
        "CollectorName": "rtsar",
        "CoreName": core_name,
        "CollectType": "MONOSTATIC",  # the reference channel's; a bistatic one has its PVPs
        "RadarMode": {"ModeType": mode},
        "Classification": "UNCLASSIFIED",
        "ReleaseInfo": "UNRESTRICTED",
    }
    # per vector: the SRP's delay varies
    spans = [toa_window_s(c.mapping, d) for c, d in zip(chans, dtaus, strict=True)]
    # Each *Fixed flag from the values written (exact equality), per channel and for the file.
    srps = [np.broadcast_to(frame.to_ecf(c.srp_m), (rec.pulses, 3)) for c in chans]
    fxs = [np.array([[c.mapping.fx1_hz, c.mapping.fx2_hz]]) for c in chans]
    toas = [np.stack(span, axis=-1) for span in spans]
    tau_span = (min(float(a.min()) for a, _ in spans), max(float(b.max()) for _, b in spans))
    fx_lo = min(c.mapping.fx1_hz for c in chans)
    fx_hi = max(c.mapping.fx2_hz for c in chans)
    ew["Global"] = {
        "DomainType": "FX",
        "SGN": -1,
        "Timeline": {
            "CollectionStart": start or UNKNOWN_EPOCH,
            "TxTime1": float(tx[0]),
            "TxTime2": float(tx[-1]),
        },
        "FxBand": {"FxMin": fx_lo, "FxMax": fx_hi},
        "TOASwath": {"TOAMin": tau_span[0], "TOAMax": tau_span[1]},
    }
    ew["SceneCoordinates"] = scene
    words = sum(w for _, w, _ in PVP_LAYOUT) + ADDED_PVP[1]
    ew["Data"] = {
        "SignalArrayFormat": "CF8",
        "NumBytesPVP": 8 * words,
        "NumCPHDChannels": len(chans),
        "Channel": [
            {
                "Identifier": c.identifier,
                "NumVectors": rec.pulses,
                "NumSamples": c.mapping.num_samples,
                "SignalArrayByteOffset": sum(
                    rec.pulses * b.mapping.num_samples * 8 for b in chans[:i]
                ),
                "PVPArrayByteOffset": i * rec.pulses * 8 * words,
            }
            for i, c in enumerate(chans)
        ],
        "NumSupportArrays": 0,
    }
    ew["Channel"] = {
        "RefChId": chans[0].identifier,
        "FXFixedCPHD": _fixed(fxs),
        "TOAFixedCPHD": _fixed(toas),
        "SRPFixedCPHD": _fixed(srps),
        "Parameters": [
            {
                "Identifier": c.identifier,
                "RefVectorIndex": rec.pulses // 2,
                "FXFixed": True,  # FX1/FX2: the chirp band, the same for every vector
                "TOAFixed": _fixed([toa]),
                "SRPFixed": _fixed([srp]),
                "Polarization": {"TxPol": "UNSPECIFIED", "RcvPol": "UNSPECIFIED"},
                "FxC": c.mapping.fxc_hz,
                "FxBW": c.mapping.fx2_hz - c.mapping.fx1_hz,
                "TOASaved": float(b.max() - a.min()),
                "DwellTimes": {"CODId": "cod", "DwellId": "dwell"},
                "TxRcv": {"TxWFId": [TX_WAVEFORM], "RcvId": [RECEIVER]},
            }
            for c, (a, b), toa, srp in zip(chans, spans, toas, srps, strict=True)
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
    ew["Dwell"] = {
        "NumCODTimes": 1,
        "CODTime": [{"Identifier": "cod", "CODTimePoly": dwell[0]}],
        "NumDwellTimes": 1,
        "DwellTime": [{"Identifier": "dwell", "DwellTimePoly": dwell[1]}],
    }
    ew["TxRcv"] = tx_rcv(cfg)
    info = etree.SubElement(root, f"{{{CPHD_NS}}}ProductInfo")
    creation = etree.SubElement(info, f"{{{CPHD_NS}}}CreationInfo")
    etree.SubElement(creation, f"{{{CPHD_NS}}}Application").text = f"rtsar {__version__}"
    etree.SubElement(creation, f"{{{CPHD_NS}}}DateTime").text = datetime.datetime.now(
        datetime.timezone.utc
    ).strftime("%Y-%m-%dT%H:%M:%SZ")
    channels = {
        c.identifier: {"name": c.name, "reference_range_m": c.reference_range_m} for c in chans
    }
    for name, value in (
        ("rtsar:config", json.dumps(cfg.to_dict())),
        ("rtsar:scene", json.dumps(rec.scene or {})),
        ("rtsar:start_along_track_m", repr(float(rec.start_along_track_m))),
        ("rtsar:origin_lat_lon_deg", f"{frame.lat_deg!r},{frame.lon_deg!r}"),
        ("rtsar:heading_deg", repr(float(frame.heading_deg))),
        ("rtsar:collection_start_utc", "unknown" if start is None else format_utc(start)),
        (SPOT_CHANNELS_PARAMETER, json.dumps(channels)),
    ):
        etree.SubElement(info, f"{{{CPHD_NS}}}Parameter", name=name).text = value
    return etree.ElementTree(root)


def write_cphd(rec, path: str | Path, frame: LocalFrame | None = None) -> dict:
    """Write recording ``rec`` (rtsar.sinks.io.Recording) as CPHD 1.0.1 to ``path``; returns
    a summary (vectors, samples, domain, channels written, auxiliary channels left out, and
    ``nonfinite``: channel → shots that held NaN/Inf, written as zeros).  Refused (ValueError,
    one line) where the file would break CPHD's own rules: shot times that do not increase
    (TxTime), a strip map with no full-aperture line (an image area of no extent)."""
    require_formats(skcphd, "CPHD export")
    frame = frame or LocalFrame()
    if rec.config.geometry.squinted:  # its scene point and dwell would be placed abeam
        raise ValueError(
            f"{rec.path} is squinted (Doppler centroid {rec.config.geometry.doppler_centroid_hz:g}"
            " Hz): CPHD export of squinted recordings is not supported yet (the scene, image "
            "area and dwell times would be placed abeam); SigMF keeps the shots as they are, "
            "and its focused image exports as SICD (rtsar process, then export --sicd)"
        )
    if rec.pulses < 1:
        raise ValueError(f"{rec.path}: no shots to export")
    require_increasing_times(rec, "CPHD (TxTime, vector by vector)")
    spot = spot_geometry_of(rec.scene, rec.path)
    if spot is not None:
        chans, scene, dwell, mode, left_out = spot_collection(rec, spot, frame)
    else:
        require_full_aperture(rec, rec.config.processor.aperture_pulses, "CPHD")
        chans, scene, dwell, mode, left_out = strip_collection(rec, frame)
    dtaus = [c.dtau_s(frame) for c in chans]
    tree = build_xml(rec, chans, scene, dwell, mode, frame, Path(path).stem, dtaus)
    dtype = skcphd.get_pvp_dtype(tree)
    pvps = [_pvps(rec, c, frame, dtype, d) for c, d in zip(chans, dtaus, strict=True)]
    for c, p, d in zip(chans, pvps, dtaus, strict=True):
        if not np.array_equal(srp_delay_s(p, c.mapping.srp_range_m), d):
            raise RuntimeError("CPHD export: the stored PVPs do not reproduce the SRP delays")
    root = tree.getroot()
    # ReferenceGeometry's place in the schema's sequence: after Dwell, before TxRcv/ProductInfo.
    root.find(f"{{{CPHD_NS}}}Dwell").addnext(skcphd.compute_reference_geometry(tree, pvps[0]))
    meta = skcphd.Metadata(xmltree=tree)
    nonfinite = {}
    # Written beside ``path`` and renamed when complete: a run that dies leaves no partial CPHD.
    with replace_when_complete(path) as tmp, open(tmp, "wb") as f, skcphd.Writer(f, meta) as w:
        for c, p, d in zip(chans, pvps, dtaus, strict=True):
            m = c.mapping
            signal = np.empty((rec.pulses, m.num_samples), np.complex64)
            nonfinite[c.name] = 0
            for i in range(0, rec.pulses, 1024):
                shots, bad = zero_nonfinite(np.asarray(c.shots[i : i + 1024], np.complex64))
                nonfinite[c.name] += bad
                signal[i : i + 1024] = shots_to_fx(m, shots, d[i : i + 1024])
            w.write_signal(c.identifier, signal)
            w.write_pvp(c.identifier, p)
    return {
        "vectors": rec.pulses,
        "samples": chans[0].mapping.num_samples,
        "domain": "FX",
        "mode": mode.lower(),
        "channels": [c.name for c in chans],
        "left_out": left_out,
        "nonfinite": {name: n for name, n in nonfinite.items() if n},
    }
