"""Scene files: strict YAML schema (SI units, named parts) → frozen dataclasses."""

from .loader import load_scene, scene_from_dict
from .schema import Scene

__all__ = ["Scene", "load_scene", "scene_from_dict"]
