"""The interface every scene effect implements (both hooks are optional)."""

from __future__ import annotations

import numpy as np


class Effect:
    """A physical effect the simulator applies only when the scene names it.

    target_gain  complex gain per scatterer for one pulse (e.g. the antenna pattern), or None
    apply_to_shot  modifies one shot's complex samples in place (e.g. receiver noise)
    """

    name = "effect"

    def target_gain(
        self, pulse: int, along_offset_m: np.ndarray, slant_range_m: np.ndarray
    ) -> np.ndarray | None:
        return None

    def apply_to_shot(self, pulse: int, samples: np.ndarray, rng: np.random.Generator) -> None:
        return None
