"""Export an rtsar image as SICD (NGA.STND.0024, Sensor Independent Complex Data) in NITF:
the metadata from sarpy's SICD model (it derives the dependent fields: SCPCOA, GeoData corners,
…), the file from sarkit's NITF writer (NGA's reference implementation).

The mapping: SICD rows are slant range, columns along track (Grid/Type RGZERO, ImagePlane
SLANT), so the pixel array is ``image.T`` (complex64, RE32F_IM32F); Row/SS the range bin
spacing, Col/SS the line spacing; the impulse responses are the processor's
(rtsar.sinks.exports.resolution): bandwidths 2B/c (range) and 2Nd/(λR) (azimuth: the CCD's
aperture of N pulses, Crouch eq. 4.8), widened by the configuration's windows, which are named
and tabulated as applied (WgtFunct, the width derived from it); the scene centre pixel is the
SCP, the whole image is valid data (ImageData/ValidData) and its footprint on the ground the
collection area (RadarCollection/Area).  Geometry: rtsar's straight track in its local frame
placed on WGS-84 as in rtsar.sources.formats.geometry (ARPPoly linear in time; a slant-plane
image gets the default platform height), Timeline with one IPP set at the PRF, ImageFormation
(range-Doppler RMA, INCA: closest approach at the column's along-track position),
RadarCollection (carrier, chirp, and the receiver: a pulsed radar's is CHIRP demodulation
(RcvFMRate 0), an FMCW dechirp STRETCH (RcvFMRate the chirp rate); window length and sample
rate).  Timeline/CollectStart is the image's ``collection_start_utc`` (the recording's), else an
arbitrary epoch, 2000-01-01.  Polarisation is UNKNOWN (rtsar does not model it).
"""

from __future__ import annotations

import datetime
import logging
import math
from pathlib import Path

import numpy as np

from ... import __version__
from ...ccd.base import beam_look_back_m, squint_cos_less_one
from ...params import C_M_PER_S
from ...sources.formats.geometry import LocalFrame, platform_height_m
from ...sources.formats.requirements import require_formats
from ...sources.formats.timebase import UNKNOWN_EPOCH, parse_utc
from ..image_file import image_config, read_image
from ..io import replace_when_complete
from .resolution import Resolution, azimuth_resolution, range_resolution

try:
    import lxml.etree as etree
    import sarkit.sicd as sksicd
    from sarpy.geometry.geocoords import ecf_to_geodetic
    from sarpy.io.complex.sicd_elements.SICD import SICDType
except ImportError:  # the optional extra "formats"
    SICDType = None


