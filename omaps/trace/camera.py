"""The camera and the light of a traced image (docs/FORMAT.md "Camera and light")."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..checks import typed

if TYPE_CHECKING:
    from ..scene import Scene
    from .prepare import Prepared

__all__ = ["Camera", "default_camera", "choose_default_camera", "gltf_camera", "framed", "DEFAULT_LIGHT",
           "SHADOW_TNEAR", "light_direction", "parse_camera", "parse_light"]

DEFAULT_LIGHT = (0.45, 0.8, 0.4)  # towards the sun: high enough to light the ground, low enough to cross crowns
SHADOW_TNEAR = 1e-5  # shadow ray start, as a fraction of the scene's diagonal


def light_direction(v: object = None) -> np.ndarray:
    """A unit direction towards the light (default DEFAULT_LIGHT); an ``InputError`` (a
    ``ValueError``) naming ``light`` for anything but three finite numbers, not all zero."""
    from ..checks import array
    from ..errors import InputError

    d = array(DEFAULT_LIGHT if v is None else v, "light", shape=(3,), kinds="iuf", dtype=np.float64)
    n = np.linalg.norm(d)
    if not np.isfinite(d).all() or not n > 0:
        raise InputError(f"light must be a finite direction, not the zero vector, got {d.tolist()}", param="light")
    return d / n


@dataclass
class Camera:
    eye: np.ndarray
    target: np.ndarray
    fov: float  # vertical field of view, degrees
    up: np.ndarray | None = None  # the image's up direction (None: world +Y, or +Z looking straight up or down)

    def basis(self, width: int, height: int) -> np.ndarray:
        """eye(3), forward(3), right(3), up(3) as the ray loops read them (docs/FORMAT.md "Camera
        and light"): right and up scaled by the half-extent of the image plane at distance 1."""
        f = np.asarray(self.target, float) - np.asarray(self.eye, float)
        f /= np.linalg.norm(f)
        if self.up is not None:
            up = np.asarray(self.up, float)
            up = up - (up @ f) * f
            n = float(np.linalg.norm(up))
            if not n > 1e-9 * float(np.linalg.norm(self.up)):
                raise ValueError("the camera's up vector must not be parallel to its view direction")
            up = up / n
        else:
            up = np.array([0.0, 1.0, 0.0])
            if abs(f @ up) > 0.999:
                up = np.array([0.0, 0.0, 1.0])
        r = np.cross(f, up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        th = math.tan(math.radians(self.fov) / 2)
        return np.concatenate([self.eye, f, r * th * width / height, u * th]).astype(np.float64)

    def to_json(self) -> dict:
        out = {"eye": [float(x) for x in self.eye], "target": [float(x) for x in self.target], "fov": self.fov}
        if self.up is not None:
            out["up"] = [float(x) for x in self.up]
        return out


@typed
def gltf_camera(scene: Scene, index: int) -> Camera:
    """Camera ``index`` of the file (``Scene.cameras``): its node's world position, view direction
    and up (roll), its vertical field of view; the aspect ratio is the traced image's. Raises
    ``InputError`` naming the file when there is no such camera or it cannot be used
    (orthographic, not placed by a node of the default scene, a degenerate transform)."""
    from ..errors import InputError

    cams = scene.cameras
    if not 0 <= index < len(cams):
        have = "no cameras" if not cams else f"{len(cams)} camera{'s' if len(cams) > 1 else ''} (0-{len(cams) - 1})"
        raise InputError(f"camera gltf:{index}: the file has {have}", scene.path, param="camera")
    c = cams[index]
    if c.problem is not None:
        raise InputError(f"camera gltf:{index}: {c.problem}", scene.path, param="camera")
    return Camera(np.array(c.eye, float), np.array(c.eye, float) + c.forward, math.degrees(c.yfov),
                  np.array(c.up, float))


def _grazing(box: np.ndarray) -> Camera:
    lo, hi = box
    size = hi - lo
    eye = lo + size * np.array([0.03, 0.12, 0.03])
    target = lo + size * np.array([0.97, 0.2, 0.97])
    return Camera(eye, target, 60.0)


def _wide(box: np.ndarray) -> bool:
    """Horizontally at least three times its height, but not flat: a grazing view needs height."""
    size = box[1] - box[0]
    across = float(np.hypot(size[0], size[2]))
    return across >= 3 * size[1] and not _flat(box)


def _flat(box: np.ndarray) -> bool:
    size = box[1] - box[0]
    return size[1] <= 1e-3 * float(np.hypot(size[0], size[2]))


FRONT = np.array([-0.6, 0.08, 0.8])  # from the front (glTF: an asset faces +Z), a little left and above
ABOVE = np.array([-0.6, 1.0, 0.8])  # flat geometry (ground cover, decals): from the front, well above


def framed(box: np.ndarray, direction=FRONT, fov: float = 50.0, aspect: float = 1.0) -> Camera:
    """The box whole in view (its bounding sphere inside the narrower field of view), seen from
    ``direction`` (from the box's centre towards the eye)."""
    lo, hi = box
    c = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    half = math.radians(fov) / 2
    if aspect < 1:
        half = math.atan(math.tan(half) * aspect)
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    return Camera(c + radius / math.sin(half) * d, c, fov)


@typed
def default_camera(bounds: np.ndarray, alpha_bounds: np.ndarray | None = None, aspect: float = 1.0) -> Camera:
    """The preferred default view, from the scene's ``bounds`` and the box of its alpha-tested
    geometry (``Scene.alpha_bounds``; None: the scene's). A wide scene (horizontally at least
    three times its height: a forest) whose alpha-tested geometry spreads over at least half of
    it along x and z is crossed along its diagonal from just inside one corner, eye at an eighth
    of its height, looking slightly up; a wide alpha box elsewhere is crossed the same way; any
    other alpha box (a tree) is framed whole, from the front, low, through its crown (a flat one,
    ground cover, from the front and well above)."""
    from ..checks import array, number

    bounds = array(bounds, "bounds", shape=(2, 3), kinds="iuf", dtype=np.float64)
    box = bounds if alpha_bounds is None else array(alpha_bounds, "alpha_bounds", shape=(2, 3), kinds="iuf",
                                                   dtype=np.float64)
    number(aspect, "aspect", 0, open_lo=True)
    if not (np.isfinite(bounds).all() and np.isfinite(box).all()):
        raise InputError("bounds must be finite", param="bounds")
    size, asize = bounds[1] - bounds[0], box[1] - box[0]
    if _wide(bounds) and asize[0] >= 0.5 * size[0] and asize[2] >= 0.5 * size[2]:
        return _grazing(bounds)
    if _wide(box):
        return _grazing(box)
    return framed(box, ABOVE if _flat(box) else FRONT, 50.0, aspect)


MIN_ALPHA_FRACTION = 0.01  # the preferred view is kept if alpha-tested surfaces fill this share of it
PROBE = 64  # probe image width


def _candidates(box: np.ndarray, aspect: float) -> list[tuple[str, Camera]]:
    """Fallback views of the alpha box: framed from eight sides, four from above and straight
    down, and from its centre along the four horizontal axes (geometry inside a building)."""
    out = []
    for k in range(8):
        a = math.radians(45 * k)
        out.append((f"framed, azimuth {45 * k}", framed(box, (-math.sin(a), 0.08, math.cos(a)), 50.0, aspect)))
    for k in range(4):
        a = math.radians(45 + 90 * k)
        out.append((f"framed from above, azimuth {45 + 90 * k}",
                    framed(box, (-math.sin(a), 1.0, math.cos(a)), 50.0, aspect)))
    out.append(("framed from straight above", framed(box, (0, 1, 0), 50.0, aspect)))
    c = box.mean(axis=0)
    for k, d in enumerate(([0, 0, -1], [1, 0, 0], [0, 0, 1], [-1, 0, 0])):
        out.append((f"from the centre, azimuth {90 * k}", Camera(c.copy(), c + np.array(d, float), 70.0)))
    return out


@typed
def choose_default_camera(prep: Prepared, width: int, height: int) -> tuple[Camera, dict]:
    """The default camera of a prepared scene (``trace.prepare``), checked to show its
    alpha-tested geometry: ``default_camera`` if alpha-tested surfaces are the first surface hit
    in at least MIN_ALPHA_FRACTION of a small probe image (opaque-only traversal), otherwise the
    fallback view (``_candidates``) where they fill the most pixels, if any does better. Returns
    the camera and what was chosen (for the report)."""
    from .embree import GEOM_ALPHA
    from .rays import run_primary

    scene: Scene = prep.scene  # type: ignore[assignment]
    bounds = scene.bounds()
    abox = scene.alpha_bounds(prep.rules)
    aspect = width / height
    pw = PROBE
    ph = max(8, min(4 * PROBE, round(PROBE / aspect)))

    def alpha_fraction(cam: Camera) -> float:
        r = run_primary(prep.bvh, None, 0, cam.basis(pw, ph), pw, ph)
        return float(np.count_nonzero(r.geom == GEOM_ALPHA)) / (pw * ph)

    best = default_camera(bounds, abox, aspect)
    if abox is None:
        return best, {"chosen": "default", "alpha_fraction": 0.0}
    frac = first = alpha_fraction(best)
    label = "default"
    if frac < MIN_ALPHA_FRACTION:
        for name, cam in _candidates(abox, aspect):
            f = alpha_fraction(cam)
            if f > frac:
                best, frac, label = cam, f, name
    return best, {"chosen": label, "alpha_fraction": frac, "default_alpha_fraction": first}


def _numbers(n: int, kind: str = "") -> str:
    return f"a {kind}number" if n == 1 else f"{n} {kind}comma-separated numbers"


def _floats(text: str, n: int, what: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")], dtype=np.float64)
    except ValueError:
        raise InputError(f"{what}: expected {_numbers(n)}, got {text!r}", param=what.split()[0]) from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what}: expected {_numbers(n, 'finite ')}, got {text!r}", param=what.split()[0])
    return v


@typed
def parse_camera(text: str) -> Camera | int:
    """A camera as ``omaps trace --camera`` writes it: ``X,Y,Z:TX,TY,TZ:FOV[:UX,UY,UZ]`` (eye,
    target, vertical field of view in degrees, optional up) gives a ``Camera``; ``gltf[:N]`` gives
    the index N of the file's camera (0 by default), resolved by ``gltf_camera`` once the scene is
    read. An ``InputError`` names what is wrong.

    Example::

        >>> from omaps.trace import parse_camera
        >>> parse_camera("0,1,5:0,1,0:60").fov, parse_camera("gltf:2")
        (60.0, 2)
    """
    if not isinstance(text, str):
        from ..errors import InputTypeError

        raise InputTypeError(f"camera must be text such as 'X,Y,Z:TX,TY,TZ:FOV' or 'gltf:N', got "
                             f"{type(text).__name__}", param="camera")
    parts = text.split(":")
    if parts[0].strip().lower() == "gltf":
        if len(parts) == 1:
            return 0
        if len(parts) == 2 and parts[1].strip().isdigit():
            return int(parts[1])
        raise InputError(f"camera gltf[:N] takes a camera index N >= 0, got {text!r}", param="camera")
    if len(parts) not in (3, 4):
        raise InputError(f"camera must be X,Y,Z:TX,TY,TZ:FOV[:UX,UY,UZ] or gltf[:N], got {text!r}", param="camera")
    eye = _floats(parts[0], 3, "camera eye")
    target = _floats(parts[1], 3, "camera target")
    fov = _floats(parts[2], 1, "camera fov")[0]
    up = _floats(parts[3], 3, "camera up") if len(parts) == 4 else None
    if not 0 < fov < 180:
        raise InputError(f"camera field of view must be in (0, 180) degrees, got {fov}", param="camera")
    if np.allclose(eye, target):
        raise InputError("camera eye and target must differ", param="camera")
    cam = Camera(eye, target, float(fov), up)
    try:
        cam.basis(1, 1)
    except ValueError:
        raise InputError("camera up must not be zero or parallel to the view direction", param="camera") from None
    return cam


@typed
def parse_light(text: str | None) -> np.ndarray:
    """The unit direction towards the light from ``X,Y,Z`` text (None: ``DEFAULT_LIGHT``)."""
    try:
        return light_direction(None if text is None else _floats(text, 3, "light"))
    except ValueError:
        raise InputError("light must not be the zero vector", param="light") from None
