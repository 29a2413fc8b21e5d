"""Float64 reference of the PGA stage: the whole recording in the stream's block layout."""

from __future__ import annotations

import numpy as np

from ...lens.plan import range_axis_m
from ...params import Config
from ...phase import phasor
from ...samples import zero_nonfinite_rows
from .blocks import Stitcher
from .doppler import antenna_coherence, centroid_lags
from .estimator import BlockReport, PGASettings, estimate_block, footprint_pulses


def pga_batch(
    config: Config,
    lines: np.ndarray,
    range_m: np.ndarray | None = None,
    settings: PGASettings | None = None,
) -> tuple[np.ndarray, np.ndarray, list[BlockReport]]:
    """Float64 reference: PGA over a whole recording in the stream's block layout.

    Returns (corrected lines complex128 [pulse, bin], phase_rad float64 [pulse] (the phase
    removed from each pulse), block reports).  ``PGAStage`` fed the same lines in any
    micro-batches returns the same phases and (in complex64) the same lines.
    """
    settings = settings or PGASettings()
    x = np.asarray(lines)
    if x.ndim != 2:
        raise ValueError(f"lines must be [pulses, range_bins], got {x.shape}")
    x = zero_nonfinite_rows(x.astype(np.complex128))[0]
    if range_m is None:
        range_m = range_axis_m(config)
    block, hop, _ = settings.resolved(config.processor.aperture_pulses, footprint_pulses(config))
    total = x.shape[0]
    st = Stitcher(block, hop, settings.doppler_gain, settings.min_doppler_coherence)
    anchor = settings.doppler_anchor and antenna_coherence(config) > 0

    def lags(lines):
        return centroid_lags(config, lines) if anchor else None

    phases, reports = [], []
    b = 0
    while st.next_start(b) + block <= total:
        s = st.next_start(b)
        stop = s + st.margin + hop
        phi, rep = estimate_block(config, x[s : s + block], range_m, settings, s)
        phases.append(st.add(s, phi, rep, stop, lags(x[s : s + block])))
        reports.append(st.annotate(rep))
        b += 1
    if st.committed < total:
        s = max(0, total - block)
        if s == st.prev_start:  # the last regular block already covers the end
            phases.append(st.extend(total))
        else:
            phi, rep = estimate_block(config, x[s:], range_m, settings, s)
            phases.append(st.add(s, phi, rep, total, lags(x[s:])))
            reports.append(st.annotate(rep))
    phase = np.concatenate(phases) if phases else np.zeros(0)
    return x * phasor(-phase)[:, None], phase, reports