def sicd_structure(
    image_shape,
    azimuth_m,
    range_m,
    cfg,
    frame: LocalFrame,
    core_name: str,
    collection_start: datetime.datetime | None = None,
    azimuth_irw=None,
):
    """The SICD metadata (sarpy SICDType, derived) of an image [azimuth, range];
    ``collection_start`` (UTC) is the time of the recording's pulse 0 (None: unknown);
    ``azimuth_irw(cfg, range_m)``, where given, the azimuth -3 dB width to declare (the
    correlator's response to the scene's antenna beam: rtsar.analysis.azimuth_response),
    else the processor's weighted band alone (resolution.py)."""
    geo, wf, proc = cfg.geometry, cfg.waveform, cfg.processor
    naz, nrg = image_shape
    speed = geo.speed_mps
    d_az = float(azimuth_m[1] - azimuth_m[0]) if naz > 1 else geo.along_track_step_m
    d_rg = float(range_m[1] - range_m[0]) if nrg > 1 else wf.range_resolution_m
    scp_row, scp_col = nrg // 2, naz // 2  # SICD row = range, column = azimuth
    r_scp, x_scp = float(range_m[scp_row]), float(azimuth_m[scp_col])
    h = platform_height_m(cfg.processor.range_centre_m or geo.slant_range_m, geo.platform_height_m)
    if h >= range_m[0]:
        raise ValueError("the platform is higher than the nearest range: no ground to image")
    scp_local = np.array([x_scp, np.sqrt(r_scp**2 - h**2), 0.0])
    scp = frame.to_ecf(scp_local)
    n = proc.aperture_pulses
    # Pulse 0's platform position: line 0's zero-Doppler position, plus the squinted beam's
    # look-back u_mid, less half an aperture (rtsar.ccd.base.line_azimuth_m; u_mid 0 broadside).
    half_m = 0.5 * (n - 1) * geo.along_track_step_m
    x_start = float(azimuth_m[0]) - half_m + beam_look_back_m(cfg)
    t_of = lambda x: (x - x_start) / speed  # noqa: E731 - the track's time at position x
    t_scp = t_of(x_scp)
    duration = (float(azimuth_m[-1] - azimuth_m[0]) + 2 * half_m) / speed  # the look-back cancels
    squint = _squint_terms(cfg, r_scp, t_scp)
    arp0 = frame.to_ecf([x_start, 0.0, h])
    vel = frame.vectors_to_ecf([speed, 0.0, 0.0])
    arp_scp = arp0 + vel * t_scp
    u_row = (scp - arp_scp) / np.linalg.norm(scp - arp_scp)
    u_col = frame.axes[0] - np.dot(frame.axes[0], u_row) * u_row
    u_col /= np.linalg.norm(u_col)
    f0 = geo.carrier_hz
    duration_pulse = getattr(wf, "pulse_duration_s", None) or wf.chirp_duration_s
    t_end = float(duration)
    d = {
        "CollectionInfo": {
            "CollectorName": "rtsar",
            "CoreName": core_name,
            "CollectType": "MONOSTATIC",
            "RadarMode": {"ModeType": "STRIPMAP"},
            "Classification": "UNCLASSIFIED",
        },
        "ImageCreation": {
            "Application": f"rtsar {__version__}",
            "DateTime": np.datetime64(
                datetime.datetime.now(datetime.timezone.utc).replace(tzinfo=None), "us"
            ),
            "Profile": "rtsar shifting-CCD correlator",
        },
        "ImageData": {
            "PixelType": "RE32F_IM32F",
            "NumRows": nrg,
            "NumCols": naz,
            "FirstRow": 0,
            "FirstCol": 0,
            "FullImage": {"NumRows": nrg, "NumCols": naz},
            "SCPPixel": {"Row": scp_row, "Col": scp_col},
            "ValidData": [  # every pixel: clockwise from the first row's first column
                {"Row": r, "Col": c, "index": i + 1}
                for i, (r, c) in enumerate(((0, 0), (0, naz - 1), (nrg - 1, naz - 1), (nrg - 1, 0)))
            ],
        },
        "GeoData": {
            "EarthModel": "WGS_84",
            "SCP": {"ECF": {"X": scp[0], "Y": scp[1], "Z": scp[2]}},
        },
        "Grid": {
            "ImagePlane": "SLANT",
            "Type": "RGZERO",
            "TimeCOAPoly": {"Coefs": squint["time_coa"]},
            "Row": _direction(
                u_row, d_rg, range_resolution(cfg), 2.0 * f0 / C_M_PER_S, None, squint["row_dk"]
            ),
            "Col": _direction(
                u_col,
                d_az,
                azimuth_resolution(cfg, r_scp),
                0.0,
                None if azimuth_irw is None else float(azimuth_irw(cfg, r_scp)),
                squint["col_dk"],
            ),
        },
        "Timeline": {
            "CollectStart": np.datetime64(collection_start or UNKNOWN_EPOCH, "us"),
            "CollectDuration": t_end,
            "IPP": [
                {
                    "TStart": 0.0,
                    "TEnd": t_end,
                    "IPPStart": 0,
                    "IPPEnd": int(round(t_end * geo.prf_hz)) - 1,
                    "IPPPoly": {"Coefs": [0.0, geo.prf_hz]},
                    "index": 1,
                }
            ],
        },
        "Position": {
            "ARPPoly": {
                "X": {"Coefs": [arp0[0], vel[0]]},
                "Y": {"Coefs": [arp0[1], vel[1]]},
                "Z": {"Coefs": [arp0[2], vel[2]]},
            }
        },
        "RadarCollection": {
            "TxFrequency": {"Min": f0 - wf.bandwidth_hz / 2, "Max": f0 + wf.bandwidth_hz / 2},
            "Waveform": [
                {
                    "TxPulseLength": duration_pulse,
                    "TxRFBandwidth": wf.bandwidth_hz,
                    # a down-chirp (rate < 0) starts at the top of its band (SICD's rate is
                    # signed: start + rate · length is where the sweep ends)
                    "TxFreqStart": f0
                    - math.copysign(0.5, wf.chirp_rate_hz_per_s) * wf.bandwidth_hz,
                    "TxFMRate": wf.chirp_rate_hz_per_s,
                    **_receiver(wf, f0),
                    "index": 1,
                }
            ],
            "Area": {"Corner": _area_corners(frame, azimuth_m, range_m, h)},
            "TxPolarization": "UNKNOWN",
            "RcvChannels": [{"TxRcvPolarization": "UNKNOWN", "index": 1}],
        },
        "ImageFormation": {
            "RcvChanProc": {"NumChanProc": 1, "ChanIndices": [1]},
            "TxRcvPolarizationProc": "UNKNOWN",
            "TStartProc": 0.0,
            "TEndProc": t_end,
            "TxFrequencyProc": {
                "MinProc": f0 - wf.bandwidth_hz / 2,
                "MaxProc": f0 + wf.bandwidth_hz / 2,
            },
            "ImageFormAlgo": "RMA",
            "STBeamComp": "NO",
            "ImageBeamComp": "NO",
            "AzAutofocus": "NO",
            "RgAutofocus": "NO",
        },
        "RMA": {
            "RMAlgoType": "RG_DOP",
            "ImageType": "INCA",
            "INCA": {
                "TimeCAPoly": {"Coefs": [t_scp, 1.0 / speed]},
                "R_CA_SCP": r_scp,
                "FreqZero": f0,
                "DRateSFPoly": {"Coefs": [[1.0]]},
                "DopCentroidPoly": {"Coefs": [[geo.doppler_centroid_hz]]},  # constant: rtsar's
                "DopCentroidCOA": True,
            },
        },
    }
    sicd = SICDType.from_dict(d)
    sicd.derive()
    corners = sicd.GeoData.ImageCorners
    placed = [*(c["Lat"] for c in d["RadarCollection"]["Area"]["Corner"]), *scp, *arp0, *vel]
    if (
        corners is None
        or not np.isfinite([*corners.get_array(dtype=np.float64).ravel(), *placed]).all()
    ):
        raise ValueError(
            "the image's geometry (its axes and configuration) places no finite point on the "
            "Earth: nothing SICD can describe"
        )
    return sicd


