"""The tracer's 2-state mode: square maps with every C cell resolved to O or T, so no ray ever
runs the any-hit shader (the deck's future work "hash/dither {O, C, T} -> {O, T}").

This is not conservative: it trades exact visibility for zero alpha tests, as hardware that
forces 2-state micromaps does. Each C cell of a pair's square map (a raw or a codec's decoded
map) becomes O or T by ``omaps.promotion``'s rule on the cell's opaque fraction
(``coverage.cell_fractions``: K x K sample points of the cell, mapped through the pair's
triangles, tested by the material's alpha test), with ``hashed`` comparing it to a threshold
hashed from the cell centre's texel position. T and O cells keep their states.
"""

from __future__ import annotations

import numpy as np

from .. import states
from ..codecs import get_codec
from ..coverage import cell_fractions
from ..promotion import PROMOTIONS, resolve_regions
from ..scene.alpha import distinct_rows, pair_corner_uvs
from .maps import SchemeMaps, by_material, dedupe_maps

from ..errors import InputError

__all__ = ["MODES", "two_state_maps", "decoded_pair_maps", "parse_modes"]

MODES = PROMOTIONS  # nearest (majority), opaque, transparent, hashed


def parse_modes(text) -> list[str]:
    """The 2-state rules of ``--two-state`` text (comma-separated ``MODES`` or ``all``; empty or
    None: none), or a list of them, checked and without repeats."""
    if text is None or (isinstance(text, (str, list, tuple)) and not text):
        return []
    if isinstance(text, str):
        modes = (list(MODES) if text.strip().lower() == "all"
                 else [m.strip().lower() for m in text.split(",") if m.strip()])
    elif isinstance(text, (list, tuple)) and all(isinstance(m, str) for m in text):
        modes = [m.strip().lower() for m in text]
    else:
        from ..errors import InputTypeError

        raise InputTypeError(f"two_state must be comma-separated rules or a list of them, got {type(text).__name__}",
                             param="two_state")
    bad = [m for m in modes if m not in MODES]
    if bad or not modes:
        raise InputError(f"two_state: unknown rule {bad[0] if bad else text!r} (choose from {', '.join(MODES)} "
                         "or all)", param="two_state")
    return list(dict.fromkeys(modes))


def decoded_pair_maps(sm: SchemeMaps, at) -> np.ndarray:
    """The (P, n, n) map every pair's hits read in a square scheme."""
    if sm.kind != "square":
        raise ValueError(f"2-state maps need a square scheme, not {sm.kind!r}")
    uniq = sm.codec.decode_many(sm.data.reshape(-1, sm.row_bytes))  # type: ignore[attr-defined]
    return uniq[sm.rows[at.pair_first]]


def two_state_maps(prep, sm: SchemeMaps, mode: str, seed: int = 0, cache: dict | None = None) -> SchemeMaps:
    """A raw square ``SchemeMaps`` (states 0 and 1 only) for square scheme ``sm``."""
    if mode not in MODES:
        raise ValueError(f"unknown 2-state mode {mode!r} (choose from {', '.join(MODES)})")
    at = prep.alpha
    n = sm.param
    cache = {} if cache is None else cache
    if "pairs" not in cache:  # the same for every scheme and rule
        uv, has_b, mat = pair_corner_uvs(at)
        cache["pairs"] = (uv, has_b, mat) + distinct_rows(uv, has_b, mat)
    uv, has_b, mat, reps, inverse = cache["pairs"]
    key = ("fractions", n)
    if key not in cache:
        frac = np.zeros((len(reps), n, n))
        centre = np.zeros((len(reps), n, n, 2))
        for m, sel in by_material(mat[reps]):
            frac[sel], centre[sel] = cell_fractions(prep.tests[m], uv[reps[sel]], has_b[reps[sel]], n)
        cache[key] = (frac, centre)
    frac, centre = cache[key]
    three = decoded_pair_maps(sm, at)[reps]
    two = resolve_regions(three, frac, centre, mode, seed)
    if np.any((three != states.C) & (two != three)):
        raise RuntimeError("internal error: a 2-state resolution changed a known cell")
    uniq, inv_u = dedupe_maps(two)
    rows = inv_u[inverse[at.pair]].astype(np.int32)
    raw = get_codec(f"sq{n}")
    blocks, _ = raw.encode_many(uniq)
    n_pairs = len(at.pair_first)
    return SchemeMaps(f"{sm.name}/{mode}", "square", n, rows, blocks.ravel().copy(), raw.block_bytes,
                      n_pairs * n * n // 8, len(uniq), 1.0, raw)
