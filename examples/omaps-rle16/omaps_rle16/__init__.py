"""omaps-rle16: an example codec plug-in for omaps.

``rle16`` stores a 16x16 opacity map in 64 bytes as runs of states along a serpentine scan
(``omaps_rle16.block``: the layout, the total decoder, the random-access lookup), made by a
conservative encoder that turns runs into C until they fit (``omaps_rle16.encode``).

omaps finds it through the entry point this distribution declares in its ``pyproject.toml``::

    [project.entry-points."omaps.codecs"]
    rle16 = "omaps_rle16:entries"

``entries()`` returns the codec's declaration. Nothing here imports numba or compiles anything:
the registry calls ``lookup()`` and ``make()`` only when a command uses the codec.
"""

from __future__ import annotations

from omaps.codecs import CodecEntry, CompileFamily

__all__ = ["entries"]

NAME = "rle16"


def _lookup():
    from .block import lookup

    return lookup


def _make():
    from omaps.codecs import square_codec

    from . import block, encode

    return square_codec(NAME, block.SIZE, block.BLOCK_BYTES, encode.encode_many, block.decode, block.lookup,
                        decode_many=block.decode_many)


def entries() -> list[CodecEntry]:
    """The codecs of this package: rle16."""
    return [CodecEntry(NAME, 16, 64, _lookup, _make,
                       families=("square", CompileFamily(NAME, ("omaps_rle16.block", "omaps_rle16.encode"), 20)),
                       budget=True, budget_default=False,
                       description="runs of states along a serpentine scan of 16x16 cells, in 512 bits")]