def _squint_terms(cfg, r_scp: float, t_scp: float) -> dict:
    """What a squint of sin θ = -λ f_dc / 2V adds to an INCA image's grid: the centre of
    aperture trails closest approach (TimeCAPoly: t_scp at the SCP, 1/V a metre along track)
    by R0 tan θ / V (rtsar.params.Geometry beam_centre_offset_m), R0 the pixel's range
    (``time_coa``, TimeCOAPoly's coefficients [row power][column power]); the spatial
    frequencies at that centre sit off KCtr by -2 sin θ / λ = f_dc / V along track
    (``col_dk``: INCA's DopCentroidPoly times TimeCAPoly's slope, as SICD requires) and
    2 (cos θ - 1) / λ in range (``row_dk``: the component of 2/λ along the closest-approach
    direction).  Broadside: closest approach, and no DeltaKCOAPoly written (None)."""
    geo = cfg.geometry
    speed = geo.speed_mps
    if not geo.squinted:
        return {"time_coa": [[t_scp, 1.0 / speed]], "row_dk": None, "col_dk": None}
    lag_s_per_m = geo.squint_tan / speed
    return {
        "time_coa": [[t_scp + r_scp * lag_s_per_m, 1.0 / speed], [lag_s_per_m, 0.0]],
        "row_dk": 2.0 * squint_cos_less_one(cfg) / geo.wavelength_m,
        "col_dk": geo.doppler_centroid_hz / speed,
    }


