"""One exception type for bad input, so the CLI can report it as ``file: problem`` and exit 2."""


class InputError(ValueError):
    """Bad input: a file that cannot be used, or parameters out of range."""

    def __init__(self, problem: str, path=None):
        self.path = None if path is None else str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}" if self.path else problem)

    def __reduce__(self):  # survive the trip back from a worker process
        return (type(self), (self.problem, self.path))


def check_count(value, option: str = "--jobs") -> None:
    """Raise :class:`InputError` unless ``value`` (a worker or thread count) is None or >= 1.

    >>> check_count(2)
    >>> check_count(0, "--threads")
    Traceback (most recent call last):
    ...
    omaps.errors.InputError: --threads must be >= 1, got 0
    """
    if value is not None and value < 1:
        raise InputError(f"{option} must be >= 1, got {value}")
