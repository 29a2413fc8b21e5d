"""Export an rtsar image as SICD (NGA.STND.0024, Sensor Independent Complex Data) in NITF, with
sarpy's SICD model and writer (it derives the dependent fields: SCPCOA, GeoData corners, …).

The mapping: SICD rows are slant range, columns along track (Grid/Type RGZERO, ImagePlane
SLANT), so the pixel array is ``image.T`` (complex64, RE32F_IM32F); Row/SS the range bin
spacing, Col/SS the line spacing, impulse-response bandwidths 2B/c (range) and 2L/(λR)
(azimuth, Crouch eq. 4.8) with the configuration's windows named; the scene centre pixel is the
SCP.  Geometry: rtsar's straight track in its local frame placed on WGS-84 as in
rtsar.sources.formats.geometry (ARPPoly linear in time; a slant-plane image gets the default
platform height), Timeline with one IPP set at the PRF, ImageFormation (range-Doppler RMA, INCA:
closest approach at the column's along-track position), RadarCollection (carrier, chirp).
Polarisation is UNKNOWN (rtsar does not model it).
"""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import numpy as np

from ... import __version__
from ...params import C_M_PER_S, config_from_dict
from ...sources.formats.geometry import LocalFrame, platform_height_m
from ...sources.formats.requirements import require_formats
from ...windows import window as taper
from ..image_file import read_image
from ..io import replace_when_complete

try:
    from sarpy.io.complex.sicd import SICDWriter
    from sarpy.io.complex.sicd_elements.SICD import SICDType, get_default_version_string
except ImportError:  # the optional extra "formats"
    SICDType = None

EPOCH = datetime.datetime(2000, 1, 1)  # rtsar's times are relative: an arbitrary epoch
SINC_3DB_WIDTH = 0.8858929  # -3 dB width of |sinc|² in units of 1 / bandwidth
WINDOW_BROADENING = {"rect": 1.0, "hann": 1.62, "hamming": 1.47, "taylor": 1.19}


def sicd_structure(image_shape, azimuth_m, range_m, cfg, frame: LocalFrame, core_name: str):
    """The SICD metadata (sarpy SICDType, derived) of an image [azimuth, range]."""
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
    x_start = float(azimuth_m[0]) - 0.5 * (n - 1) * geo.along_track_step_m
    t_of = lambda x: (x - x_start) / speed  # noqa: E731 - the track's time at position x
    t_scp = t_of(x_scp)
    duration = t_of(float(azimuth_m[-1]) + 0.5 * (n - 1) * geo.along_track_step_m)
    arp0 = frame.to_ecf([x_start, 0.0, h])
    vel = frame.vectors_to_ecf([speed, 0.0, 0.0])
    arp_scp = arp0 + vel * t_scp
    u_row = (scp - arp_scp) / np.linalg.norm(scp - arp_scp)
    u_col = frame.axes[0] - np.dot(frame.axes[0], u_row) * u_row
    u_col /= np.linalg.norm(u_col)
    bw_rg = 2.0 * wf.bandwidth_hz / C_M_PER_S
    bw_az = 2.0 * geo.illuminated_length_m / (geo.wavelength_m * r_scp)
    bw_az = min(bw_az, 1.0 / geo.along_track_step_m)
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
        },
        "GeoData": {
            "EarthModel": "WGS_84",
            "SCP": {"ECF": {"X": scp[0], "Y": scp[1], "Z": scp[2]}},
        },
        "Grid": {
            "ImagePlane": "SLANT",
            "Type": "RGZERO",
            "TimeCOAPoly": {"Coefs": [[t_scp, 1.0 / speed]]},
            "Row": _direction(u_row, d_rg, bw_rg, 2.0 * f0 / C_M_PER_S, proc.range_window),
            "Col": _direction(u_col, d_az, bw_az, 0.0, proc.azimuth_window),
        },
        "Timeline": {
            "CollectStart": np.datetime64(EPOCH, "us"),
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
                    "TxFreqStart": f0 - wf.bandwidth_hz / 2,
                    "TxFMRate": wf.chirp_rate_hz_per_s,
                    "RcvDemodType": "CHIRP" if wf.kind == "fmcw" else "STRETCH",
                    "index": 1,
                }
            ],
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
                "DopCentroidPoly": {"Coefs": [[0.0]]},  # broadside: zero Doppler centroid
                "DopCentroidCOA": True,
            },
        },
    }
    sicd = SICDType.from_dict(d)
    sicd.derive()
    return sicd


def _direction(u, ss, bw, kctr, window) -> dict:
    return {
        "UVectECF": {"X": u[0], "Y": u[1], "Z": u[2]},
        "SS": ss,
        "ImpRespWid": SINC_3DB_WIDTH * WINDOW_BROADENING.get(window, 1.0) / bw,
        "Sgn": -1,
        "ImpRespBW": bw,
        "KCtr": kctr,
        "DeltaK1": -0.5 * bw,
        "DeltaK2": 0.5 * bw,
        "WgtType": {"WindowName": "UNIFORM" if window == "rect" else window.upper()},
        **({} if window == "rect" else {"WgtFunct": [float(v) for v in taper(window, 64)]}),
    }


def write_sicd(image_path: str | Path, path: str | Path, frame: LocalFrame | None = None) -> dict:
    """Write the rtsar image file ``image_path`` as SICD (NITF) at ``path``."""
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
    text = attrs["config"]
    cfg = config_from_dict(json.loads(text.decode() if isinstance(text, bytes) else str(text)))
    sicd = sicd_structure(
        image.shape, azimuth_m, range_m, cfg, frame or LocalFrame(), Path(path).stem
    )
    # Written beside ``path`` and renamed when complete: a run that dies leaves no partial file.
    with (
        replace_when_complete(path) as tmp,
        open(tmp, "wb") as f,
        SICDWriter(f, sicd, check_existence=False) as w,
    ):
        w.write_chip(np.ascontiguousarray(image.T.astype(np.complex64)), start_indices=(0, 0))
    # The version the file declares (sarpy's writer writes its default, urn:SICD:1.3.0 with
    # sarpy 1.3); version_required() is only the oldest that could hold this content.
    version = get_default_version_string()
    return {"version": version, "rows": image.shape[1], "cols": image.shape[0]}
