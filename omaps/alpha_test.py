"""The alpha test: the one place where alpha becomes a decision, for every command.

An ``AlphaTest`` is what an any-hit shader compares -- a texture's values (``value[y, x]``),
a threshold and whether equality passes -- plus the filter and addressing it samples with, and
the *rule* that turns texel values into T/O/C states for the bakers:

* ``test``: O where the shader's comparison passes, T elsewhere; texels within ``tolerance`` of
  the threshold are C (a shader computing alpha x factor in its own precision may decide them
  either way);
* ``levels``: T iff value <= ``low``, O iff value >= ``high``, C between (the deck's corpus rule;
  and glTF BLEND materials, whose partial alpha no map can decide);
* ``unknown``: every texel C (a texture that could not be read).

The corpus rules (``StateRule``: ``levels`` and ``cutoff`` in 8-bit units) and the glTF material
rule (``material_test``: MASK ``alphaCutoff``, the BLEND policy, base colour factor x texture
alpha, the sampler's filter and wrap) both build an ``AlphaTest``. The bakers read its texel
states through ``grid()``; the tracer's any-hit shader, the OMM promotion and the 2-state modes
evaluate ``sample_passes`` on the same ``value`` and ``threshold``. docs/FORMAT.md "The alpha
test" states the same rules.

Example::

    >>> import numpy as np
    >>> from omaps.alpha_test import StateRule
    >>> from omaps.texture import load_alpha
    >>> test = StateRule("cutoff", cutoff=0.5).alpha_test(load_alpha(np.array([[0, 200]], np.uint8)))
    >>> test.texel_states().tolist()
    [[0, 1]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

import os

from . import checks, states
from .errors import InputError, InputTypeError
from .sampling import FootprintGrid, filter_code, footprint_grid, sample_texture, wrap_code
from .texture import AlphaTexture, as_texture

__all__ = ["AlphaTest", "StateRule", "MaterialRules", "material_test", "passes", "below", "sample_passes", "MODES",
           "BLEND_RULES", "RULES", "CUTOFF_TOLERANCE"]

RULES = ("test", "levels", "unknown")
from .names import BLEND_RULES, MODES  # noqa: E402,F401 corpus rules (``StateRule``), BLEND rules (``MaterialRules``)
# glTF texels whose alpha x baseColorFactor.a is this close to the cut-off are unknown: a shader's
# float32 product may fall on either side (exact 8-bit alphas are 1/255 = 0.0039 apart)
CUTOFF_TOLERANCE = 1e-6


@dataclass(frozen=True)
class AlphaTest:
    """``value[y, x]`` passes when ``value > threshold`` (``>=`` if ``inclusive``), sampled with
    ``filter`` and the addressing ``wrap_u`` / ``wrap_v``; ``rule`` (with ``low``, ``high``,
    ``tolerance``) makes texel states. See the module docstring."""

    name: str
    value: np.ndarray  # (H, W) any real dtype; integer textures keep their raw values
    threshold: float
    inclusive: bool = False
    filter: str = "nearest"
    wrap_u: str = "clamp"
    wrap_v: str = "clamp"
    rule: str = "test"
    low: float = 0.0
    high: float = 1.0
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        from .names import FILTERS, WRAP_MODES

        checks.text(self.name, "name")
        checks.choice(self.filter, "filter", FILTERS)
        checks.choice(self.wrap_u, "wrap_u", WRAP_MODES)
        checks.choice(self.wrap_v, "wrap_v", WRAP_MODES)
        checks.choice(self.rule, "rule", RULES)
        checks.boolean(self.inclusive, "inclusive")
        for name in ("threshold", "low", "high", "tolerance"):
            if isinstance(getattr(self, name), bool) or not isinstance(getattr(self, name), (int, float, np.number)):
                raise InputTypeError(f"{name} must be a number, got {type(getattr(self, name)).__name__}", param=name)
        v = checks.array(self.value, "value", kinds="biuf")
        if v.ndim != 2 or v.size == 0:
            raise InputError(f"alpha must be a non-empty 2-D array, got shape {v.shape}", self.name)

    @property
    def width(self) -> int:
        return int(self.value.shape[1])

    @property
    def height(self) -> int:
        return int(self.value.shape[0])

    def bounds(self) -> np.ndarray:
        """The rule as bounds on alpha, float64 (o_bound, o_inclusive, t_bound, t_inclusive): an
        alpha (a texel's, or every alpha a region can read) is O iff it is > o_bound (>= when
        o_inclusive), T iff it is < t_bound (<= when t_inclusive), C otherwise."""
        if self.rule == "unknown":
            return np.array([np.inf, 0.0, -np.inf, 0.0])
        if self.rule == "levels":
            return np.array([self.high, 1.0, self.low, 1.0])
        if self.tolerance > 0:  # within the tolerance of the threshold either decision may happen
            return np.array([self.threshold + self.tolerance, 0.0, self.threshold - self.tolerance, 0.0])
        if self.inclusive:
            return np.array([self.threshold, 1.0, self.threshold, 0.0])
        return np.array([self.threshold, 0.0, self.threshold, 1.0])

    def texel_states(self) -> np.ndarray:
        """T/O/C code of every texel, uint8 (H, W)."""
        v = np.asarray(self.value)
        ob, oi, tb, ti = self.bounds()
        out = np.full(v.shape, states.C, dtype=np.uint8)
        out[passes.py_func(tb, v, bool(ti))] = states.T  # ``below``: tb > v (>=), as arrays
        out[passes.py_func(v, ob, bool(oi))] = states.O
        return out

    def grid(self) -> FootprintGrid:
        """The footprint grid the bakers rasterise over (made once per test: the tracer's schemes
        and an OMM's primitives of one material share it). Under the linear filter it is exact:
        a region's part of a cell whose taps disagree is decided from the extremes of the
        bilinear alpha over it (``omaps.bilinear``)."""
        grid = self.__dict__.get("_grid")
        if grid is None:
            exact = self.filter == "linear" and self.rule != "unknown"
            grid = footprint_grid(self.texel_states(), self.filter, self.wrap_u, self.wrap_v,
                                  self.value if exact else None, self.bounds() if exact else None)
            object.__setattr__(self, "_grid", grid)
        return grid

    def codes(self) -> tuple[int, int, int]:
        """(filter 0 nearest / 1 linear, wrap code of u, of v) for the numba kernels."""
        return filter_code(self.filter), wrap_code(self.wrap_u), wrap_code(self.wrap_v)

    def settings(self) -> dict:
        """What decides this test, as JSON (outputs record it)."""
        out = {"name": self.name, "width": self.width, "height": self.height, "rule": self.rule,
               "threshold": float(self.threshold), "inclusive": bool(self.inclusive), "filter": self.filter,
               "wrap_u": self.wrap_u, "wrap_v": self.wrap_v}
        if self.rule == "levels":
            out.update(low=float(self.low), high=float(self.high))
        if self.rule == "test" and self.tolerance:
            out["tolerance"] = float(self.tolerance)
        return out


@njit(cache=True, inline="always")
def passes(a, threshold, inclusive):
    """The shader's comparison: alpha ``a`` passes when it is above ``threshold``, or equal to it
    when ``inclusive``. Every alpha decision calls it: the shader (``sample_passes``), the
    sampled opaque fractions, the texel states and the exact bilinear extremes (O bounds).
    ``passes.py_func`` applies it to numpy arrays element by element."""
    return a >= threshold if inclusive else a > threshold


@njit(cache=True, inline="always")
def below(a, bound, inclusive):
    """``passes`` mirrored: ``a`` is below ``bound``, or equal to it when ``inclusive`` (the T
    bounds of ``AlphaTest.bounds``): ``bound`` passes ``a``."""
    return passes(bound, a, inclusive)


@njit(cache=True)
def sample_passes(value, threshold, inclusive, filt, mode_u, mode_v, x, y):
    """The any-hit shader's alpha test at texel coordinate (x, y): the texture fetch
    ``sampling.sample_texture`` compared with the threshold (``passes``)."""
    return passes(sample_texture(value, filt, mode_u, mode_v, x, y), threshold, inclusive)


# ---- the corpus rules -------------------------------------------------------------------------

@dataclass(frozen=True)
class StateRule:
    """The corpus rules of ``omaps eval``, in 8-bit units (``alpha8 = raw * 255 / maxval``):
    ``levels`` (the deck's: T if alpha8 <= t_max, O if alpha8 >= o_min) or ``cutoff`` (opaque iff
    alpha8 > cutoff * 255; cutoff in [0, 1] like glTF's alphaCutoff)."""

    mode: str = "levels"
    t_max: float = 30.0
    o_min: float = 225.0
    cutoff: float = 0.5

    def __post_init__(self) -> None:
        if isinstance(self.mode, str) and self.mode not in MODES:
            raise InputError(f"unknown state mode {self.mode!r} (choose from {', '.join(MODES)})", param="mode")
        checks.choice(self.mode, "mode", MODES)
        for name in ("t_max", "o_min", "cutoff"):
            checks.number(getattr(self, name), name)
        if self.mode == "levels" and not (0 <= self.t_max < self.o_min <= 255):
            raise InputError(f"levels need 0 <= t_max < o_min <= 255, got {self.t_max}, {self.o_min}",
                             param=("t_max", "o_min"))
        if self.mode == "cutoff" and not (0 <= self.cutoff <= 1):
            raise InputError(f"cutoff must be in [0, 1], got {self.cutoff}", param="cutoff")

    def alpha_test(self, texture: AlphaTexture | np.ndarray | str | os.PathLike[str], filter: str = "nearest",
                   wrap: str = "clamp", wrap_v: str | None = None) -> AlphaTest:
        """The test of a texture under this rule.

        Parameters
        ----------
        texture : AlphaTexture, numpy array or path
            Anything ``omaps.texture.as_texture`` takes: an (H, W) or (H, W, C) array of uint8,
            uint16, bool or float in [0, 1] (greyscale, LA, RGB with ``channel``, RGBA), or an
            image file.
        filter, wrap, wrap_v : str
            How the shader samples: ``nearest`` / ``linear``; ``clamp`` / ``wrap`` / ``mirror``
            (``wrap_v`` defaults to ``wrap``).

        Returns
        -------
        AlphaTest
            ``levels`` has no shader decision of its own; its threshold (alpha8 > 127.5) only
            serves promotions to 2-state. ``cutoff`` on a float texture compares the floats with
            ``cutoff`` itself, exactly (alpha 0.5 does not pass a cut-off of 0.5).

        Examples
        --------
        >>> import numpy as np
        >>> StateRule("cutoff", cutoff=0.5).alpha_test(np.array([[0.5, 0.75]])).texel_states().tolist()
        [[0, 1]]
        """
        from .names import FILTERS, WRAP_MODES

        checks.choice(filter, "filter", FILTERS)
        checks.choice(wrap, "wrap", WRAP_MODES)
        checks.choice(wrap_v, "wrap_v", WRAP_MODES, optional=True)
        texture = as_texture(texture)
        a8 = texture.alpha8
        wv = wrap if wrap_v is None else wrap_v
        if self.mode == "levels":
            return AlphaTest(texture.name, a8, 127.5, False, filter, wrap, wv, "levels", self.t_max, self.o_min)
        if texture.is_float:  # the floats themselves: x 255 could round a cut-off onto an alpha
            return AlphaTest(texture.name, texture.values, float(self.cutoff), False, filter, wrap, wv, "test")
        return AlphaTest(texture.name, a8, self.cutoff * 255.0, False, filter, wrap, wv, "test")

    def classify(self, texture: AlphaTexture | np.ndarray | str | os.PathLike[str]) -> np.ndarray:
        """Texel states (uint8 codes of ``omaps.states``), shape (H, W), of a texture, an array
        or an image path."""
        return self.alpha_test(texture).texel_states()

    def settings(self) -> dict:
        if self.mode == "levels":
            return {"mode": "levels", "t_max": self.t_max, "o_min": self.o_min}
        return {"mode": "cutoff", "cutoff": self.cutoff}


def as_grid(value: object, param: str = "grid") -> FootprintGrid:
    """A footprint grid (``omaps.sampling.FootprintGrid``) as it is; an ``AlphaTest`` gives its
    ``grid()``; anything else raises an ``InputTypeError`` naming ``param``."""
    if isinstance(value, AlphaTest):
        return value.grid()
    if not isinstance(value, FootprintGrid):
        raise InputTypeError(f"{param} must be a FootprintGrid (AlphaTest.grid()) or an AlphaTest, got "
                             f"{checks._show(value)}", param=param)
    return value


# ---- the glTF material rule -------------------------------------------------------------------

@dataclass(frozen=True)
class MaterialRules:
    """How a scene's materials are alpha-tested, the same for ``omaps trace`` and ``omaps omm``.

    ``cutoff`` replaces every MASK material's ``alphaCutoff``; ``filter`` and ``wrap`` replace the
    samplers' (None keeps each material's own). BLEND materials follow ``blend``: ``levels`` (T
    only where alpha x factor is 0, O only where it is 1; the shader decides the rest at
    ``blend_cutoff``), ``cutoff`` (alpha-tested like MASK at ``blend_cutoff``) or ``skip``
    (treated as opaque geometry: no alpha test, no map)."""

    cutoff: float | None = None
    filter: str | None = None
    wrap: str | None = None
    blend: str = "levels"
    blend_cutoff: float = 0.5

    def __post_init__(self) -> None:
        from .names import FILTERS, WRAP_MODES

        if isinstance(self.blend, str) and self.blend not in BLEND_RULES:
            raise InputError(f"unknown blend rule {self.blend!r} (choose from {', '.join(BLEND_RULES)})",
                             param="blend")
        checks.choice(self.blend, "blend", BLEND_RULES)
        for name in ("cutoff", "blend_cutoff"):
            v = getattr(self, name)
            if v is not None:
                checks.number(v, name, 0.0, 1.0)
        checks.choice(self.filter, "filter", FILTERS, optional=True)
        checks.choice(self.wrap, "wrap", WRAP_MODES, optional=True)

    def alpha_tested(self, alpha_mode: str) -> bool:
        return alpha_mode == "MASK" or (alpha_mode == "BLEND" and self.blend != "skip")

    def settings(self) -> dict:
        return {"cutoff": self.cutoff, "filter": self.filter, "wrap": self.wrap, "blend": self.blend,
                "blend_cutoff": self.blend_cutoff}


def material_test(name: str, alpha_mode: str, cutoff: float, factor: float, alpha: np.ndarray | None,
                  maxval: int, filter: str, wrap_u: str, wrap_v: str, rules: MaterialRules = MaterialRules(),
                  readable: bool = True) -> AlphaTest:
    """The alpha test of a glTF material: opaque iff factor x alpha / maxval >= cutoff, evaluated
    on the raw texture values as alpha >= cutoff x maxval / factor (so baker and shader compare
    the same numbers). ``alpha`` None: no texture (one texel of value ``maxval``); ``readable``
    False: the texture could not be read, the shader sees white and every texel is C."""
    if not rules.alpha_tested(alpha_mode):
        raise ValueError(f"{alpha_mode} materials are not alpha-tested under blend rule {rules.blend!r}")
    # (the placeholder texel in the 8-bit textures' dtype when it fits: the kernels then run on
    # the specialisation every 8-bit texture uses instead of compiling another)
    value = np.full((1, 1), maxval, dtype=np.uint8 if maxval <= 255 else np.uint16) if alpha is None else alpha
    filt = rules.filter or filter
    wu = rules.wrap or wrap_u
    wv = rules.wrap or wrap_v
    scale = maxval / factor if factor > 0 else np.inf  # raw units per unit of factor x alpha

    def raw(x):
        return np.inf if factor <= 0 else x * scale

    if alpha_mode == "BLEND":
        thr = raw(rules.blend_cutoff)
        if not readable:
            return AlphaTest(name, value, thr, True, filt, wu, wv, "unknown")
        if rules.blend == "levels":
            low = 0.0 if factor > 0 else np.inf
            return AlphaTest(name, value, thr, True, filt, wu, wv, "levels", low, raw(1.0))
        c = rules.blend_cutoff
    else:
        c = cutoff if rules.cutoff is None else rules.cutoff
    thr = raw(c)
    if not readable:
        return AlphaTest(name, value, thr, True, filt, wu, wv, "unknown")
    tol = CUTOFF_TOLERANCE * scale if factor > 0 else 0.0
    return AlphaTest(name, value, thr, True, filt, wu, wv, "test", tolerance=tol)
