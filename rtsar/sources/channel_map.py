"""Which channels of an instrument frame carry which channel of the shot.

A frame (rtsar.sources.frame) holds C channels of the same sample count S.  An instrument's shot
has a main channel and auxiliary ones (reference interferometer, HCN cell, second receiver, …;
rtsar.instrument), and an oversampled auxiliary channel (the HCN cell at q·S samples) does not
fit one frame channel: it spans q consecutive ones, samples in order.  A channel map lists the
shot's channels in frame order, each with the number of frame channels it spans::

    main,reference_interferometer,hcn_cell*8      # frame channels 0, 1 and 2-9

The instrument side packs a shot into frame channels (:meth:`ChannelMap.pack`), the receiver
unpacks them (:meth:`ChannelMap.unpack`); ``tools/fake_instrument.py`` prints the map it sends.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from ..scene.simulator import Simulator

MAIN = "main"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class ChannelMap:
    """The shot's channels in frame order: ((name, frame channels spanned), ...)."""

    entries: tuple[tuple[str, int], ...]

    def __post_init__(self):
        names = [n for n, _ in self.entries]
        if names.count(MAIN) != 1:
            raise ValueError(f"a channel map names the channel {MAIN!r} exactly once: {self.text}")
        if len(set(names)) != len(names):
            raise ValueError(f"a channel map names each channel once: {self.text}")
        for name, count in self.entries:
            if not _NAME.match(name):
                raise ValueError(f"channel name {name!r}: letters, digits and _ only")
            if not (isinstance(count, int) and count >= 1):
                raise ValueError(f"channel {name!r} must span >= 1 frame channels, got {count!r}")
            if name == MAIN and count != 1:
                raise ValueError("the main channel spans one frame channel")

    @classmethod
    def parse(cls, text: str) -> ChannelMap:
        """``"main,reference_interferometer,hcn_cell*8"`` → a ChannelMap (ValueError if bad)."""
        entries = []
        for part in str(text).split(","):
            name, _, count = part.strip().partition("*")
            try:
                k = int(count) if count else 1
            except ValueError:
                raise ValueError(f"channel map {text!r}: {part!r} is not NAME or NAME*K") from None
            entries.append((name.strip(), k))
        return cls(tuple(entries))

    @classmethod
    def for_channels(cls, samples_per_shot: int, widths: dict[str, int]) -> ChannelMap:
        """Main first, then the auxiliary channels by name, each over width / S frame channels."""
        entries = [(MAIN, 1)]
        for name in sorted(widths):
            k, rest = divmod(int(widths[name]), int(samples_per_shot))
            if rest or k < 1:
                raise ValueError(
                    f"channel {name!r} has {widths[name]} samples per shot, not a multiple of "
                    f"the main channel's {samples_per_shot}: it cannot travel in frames"
                )
            entries.append((name, k))
        return cls(tuple(entries))

    @classmethod
    def for_scene(cls, scene) -> ChannelMap | None:
        """The map of a scene's shots (one simulated shot says which channels its effects add);
        None when the scene has the main channel only."""
        main, aux = Simulator(replace(scene, pulses=1)).block_with_aux(1)
        if not aux:
            return None
        return cls.for_channels(main.shape[1], {k: v.shape[1] for k, v in aux.items()})

    @property
    def text(self) -> str:
        return ",".join(n if k == 1 else f"{n}*{k}" for n, k in self.entries)

    @property
    def frame_channels(self) -> int:
        return sum(k for _, k in self.entries)

    @property
    def aux_names(self) -> list[str]:
        return [n for n, _ in self.entries if n != MAIN]

    def pack(self, main: np.ndarray, aux: dict) -> np.ndarray:
        """Shots [pulse, S] and their channels → frame payloads [pulse, frame channel, S]."""
        main = np.atleast_2d(main)
        p, s = main.shape
        parts = []
        for name, k in self.entries:
            x = main if name == MAIN else np.asarray(aux[name])
            if x.shape != (p, k * s):
                raise ValueError(f"channel {name!r}: {x.shape}, the map says ({p}, {k * s})")
            parts.append(x.reshape(p, k, s))
        return np.concatenate(parts, axis=1)

    def unpack(self, frames: np.ndarray) -> tuple[np.ndarray, dict]:
        """Frame payloads [pulse, frame channel, S] → (main [pulse, S], {name: [pulse, k·S]})."""
        p, c, s = frames.shape
        if c < self.frame_channels:
            raise ValueError(f"frames carry {c} channels, the map needs {self.frame_channels}")
        main, aux, i = None, {}, 0
        for name, k in self.entries:
            block = frames[:, i : i + k].reshape(p, k * s)
            if name == MAIN:
                main = block
            else:
                aux[name] = block
            i += k
        return main, aux