def _direction(
    u, ss, res: Resolution, kctr, irw_m: float | None = None, dk_coa: float | None = None
) -> dict:
    """A Grid direction (Row or Col) of sample spacing ``ss`` and resolution ``res`` (its
    declared -3 dB width ``irw_m`` where given), its support centred ``dk_coa`` cycles/m off
    KCtr (DeltaKCOAPoly, constant; None: on it, and not written)."""
    bw = res.bandwidth_cycles_per_m
    if not (0 < bw < np.inf and 0 < ss < np.inf):
        raise ValueError(f"an impulse-response bandwidth of {bw:g} cycles/m: no SICD grid")
    # SICD: ImpRespBW <= DeltaK2 - DeltaK1 and |DeltaK| <= 1/(2 SS) (sarpy checks both).  An
    # image sampled at exactly its bandwidth has bw = 1/SS, and rounding may put bw/2 one ulp
    # beyond the bound: the support is clipped to it (2 dk is exact, so ImpRespBW <= 2 dk).
    # A support off centre that crosses ±1/(2 SS) wraps the sampled band: DeltaK1, DeltaK2
    # are then the whole of it (sarpy's Grid estimate_deltak does the same).
    half = 0.5 / ss
    centre = dk_coa or 0.0
    lo, hi = centre - 0.5 * bw, centre + 0.5 * bw
    if lo < -half or hi > half:
        lo, hi = -half, half
    return {
        "UVectECF": {"X": u[0], "Y": u[1], "Z": u[2]},
        "SS": ss,
        "ImpRespWid": res.irw_m if irw_m is None else irw_m,
        "Sgn": -1,
        "ImpRespBW": min(bw, hi - lo),
        "KCtr": kctr,
        "DeltaK1": lo,
        "DeltaK2": hi,
        **({} if dk_coa is None else {"DeltaKCOAPoly": {"Coefs": [[dk_coa]]}}),
        "WgtType": {"WindowName": "UNIFORM" if res.window == "rect" else res.window.upper()},
        **({} if res.window == "rect" else {"WgtFunct": list(res.weights)}),
    }


def _receiver(wf, f0: float) -> dict:
    """RadarCollection/Waveform's receive fields.  A pulsed radar's receiver demodulates with a
    fixed LO and compresses by matched filter: CHIRP, RcvFMRate 0, the AO window's length, its
    band the complex sample rate about the carrier.  An FMCW dechirp mixes with the chirp itself
    (delayed to the reference range): STRETCH, RcvFMRate the chirp rate, a window of one sweep.
    A dechirp's RcvFreqStart is left out: rtsar's beat samples span the transmitted sweep, where
    the ideal LO (the sweep delayed by τ_ref) runs from TxFreqStart - K·τ_ref, below the bound
    SICD sets for a window no longer than the pulse; the CPHD's SC0 gives those frequencies."""
    fs = wf.sample_rate_hz
    if wf.kind == "fmcw":
        return {
            "RcvDemodType": "STRETCH",
            "RcvFMRate": wf.chirp_rate_hz_per_s,
            "RcvWindowLength": wf.chirp_duration_s,
            "ADCSampleRate": fs,
            "RcvIFBandwidth": fs,
        }
    return {
        "RcvDemodType": "CHIRP",  # (sarpy then writes RcvFMRate 0)
        "RcvWindowLength": wf.receive_window_s,
        "ADCSampleRate": fs,
        "RcvIFBandwidth": fs,
        "RcvFreqStart": f0 - 0.5 * fs,
    }


