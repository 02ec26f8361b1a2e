"""Plain-text tables and counts, as every command and result object prints them.

Example::

    >>> from omaps.text import format_table, plural
    >>> print(format_table(["scheme", "tests/ray"], [["none", "1.500"], ["vq4", "0.250"]]))
    scheme  tests/ray
    none        1.500
    vq4         0.250
    >>> plural(1, "file"), plural(3, "family", "families")
    ('1 file', '3 families')
"""

from __future__ import annotations

__all__ = ["format_table", "format_row", "plural", "count"]


def plural(n: int, noun: str, plural_noun: str | None = None) -> str:
    """``n`` and the noun in the number it takes: ``plural(1, "file")`` is "1 file", ``plural(3,
    "file")`` "3 files", ``plural(2, "family", "families")`` "2 families"."""
    return f"{n} {noun if n == 1 else plural_noun or noun + 's'}"


def count(n: int, noun: str, plural_noun: str | None = None) -> str:
    """``plural`` with thousands separators: "1 triangle", "4,152 triangles"."""
    return f"{n:,}" + plural(n, noun, plural_noun)[len(str(n)):]


def format_row(cells, widths) -> str:
    """One row: the first cell left-aligned, the others right-aligned, two spaces apart."""
    return "  ".join(str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(cells, widths)))


def format_table(header: list, rows: list) -> str:
    """A header and rows as aligned columns (one line each, no trailing newline)."""
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    return "\n".join(format_row(r, widths) for r in [header] + rows)
