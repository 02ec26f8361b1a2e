"""Argument checks of the Python API, one place for all: each returns the value in the form the
code uses, or raises an omaps error naming the parameter in Python terms (``param``): an
:class:`~omaps.errors.InputTypeError` for a value of the wrong type, an
:class:`~omaps.errors.InputError` for one out of range. The command line names its own option
for the parameter (``omaps.cli.main``).

>>> integer(3, "level", 0, 12)
3
>>> integer("3", "level", 0, 12)
Traceback (most recent call last):
...
omaps.errors.InputTypeError: level must be an integer, got '3'
>>> choice("2state", "format", ("4state", "2state"))
'2state'
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Iterable, Sequence
from typing import Any

from .errors import InputError, InputTypeError

__all__ = ["integer", "number", "boolean", "choice", "text", "path", "paths", "path_or_array", "paths_or_arrays",
           "array", "size", "input_name", "grid"]


def _show(value: object) -> str:
    """A value for a message: short, its type when it is no plain scalar."""
    if isinstance(value, (str, bytes, int, float, bool, type(None))):
        text = repr(value)
        return text if len(text) <= 60 else text[:57] + "..."
    shape = getattr(value, "shape", None)
    if shape is not None and hasattr(value, "dtype"):
        return f"an array of shape {tuple(shape)} ({value.dtype})"  # type: ignore[attr-defined]
    return f"a {type(value).__name__}"


def _range(lo: float | None, hi: float | None) -> str:
    if lo is not None and hi is not None:
        return f"from {lo} to {hi}"
    return f">= {lo}" if lo is not None else f"<= {hi}"


def integer(value: object, param: str, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as an int: a Python or numpy integer (not a bool) within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputTypeError(f"{param} must be an integer, got {_show(value)}", param=param)
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        what = f"an integer {_range(lo, hi)}" if lo is not None and hi is not None else _range(lo, hi)
        raise InputError(f"{param} must be {what}, got {v}", param=param)
    return v


def number(value: object, param: str, lo: float | None = None, hi: float | None = None, *,
           open_lo: bool = False, open_hi: bool = False) -> float:
    """``value`` as a finite float: a Python or numpy real number (not a bool) within the bounds
    (``open_lo`` / ``open_hi``: the bound itself excluded)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputTypeError(f"{param} must be a number, got {_show(value)}", param=param)
    v = float(value)
    bad = not math.isfinite(v) or (lo is not None and (v <= lo if open_lo else v < lo)) or (
        hi is not None and (v >= hi if open_hi else v > hi))
    if bad:
        if lo is not None and hi is not None:
            what = f"in {'(' if open_lo else '['}{lo}, {hi}{')' if open_hi else ']'}"
        elif lo is not None:
            what = f"{'>' if open_lo else '>='} {lo}"
        elif hi is not None:
            what = f"{'<' if open_hi else '<='} {hi}"
        else:
            what = "finite"
        raise InputError(f"{param} must be {what}, got {v}", param=param)
    return v


def boolean(value: object, param: str) -> bool:
    """``value`` as a bool: True, False (or a numpy bool)."""
    if not isinstance(value, (bool, _np_bool())):
        raise InputTypeError(f"{param} must be True or False, got {_show(value)}", param=param)
    return bool(value)


def _np_bool() -> type:
    import numpy as np

    return np.bool_


def text(value: object, param: str) -> str:
    """``value`` as a str."""
    if not isinstance(value, str):
        raise InputTypeError(f"{param} must be a string, got {_show(value)}", param=param)
    return value


def choice(value: object, param: str, choices: Iterable[str], *, optional: bool = False) -> str | None:
    """``value``, one of ``choices`` (None too when ``optional``)."""
    if value is None and optional:
        return None
    names = tuple(choices)
    if not isinstance(value, str):
        raise InputTypeError(f"{param} must be one of {', '.join(names)}, got {_show(value)}", param=param)
    if value not in names:
        raise InputError(f"unknown {param} {value!r} (choose from {', '.join(names)})", param=param)
    return value


def path(value: object, param: str) -> str:
    """``value``, a file path (str or os.PathLike), as a str."""
    if isinstance(value, os.PathLike):
        value = os.fspath(value)
    if not isinstance(value, str):
        raise InputTypeError(f"{param} must be a path (str or os.PathLike), got {_show(value)}", param=param)
    if not value or "\0" in value:
        raise InputError(f"{param} must be a path, got {value!r}", param=param)
    return value


