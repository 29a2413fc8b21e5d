"""What a scene tells the corrections: the retro-reflector, the reference interferometer's delay,
the reference-region geometry (rtsar.focus.chain.CorrectionContext).

The simulator and the processor share one description of the instrument, as an instrument and
its calibration sheet do: the defaults of ``pra`` (the scene's brightest point, Crouch's retro-
reflector), of ``linearize`` (the fibre delay of the ``reference_interferometer`` effect) and the
geometry ``reference_region`` needs (the INO patent's d, D and region, from the
``reference_region`` effect) are read from the scene here, so the corrections never see a scene.
"""

from __future__ import annotations

import numpy as np

from ..focus.chain import CorrectionContext
from ..focus.reference_region import ReferenceGeometry
from ..topo.insar_geometry import InsalGeometry
from ..topo.sam3d import ModulationGeometry
from .effects import load_effects
from .model import Scene


def _effect(scene: Scene, name: str):
    """The instantiated effect ``name`` of the scene, or None when the scene does not name it."""
    specs = [(n, p) for n, p in scene.effects if n == name]
    return load_effects(specs, scene.config)[0] if specs else None


def insal_geometry(scene: Scene | None):
    """The interferometer of the scene's ``interferometric_receivers`` effect (main antenna and
    the second receiver ``rx1``) as an rtsar.topo.insar_geometry.InsalGeometry; ValueError when
    the scene has none (height strips need it)."""
    effect = None if scene is None else _effect(scene, "interferometric_receivers")
    if effect is None:
        raise ValueError(
            "--height insal needs the interferometer's geometry: a scene (or a recording of "
            "one) with the interferometric_receivers effect"
        )
    dy, dz = float(effect.dy_m[1] - effect.dy_m[0]), float(effect.dz_m[1] - effect.dz_m[0])
    return InsalGeometry.from_config(
        scene.config,
        baseline_m=float(np.hypot(dy, dz)),
        baseline_angle_deg=float(np.degrees(np.arctan2(dz, dy))),
        passes=2 if effect.mode == "two_pass" else 1,
    )


def modulation_geometry(scene: Scene | None):
    """The masks of the scene's ``amplitude_modulation_3d`` effect as an
    rtsar.topo.sam3d.ModulationGeometry; ValueError when the scene has none."""
    effect = None if scene is None else _effect(scene, "amplitude_modulation_3d")
    if effect is None:
        raise ValueError(
            "--height sam needs the masks' geometry: a scene (or a recording of one) with the "
            "amplitude_modulation_3d effect"
        )
    return ModulationGeometry.from_config(
        scene.config,
        effect.angular_period_rad,
        mask_offset_a=effect.a,
        mask_depth_b=effect.b,
        mask_phase_rad=effect.mask_phase_rad,
    )


def correction_context(scene: Scene | None, start_along_track_m: float | None = None):
    """The CorrectionContext of ``scene`` (an empty one, with ``start_along_track_m``, for None).

    ``start_along_track_m``: the platform position of pulse 0 (default: the scene's).
    """
    if scene is None:
        return CorrectionContext(start_along_track_m=float(start_along_track_m or 0.0))
    retro = None
    if len(scene.targets):
        k = int(np.argmax(np.abs(scene.targets.amplitude)))  # the brightest point
        retro = (float(scene.targets.along_track_m[k]), float(scene.targets.slant_range_m[k]))
    ri = _effect(scene, "reference_interferometer")
    region = _effect(scene, "reference_region")
    start = scene.start_along_track_m if start_along_track_m is None else start_along_track_m
    return CorrectionContext(
        start_along_track_m=float(start),
        retro_m=retro,
        ri_delay_s=None if ri is None else ri.delay_s,
        reference_geometry=None if region is None else ReferenceGeometry.from_effect(region),
    )
