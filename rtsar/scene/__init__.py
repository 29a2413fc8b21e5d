"""Scene model (TOML), the raw-shot simulator and the opt-in effects registry."""

from .files import load_scene
from .model import DEMO_SCENE, Scene, Targets, point_scene, scene_from_dict
from .simulator import Shot, Simulator

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
