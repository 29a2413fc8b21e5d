"""The interface every scene effect implements (every hook is optional).

The simulator calls, per pulse and only for effects that override them:

along_track_error_m  platform position error along track (added to the nominal x_p), metres
chirp_deviation_cycles  transmitted-phase deviation from the ideal linear chirp, in cycles, as a
                     function of time u_s from the middle of the transmitted chirp (pulsed: from the
                     pulse centre).  Each echo delayed by τ carries e(u - τ); an FMCW LO delayed by
                     τ_ref subtracts e(u - τ_ref) (the deviation passes through dechirp; Crouch 3.2)
target_gain          complex gain per scatterer (e.g. the antenna pattern)
along_track_support_m  (not per pulse) the half-width of the along-track offsets outside which
                     target_gain is exactly 0 for every range up to the one given, or None (no
                     such bound): the simulator then skips those scatterers unseen
apply_to_shot        modifies a channel's complex samples in place.  Per receiver (the class
                     attribute ``common_to_receivers`` False, e.g. the main receiver's noise): the
                     main channel's finished shot.  Common (``common_to_receivers`` True, e.g.
                     piston): called on the main channel's echo before the per-receiver effects,
                     and on every echo that ``PulseContext.echo`` synthesises for an auxiliary
                     receiver, so the error reaches every receiver identically; such an effect
                     must not draw from ``rng`` (it is called once per receiver)
aux_channels         extra receive channels of this pulse (reference interferometer, HCN cell,
                     second receiver, ...): returns {name: complex samples}; the PulseContext
                     gives the geometry and an ``echo`` function that synthesises returns exactly
                     as the main channel's, common effects included, for any ranges/gains;
                     ``bare_echo`` omits the common effects (for channels that model their own
                     path errors: reference_region's reference receivers)

What is common to the receivers of one pass (one transmitter, one platform carrying every
receiver; Zhao 2014's two apertures, the INO 3D patent's three detectors behind one aperture):
platform motion — along-track position errors (``along_track_error_m``: each receiver sees the
moved platform through its own geometry, via ctx.along_offset_m / slant_range_m) and piston (a
pure phase: the same phase on every receiver) — transmitter chirp errors
(``chirp_deviation_cycles``: every echo carries the same e(u), via ctx.echo) and the antenna
pattern (``target_gain``, via ctx.gain).  Per receiver: receiver noise (the ``noise`` effect on
the main channel, each auxiliary effect's own ``snr_db``) and the errors of a second pass
(interferometric_receivers mode="two_pass": ψ_k and along_track_offset_m, differential to pass 0,
whose scene effects the second pass repeats).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class PulseContext:
    """What an effect may read about the pulse being simulated (all float64, SI units)."""

    pulse: int
    config: object  # rtsar.params.Config
    platform_along_track_m: float  # true position, errors included
    targets: object  # rtsar.scene.model.Targets
    along_offset_m: np.ndarray  # target along-track minus platform, per target
    slant_range_m: np.ndarray  # exact range to each target at this pulse
    gain: np.ndarray  # complex gain per target after every target_gain hook
    sample_time_s: np.ndarray  # the simulator's time axis of one shot (see simulator docstring)
    deviation: Callable[[np.ndarray], np.ndarray] | None  # total chirp deviation e(u) in cycles
    echo: Callable[..., np.ndarray]  # echo(range_m, gain[, lo_range_m]) → complex128 samples
    rng: np.random.Generator
    bare_echo: Callable[..., np.ndarray] | None = None  # echo without the common effects


class Effect:
    """A physical effect the simulator applies only when the scene names it."""

    name = "effect"
    common_to_receivers = False  # True: apply_to_shot is a platform/transmitter error of the pass

    def along_track_error_m(self, pulse: int) -> float:
        return 0.0

    def chirp_deviation_cycles(self, pulse: int, u_s: np.ndarray) -> np.ndarray | None:
        return None

    def target_gain(
        self, pulse: int, along_offset_m: np.ndarray, slant_range_m: np.ndarray
    ) -> np.ndarray | None:
        return None

    def along_track_support_m(self, max_slant_range_m: float) -> float | None:
        return None

    def apply_to_shot(self, pulse: int, samples: np.ndarray, rng: np.random.Generator) -> None:
        return None

    def aux_channels(self, ctx: PulseContext) -> dict[str, np.ndarray]:
        return {}
