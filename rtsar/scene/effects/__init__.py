"""Scene effects: opt-in by name, one module per effect, imported only when a scene names it.

REGISTRY maps an effect name to "module:Class".  ``load_effects`` imports a module the first time
a scene names its effect, so an effect that is not named is never computed and never imported.
Effect hooks (see base.Effect) are called by the simulator once per pulse.
"""

from __future__ import annotations

import importlib
import inspect

REGISTRY: dict[str, str] = {
    "noise": "rtsar.scene.effects.noise:ReceiverNoise",
    "antenna_pattern": "rtsar.scene.effects.antenna:AntennaPattern",
    # chirp defects and the reference channels (Crouch ch. 3, HCN; Zhao channels 1-2)
    "chirp_nonlinearity": "rtsar.scene.effects.chirp:ChirpNonlinearity",
    "start_frequency_jitter": "rtsar.scene.effects.chirp:StartFrequencyJitter",
    "reference_interferometer": "rtsar.scene.effects.channels:ReferenceInterferometer",
    "hcn_cell": "rtsar.scene.effects.channels:HCNCell",
    # platform phase errors (Crouch ch. 4; INO phase-error patent)
    "piston": "rtsar.scene.effects.platform:PistonError",
    "along_track_jitter": "rtsar.scene.effects.platform:AlongTrackJitter",
    "reference_region": "rtsar.scene.effects.reference_region:ReferenceRegion",
    # 3D: extra receivers (Zhao 2014; Crouch ch. 6-7; INO 3D patent)
    "interferometric_receivers": "rtsar.scene.effects.receivers:InterferometricReceivers",
    "amplitude_modulation_3d": "rtsar.scene.effects.sam3d:AmplitudeModulation3D",
}


def load_effects(specs, config):
    """Instantiate the named effects, in order.  specs: iterable of (name, params dict)."""
    effects = []
    for name, params in specs:
        try:
            target = REGISTRY[name]
        except KeyError:
            raise ValueError(
                f"unknown effect {name!r}; known effects: {sorted(REGISTRY)}"
            ) from None
        module_name, class_name = target.split(":")
        cls = getattr(importlib.import_module(module_name), class_name)
        accepted = [p for p in inspect.signature(cls).parameters if p != "config"]
        unknown = set(params) - set(accepted)
        if unknown:
            raise ValueError(
                f"effect {name!r}: unknown parameters {sorted(unknown)}; it takes {accepted}"
            )
        try:
            effects.append(cls(config, **params))
        except TypeError as exc:
            raise ValueError(f"effect {name!r}: {exc}; it takes {accepted}") from None
    return effects
