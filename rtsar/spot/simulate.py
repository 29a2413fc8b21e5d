"""Spotlight shots: the arc of rtsar.spot.geometry, exact path lengths, the dechirped FMCW echo.

For shot n every scatterer's exact path (Crouch eq. 9.2a: 2|P_n - p|; eq. 9.2b for the bistatic
channel: |P_n - p| + |B - p|) is turned into samples by the strip-map simulator's public
``Simulator.echo`` at the effective range L/2, so both instruments share one synthesis (float64
phases reduced mod 1, complex64 only at the end).  The bistatic receiver, when the geometry has
one, is recorded as its own channel ``bistatic`` with its own LO delay.  Effects that act on a
finished shot (``apply_to_shot``: noise, piston) are applied to the main channel as the
strip-map simulator does; effects that need the strip-map track are refused by name.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from ..scene.effects import load_effects
from ..scene.effects.base import Effect
from ..scene.model import point_scene
from ..scene.simulator import Simulator
from .scene import SpotScene

BISTATIC_CHANNEL = "bistatic"
_SHOT_HOOKS = ("apply_to_shot",)


@dataclass(frozen=True, eq=False)
class SpotShot:
    index: int
    angle_rad: float  # θ_n of the Tx/Rx station
    arc_m: float  # station position along the arc, R₀·θ_n
    samples: np.ndarray  # complex64 [sample]
    aux: dict = field(default_factory=dict)


def _shot_effects(scene: SpotScene) -> list[Effect]:
    effects = load_effects(scene.effects, scene.config)
    hooks = [h for h in vars(Effect) if not h.startswith("_") and callable(getattr(Effect, h))]
    for (name, _), e in zip(scene.effects, effects, strict=True):
        used = [h for h in hooks if getattr(type(e), h) is not getattr(Effect, h)]
        if set(used) - set(_SHOT_HOOKS):
            raise ValueError(
                f"effect {name!r} needs the strip-map track ({', '.join(used)}); a spotlight "
                f"scene takes only effects acting on a finished shot"
            )
    return effects


class SpotlightSimulator:
    """Generates the shots of a spotlight scene in order; ``shots()`` feeds a live stream."""

    def __init__(self, scene: SpotScene):
        self.scene = scene
        self.geometry = scene.geometry
        cfg = scene.config
        self._echo = Simulator(point_scene(cfg, [], [], pulses=1)).echo
        self._effects = _shot_effects(scene)
        self._rng = np.random.default_rng(scene.seed)
        self._targets = scene.rotated_m()
        self._next = 0
        wf = cfg.waveform
        self._lo_bistatic = (
            self.geometry.lo_range_m(wf, BISTATIC_CHANNEL) if self.geometry.bistatic else None
        )

    @property
    def pulses(self) -> int:
        return self.geometry.pulses

    def shot(self, pulse: int) -> SpotShot:
        if pulse != self._next:
            raise ValueError(f"shots are generated in order: expected {self._next}, got {pulse}")
        self._next += 1
        g, amp = self.geometry, self.scene.amplitude
        r = g.half_path_m(self._targets, [pulse], "main")[0]
        main = self._echo(r, amp)
        for e in self._effects:
            e.apply_to_shot(pulse, main, self._rng)
        aux = {}
        if g.bistatic:
            rb = g.half_path_m(self._targets, [pulse], BISTATIC_CHANNEL)[0]
            aux[BISTATIC_CHANNEL] = self._echo(rb, amp, None, self._lo_bistatic).astype(
                np.complex64
            )
        theta = float(g.angles_rad([pulse])[0])
        return SpotShot(pulse, theta, g.range_m * theta, main.astype(np.complex64), aux)

    def shots(self, count: int | None = None) -> Iterator[SpotShot]:
        stop = self.pulses if count is None else min(self.pulses, self._next + count)
        while self._next < stop:
            yield self.shot(self._next)

    def block(self, count: int | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The next ``count`` shots (default all): main [pulse, sample], {aux: [pulse, sample]}."""
        shots = list(self.shots(count))
        if not shots:
            return np.zeros((0, self.scene.config.waveform.samples_per_shot), np.complex64), {}
        aux = {k: np.stack([s.aux[k] for s in shots]) for k in shots[0].aux}
        return np.stack([s.samples for s in shots]), aux
