"""Whether the echoes compress with the chirp the instrument file gives, or better with the
chirp of the other sign: a sign written wrong, or samples stored conjugated (I and Q swapped).

The matched filter of a chirp of rate k, applied to the samples' conjugate, gives the conjugate
of the filter of rate -k applied to the samples (a chirp's conjugate is the chirp of the
opposite rate), so one lens tells both: ``lens.compress(x)`` and ``lens.compress(conj(x))``
have the magnitudes of x compressed with k and with -k.  Their sharpness is the contrast
E|y|⁴ / (E|y|²)²: 2 for speckle (complex Gaussian samples, with either chirp: nothing to
compress), higher where bright scatterers compress to points, and lower again where the wrong
chirp spreads each over twice the pulse.  RADARSAT-1's Vancouver block, its first 256 pulses:
3.46 with its down-chirp, 2.66 with an up-chirp; 10.8 against 2.75 over all 1536 (the ships).
"""

from __future__ import annotations

import numpy as np

FLIPPED_SHARPER = 1.2  # the other sign's contrast this many times the given's: told


def compression_contrast(lines: np.ndarray) -> float:
    """E|y|⁴ / (E|y|²)² of range-compressed lines (0 where they are all zero)."""
    power = np.abs(np.asarray(lines, np.complex128)) ** 2
    mean = float(power.mean()) if power.size else 0.0
    return float((power**2).mean() / mean**2) if mean > 0 else 0.0


def chirp_sign_contrasts(lens, shots: np.ndarray) -> tuple[float, float]:
    """(contrast of ``shots`` [pulse, sample] compressed by ``lens`` with its own chirp, with
    the chirp of the other sign)."""
    x = np.ascontiguousarray(shots, np.complex64)
    given = compression_contrast(lens.compress(x))
    flipped = compression_contrast(lens.compress(np.ascontiguousarray(np.conj(x))))
    return given, flipped


def chirp_sign_warning(given: float, flipped: float, key: str) -> str | None:
    """The warning where the other sign compresses the echoes sharper (None where not):
    ``key`` names the chirp rate's setting."""
    if not flipped > FLIPPED_SHARPER * given:
        return None
    return (
        f"warning: the echoes compress sharper with the chirp of the other sign (contrast "
        f"{flipped:.2f} against {given:.2f} with {key} as given; 2 is speckle's): check its "
        "sign, or whether the samples are stored conjugated (I and Q swapped; that also "
        "turns the Doppler centroid's sign)"
    )
