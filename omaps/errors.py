"""The errors of omaps' Python API: bad input raises an :class:`InputError` (a ``ValueError``),
an argument of the wrong type an :class:`InputTypeError` (an ``InputError`` and a ``TypeError``).

Messages name the file (``path``) or the parameter (``param``) in Python terms (``level must be
an integer from 0 to 12, got 13``); the command line prints ``omaps: error: <path>: <problem>``
and names its own option for the parameter (``--level must be ...``).
"""

from __future__ import annotations

import numbers
import os
import re
from typing import Any


class InputError(ValueError):
    """Bad input: a file that cannot be used, or an argument out of range.

    Attributes
    ----------
    problem : str
        What is wrong, without the path.
    path : str or None
        The file the problem is in, if any.
    param : str or tuple of str or None
        The parameter(s) the problem names, in Python terms (``"level"``), if any; the message
        names it as written here, so that the command line can name its option instead.
    """

    def __init__(self, problem: str, path: str | os.PathLike[str] | None = None, *,
                 param: str | tuple[str, ...] | None = None) -> None:
        self.path = None if path is None else str(path)
        self.param = param
        self.template = problem  # the parameters as ``{name}`` where a plain word would be ambiguous
        self.problem = self.named({})
        super().__init__(f"{self.path}: {self.problem}" if self.path else self.problem)

    @property
    def params(self) -> tuple[str, ...]:
        """The parameters the problem names (``param`` as a tuple)."""
        return (self.param,) if isinstance(self.param, str) else tuple(self.param or ())

    def named(self, names: dict[str, str]) -> str:
        """The problem with its parameters named as ``names`` says (``{"level": "--level"}``;
        others as in Python): a ``{param}`` of the text, else its first whole-word occurrence."""
        text = self.template
        for p in self.params:
            token = "{" + p + "}"
            if token in text:
                text = text.replace(token, names.get(p, p))
            elif p in names:
                text = re.sub(rf"(?<![\w\-]){re.escape(p)}(?![\w\-])", lambda _: names[p], text, count=1)
        return text

    def __reduce__(self) -> tuple[Any, ...]:  # survive the trip back from a worker process
        return (_rebuild, (type(self), self.template, self.path, self.param))


class InputTypeError(InputError, TypeError):
    """An argument of the wrong type (a string where a number is expected, an ``AlphaTest``
    where a state grid is expected): an :class:`InputError` and a ``TypeError``."""


def _rebuild(cls: type[InputError], problem: str, path: str | None, param: str | tuple[str, ...] | None) -> InputError:
    return cls(problem, path, param=param)


def check_count(value: object, param: str = "jobs") -> int | None:
    """``value`` (a worker or thread count) as an int, or None; an :class:`InputError` naming
    ``param`` unless it is None or an integer >= 1.

    >>> check_count(2)
    2
    >>> check_count(0, "threads")
    Traceback (most recent call last):
    ...
    omaps.errors.InputError: threads must be >= 1, got 0
    """
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputTypeError(f"{param} must be an integer >= 1, got {value!r:.60}", param=param)
    if value < 1:
        raise InputError(f"{param} must be >= 1, got {value}", param=param)
    return int(value)
