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
omaps.errors.InputTypeError: level must be an integer from 0 to 12, got '3'
>>> choice("2state", "format", ("4state", "2state"))
'2state'
"""

from __future__ import annotations

import collections.abc
import functools
import inspect
import math
import numbers
import os
import types
import typing
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

from .errors import InputError, InputTypeError

F = TypeVar("F", bound=Callable[..., Any])

__all__ = ["integer", "number", "boolean", "choice", "text", "path", "paths", "path_or_array", "paths_or_arrays",
           "array", "size", "input_name", "typed"]


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
        what = f"an integer {_range(lo, hi)}" if lo is not None and hi is not None else "an integer"
        raise InputTypeError(f"{param} must be {what}, got {_show(value)}", param=param)
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


# ---- the types of annotated parameters ------------------------------------------------------------

def typed(func: F) -> F:
    """``func`` with its arguments checked against its annotations on every call: an argument of
    another type raises an ``InputTypeError`` naming the parameter (``run must be a SchemeRun, got
    None``). For functions whose annotations say it all (values are the function's own checks);
    an annotation that cannot be resolved, ``Any``, ``object`` or a type variable checks nothing.
    A few microseconds a call: not for kernels called in loops."""
    sig = inspect.signature(func)
    hints: dict[str, Any] | None = None

    @functools.wraps(func)
    def checked(*args: Any, **kwargs: Any) -> Any:
        nonlocal hints
        if hints is None:
            hints = _resolved_hints(func, sig)
        try:
            bound = sig.bind(*args, **kwargs)
        except TypeError as exc:  # a missing or unknown argument: Python's own message, as an omaps error
            raise InputTypeError(f"{func.__name__}(): {exc}") from None
        for name, value in bound.arguments.items():
            hint = hints.get(name)
            if hint is not None and not _matches(value, hint):
                raise InputTypeError(f"{name} must be {_describe(hint)}, got {_show(value)}", param=name)
        return func(*args, **kwargs)

    return checked  # type: ignore[return-value]


def _resolved_hints(func: Callable[..., Any], sig: inspect.Signature) -> dict[str, Any]:
    """The parameters' annotations as objects; one that names what the module cannot resolve
    (an import only for type checkers) is left out."""
    out: dict[str, Any] = {}
    space = dict(getattr(func, "__globals__", {}))
    for name, p in sig.parameters.items():
        ann = p.annotation
        if ann is inspect.Parameter.empty or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        if isinstance(ann, str):
            try:
                ann = eval(ann, space)  # noqa: S307 - the module's own annotation text
            except NameError:  # a name imported only for type checkers: omaps' class of that name
                ann = _with_omaps_classes(ann, space)
            except Exception:  # noqa: BLE001 - unresolvable: not checked
                continue
            if ann is None and p.annotation != "None":
                continue
        out[name] = ann
    return out


def _with_omaps_classes(text: str, space: dict[str, Any]) -> Any:
    """Annotation ``text`` resolved with the classes of omaps' loaded modules it names (the one
    class of each name), or None."""
    import re
    import sys

    extra: dict[str, Any] = {}
    import builtins

    for word in set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text)) - set(space) - set(dir(builtins)):
        found = {id(c): c for name, mod in list(sys.modules.items()) if name.startswith("omaps") and mod is not None
                 for c in [getattr(mod, word, None)] if isinstance(c, type)}
        if len(found) == 1:
            extra[word] = next(iter(found.values()))
    try:
        return eval(text, {**space, **extra})  # noqa: S307 - the module's own annotation text
    except Exception:  # noqa: BLE001 - unresolvable: not checked
        return None


def _matches(value: object, hint: Any) -> bool:
    import numpy as np

    if hint is Any or hint is object or isinstance(hint, typing.TypeVar):
        return True
    if hint is None or hint is type(None):
        return value is None
    if hint is _ARRAY_LIKE:
        return value is not None and not isinstance(value, (str, bytes, dict, set, os.PathLike))
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is typing.Union or origin is types.UnionType:
        return any(_matches(value, a) for a in args)
    if origin is typing.Literal:
        return value in args
    if origin is not None:
        if origin in (Callable, collections.abc.Callable):
            return callable(value)
        if origin is list and isinstance(value, tuple):  # (a tuple serves where a list is read)
            origin = collections.abc.Sequence
        if not isinstance(origin, type) or not isinstance(value, origin):
            return not isinstance(origin, type)
        if origin in (list, collections.abc.Sequence) and len(args) == 1 and not isinstance(value, str):
            return all(_matches(v, args[0]) for v in typing.cast(Sequence[Any], value))
        return True
    if hint is float:
        return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    if hint is int:
        return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if hint is bool:
        return isinstance(value, (bool, np.bool_))
    if isinstance(hint, type):
        if getattr(hint, "_is_protocol", False):  # a protocol: what it needs, not a class
            return not getattr(hint, "_is_runtime_protocol", False) or isinstance(value, hint)
        return isinstance(value, hint)
    return True  # a construct not checked here


def _describe(hint: Any) -> str:
    if hint is None or hint is type(None):
        return "None"
    if hint is _ARRAY_LIKE:
        return "an array"
    origin = typing.get_origin(hint)
    if origin is typing.Union or origin is types.UnionType:
        return " or ".join(_describe(a) for a in typing.get_args(hint))
    if origin is typing.Literal:
        return "one of " + ", ".join(map(repr, typing.get_args(hint)))
    if origin is not None:
        args = typing.get_args(hint)
        name = getattr(origin, "__name__", str(origin))
        if name in ("list", "Sequence") and len(args) == 1:
            return f"a {name} of {_describe(args[0]).removeprefix('a ').removeprefix('an ')}"
        return f"a {name}"
    names = {int: "an integer", float: "a number", bool: "True or False", str: "a string"}
    if hint in names:
        return names[hint]
    return f"a {getattr(hint, '__name__', str(hint))}"


def _array_like() -> Any:
    from numpy.typing import ArrayLike

    return ArrayLike


_ARRAY_LIKE = _array_like()