def _items(value: object, param: str, single: tuple[type, ...]) -> list[Any]:
    """One item (of the types ``single``) or a list / tuple of them, as a list."""
    if isinstance(value, single) or isinstance(value, os.PathLike):
        return [value]
    if not isinstance(value, Sequence) or isinstance(value, (str, bytes)):
        kinds = "a path, an array, or a list of them" if len(single) > 1 else "a path or a list of paths"
        raise InputTypeError(f"{param} must be {kinds}, got {_show(value)}", param=param)
    return list(value)


def paths(value: object, param: str) -> list[str]:
    """One path or a list / tuple of them, as a list of str."""
    if isinstance(value, (str, os.PathLike)):
        return [path(value, param)]
    return [path(v, f"{param}[{i}]") for i, v in enumerate(_items(value, param, (str,)))]


def path_or_array(value: object, param: str) -> Any:
    """A path (as a str) or a numpy array (as it is)."""
    import numpy as np

    if isinstance(value, np.ndarray):
        return value
    if isinstance(value, (str, os.PathLike)):
        return path(value, param)
    raise InputTypeError(f"{param} must be a path or a numpy array, got {_show(value)}", param=param)


def paths_or_arrays(value: object, param: str) -> list[Any]:
    """One path or numpy array, or a list / tuple of them, as a list (paths as str)."""
    import numpy as np

    if isinstance(value, (str, os.PathLike, np.ndarray)):
        return [path_or_array(value, param)]
    return [path_or_array(v, f"{param}[{i}]") for i, v in enumerate(_items(value, param, (str, np.ndarray)))]


def input_name(item: object, index: int) -> str:
    """The name of an input in messages and results: a path as given, an array as ``array N``."""
    return item if isinstance(item, str) else f"array {index}"


def array(value: object, param: str, *, ndim: int | Sequence[int] | None = None, shape: tuple[int | None, ...] | None = None,
          kinds: str | None = None, dtype: Any = None) -> Any:
    """``value`` as a numpy array: of ``ndim`` dimensions (one of them), of ``shape`` (None: any
    size on that axis), of a dtype whose kind is in ``kinds`` (``"b"``, ``"iu"``, ``"f"``), then
    converted to ``dtype``."""
    import numpy as np

    if isinstance(value, (str, bytes, os.PathLike)) or value is None:
        raise InputTypeError(f"{param} must be an array, got {_show(value)}", param=param)
    try:
        a = np.asarray(value)
    except (ValueError, TypeError):
        raise InputTypeError(f"{param} must be an array, got {_show(value)}", param=param) from None
    if a.dtype == object or (kinds is not None and a.dtype.kind not in kinds):
        raise InputTypeError(f"{param} must be an array of {_kinds(kinds)}, got dtype {a.dtype}", param=param)
    dims = (ndim,) if isinstance(ndim, int) else ndim
    if dims is not None and a.ndim not in dims:
        raise InputError(f"{param} must have {' or '.join(map(str, dims))} dimensions, got shape {a.shape}",
                         param=param)
    if shape is not None and (a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape))):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InputError(f"{param} must have shape {want}, got {a.shape}", param=param)
    return a if dtype is None else a.astype(dtype, copy=False)


def _kinds(kinds: str | None) -> str:
    names = {"b": "booleans", "i": "integers", "u": "integers", "f": "floats"}
    return " or ".join(dict.fromkeys(names[k] for k in (kinds or "biuf")))


def size(value: object, param: str = "size", hi: int = 8192) -> tuple[int, int]:
    """An image size: an int W (square), a (W, H) pair, or text ``W`` / ``WxH``; sides 1..hi."""
    if isinstance(value, str):
        parts = value.strip().lower().split("x")
        if len(parts) > 2 or not all(p.strip().isdigit() for p in parts):
            raise InputError(f"{param} must be W or WxH, got {value!r}", param=param)
        value = tuple(int(p) for p in parts)
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        value = (value, value)
    if not isinstance(value, (tuple, list)) or len(value) not in (1, 2):
        raise InputTypeError(f"{param} must be an int W, a (W, H) pair or text 'WxH', got {_show(value)}", param=param)
    w = integer(value[0], param, 1, hi)
    h = integer(value[-1], param, 1, hi)
    return w, h


def grid(value: object, param: str = "grid") -> Any:
    """A footprint grid (``omaps.sampling.FootprintGrid``); an ``AlphaTest`` gives its ``grid()``."""
    from .alpha_test import AlphaTest
    from .sampling import FootprintGrid

    if isinstance(value, AlphaTest):
        return value.grid()
    if not isinstance(value, FootprintGrid):
        raise InputTypeError(f"{param} must be a FootprintGrid (AlphaTest.grid()) or an AlphaTest, got "
                             f"{_show(value)}", param=param)
    return value
