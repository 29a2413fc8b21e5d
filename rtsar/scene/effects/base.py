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
apply_to_shot        modifies the main channel's complex samples in place (noise, piston phase)
aux_channels         extra receive channels of this pulse (reference interferometer, HCN cell,
                     second receiver, ...): returns {name: complex samples}; the PulseContext
                     gives the geometry and an ``echo`` function that synthesises returns exactly
                     as the main channel does, for any ranges/gains
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


class Effect:
    """A physical effect the simulator applies only when the scene names it."""

    name = "effect"

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
