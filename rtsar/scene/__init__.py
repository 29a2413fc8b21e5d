"""Scene model (TOML), the raw-shot simulator and the opt-in effects registry."""

from .files import load_scene
from .model import DEMO_SCENE, Scene, Targets, point_scene, scene_from_dict

__all__ = [
    "DEMO_SCENE",
    "Scene",
    "Targets",
    "load_scene",
    "point_scene",
    "scene_from_dict",
    "Shot",
    "Simulator",
]


def __getattr__(name: str):
    """``Simulator`` and ``Shot`` load on first use: the simulator's numba kernels take ~0.4 s to
    import, and reading a scene or a recording needs none of them."""
    if name in ("Shot", "Simulator"):
        from . import simulator

        return getattr(simulator, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