def _area_corners(frame: LocalFrame, azimuth_m, range_m, height_m: float) -> list[dict]:
    """RadarCollection/Area/Corner: the image's footprint on the ground plane (first and last
    line, nearest and farthest range), clockwise seen from above as SICD asks."""
    x = (float(azimuth_m[0]), float(azimuth_m[-1]))
    y = [float(np.sqrt(r * r - height_m**2)) for r in (range_m[0], range_m[-1])]
    local = np.array([[x[0], y[0], 0.0], [x[1], y[0], 0.0], [x[1], y[1], 0.0], [x[0], y[1], 0.0]])
    east, north = local[:, 0], -local[:, 1]  # the frame: x east, y south
    twice_area = np.sum(east * np.roll(north, -1) - np.roll(east, -1) * north)
    if twice_area > 0:  # counter-clockwise: the other way round
        local = local[::-1]
    llh = ecf_to_geodetic(frame.to_ecf(local))
    return [
        {"Lat": float(p[0]), "Lon": float(p[1]), "HAE": float(p[2]), "index": i + 1}
        for i, p in enumerate(llh)
    ]


def write_sicd(
    image_path: str | Path, path: str | Path, frame: LocalFrame | None = None, azimuth_irw=None
) -> dict:
    """Write the rtsar image file ``image_path`` as SICD (NITF) at ``path``
    (``azimuth_irw``: see :func:`sicd_structure`)."""
    require_formats(SICDType, "SICD export")
    image, azimuth_m, range_m, attrs = read_image(image_path)
    if "spotlight" in attrs:  # rtsar.app.spotlight.write_spot_image: an arc, not a track
        raise ValueError(
            f"{image_path} is a spotlight image: SICD export of spotlight images is not "
            "supported (rtsar's SICD geometry is a straight strip-map track); export the "
            "recording's phase history with `rtsar export REC.h5 --cphd OUT.cphd` instead"
        )
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise ValueError(f"{image_path}: an image of {image.shape} has no grid to describe")
    for name, axis in (("azimuth_m", azimuth_m), ("range_m", range_m)):
        steps = np.diff(axis)
        if np.ptp(steps) > 1e-6 * abs(steps[0]):
            raise ValueError(
                f"{image_path}: {name} is not evenly spaced (a live image's line jumps?): "
                "SICD's grid is uniform"
            )
    cfg = image_config(attrs, image_path)
    kept = attrs.get("collection_start_utc")
    start = None if kept is None else parse_utc(kept, f"{image_path}: collection_start_utc")
    # sarpy logs what it finds odd (a degenerate geometry) on stderr; the error here says it.
    sarpy_log = logging.getLogger("sarpy")
    level = sarpy_log.level
    sarpy_log.setLevel(logging.CRITICAL)
    try:
        sicd = sicd_structure(
            image.shape,
            azimuth_m,
            range_m,
            cfg,
            frame or LocalFrame(),
            Path(path).stem,
            start,
            azimuth_irw,
        )
    except ValueError as exc:
        raise ValueError(f"{image_path}: {exc}") from None
    finally:
        sarpy_log.setLevel(level)
    # The XML is sarpy's (its SICD model derives the dependent fields); NGA's sarkit writes the
    # NITF.  (sarpy's own writer copies the structure first, and its copy loses a CHIRP
    # waveform's RcvFMRate = 0 and with it RcvDemodType.)
    xml = etree.ElementTree(etree.fromstring(sicd.to_xml_bytes(tag="SICD")))
    security = sksicd.NitfSecurityFields(clas="U")
    meta = sksicd.NitfMetadata(
        xmltree=xml,
        file_header_part=sksicd.NitfFileHeaderPart(ostaid="rtsar", security=security),
        im_subheader_part=sksicd.NitfImSubheaderPart(isorce="rtsar", security=security),
        de_subheader_part=sksicd.NitfDeSubheaderPart(security=security),
    )
    # Written beside ``path`` and renamed when complete: a run that dies leaves no partial file.
    with (
        replace_when_complete(path) as tmp,
        open(tmp, "wb") as f,
        sksicd.NitfWriter(f, meta) as w,
    ):
        w.write_image(np.ascontiguousarray(image.T, np.complex64))
    version = etree.QName(xml.getroot()).namespace.rsplit(":", 1)[-1]
    return {"version": version, "rows": image.shape[1], "cols": image.shape[0]}
