"""The camera and the light of a traced image (docs/FORMAT.md "Camera and light")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Camera", "default_camera", "DEFAULT_LIGHT", "SHADOW_TNEAR", "light_direction"]

DEFAULT_LIGHT = (0.45, 0.8, 0.4)  # towards the sun: high enough to light the ground, low enough to cross crowns
SHADOW_TNEAR = 1e-5  # shadow ray start, as a fraction of the scene's diagonal


def light_direction(v=None) -> np.ndarray:
    """A unit direction towards the light (default DEFAULT_LIGHT)."""
    d = np.asarray(DEFAULT_LIGHT if v is None else v, np.float64)
    n = np.linalg.norm(d)
    if not n > 0:
        raise ValueError("the light direction must not be the zero vector")
    return d / n


@dataclass
class Camera:
    eye: np.ndarray
    target: np.ndarray
    fov: float  # vertical field of view, degrees

    def basis(self, width: int, height: int) -> np.ndarray:
        f = np.asarray(self.target, float) - np.asarray(self.eye, float)
        f /= np.linalg.norm(f)
        up = np.array([0.0, 1.0, 0.0])
        if abs(f @ up) > 0.999:
            up = np.array([0.0, 0.0, 1.0])
        r = np.cross(f, up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        th = math.tan(math.radians(self.fov) / 2)
        return np.concatenate([self.eye, f, r * th * width / height, u * th]).astype(np.float64)

    def to_json(self) -> dict:
        return {"eye": [float(x) for x in self.eye], "target": [float(x) for x in self.target], "fov": self.fov}


def default_camera(bounds: np.ndarray) -> Camera:
    """A low, grazing view through the foliage. A wide scene (a forest) is crossed along its
    diagonal from just inside one corner, eye at an eighth of the scene's height, looking slightly
    up; a compact one (a tree) is framed whole from the side, low, through its crown."""
    lo, hi = bounds
    size = hi - lo
    height = size[1]
    if float(np.hypot(size[0], size[2])) >= 3 * height:
        eye = lo + size * np.array([0.03, 0.12, 0.03])
        target = lo + size * np.array([0.97, 0.2, 0.97])
        return Camera(eye, target, 60.0)
    c = (lo + hi) / 2
    radius = float(np.linalg.norm(size)) / 2
    d = radius / math.sin(math.radians(50) / 2)
    direction = np.array([-0.6, 0.08, -0.8])
    direction /= np.linalg.norm(direction)
    return Camera(c + d * direction, c, 50.0)
