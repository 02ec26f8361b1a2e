"""The corpus evaluation: every scheme's savings and bits on every texture, in parallel.

Each texture covers the corpus pair (``omaps.pair``); a scheme's map is baked by the core bakers
(``bake.pair_maps``), stored through its codec where it has one, and its savings is the fraction
of hits, uniform over the pair's area, that land in a T or O region.

Example::

    >>> from omaps.corpus import EvalConfig, default_corpus, evaluate_texture
    >>> from omaps.schemes import parse_schemes
    >>> r = evaluate_texture(default_corpus()[0], parse_schemes("sq16,tri3"), EvalConfig())
    >>> sorted(r.savings) == ["sq16", "tri3"] and 0 < r.savings["sq16"] < 1
    True
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from .. import states
from ..alpha_test import StateRule
from ..bake import bake_pair_triangles, bake_square, known_fraction, texel_limit
from .. import checks
from ..codecs.registry import check_choice
from ..errors import InputError, InputTypeError
from ..names import EFFORTS, ENCODERS
from ..schemes import EVAL_KINDS, Scheme, parse_schemes
from ..texture import AlphaTexture, as_texture, load_alpha
from ..workers import process_pool
from ..checks import typed

__all__ = ["EvalConfig", "TextureResult", "evaluate_texture", "evaluate_many", "mean_results", "scheme_map",
           "scheme_bits"]


@dataclass(frozen=True)
class EvalConfig:
    rule: StateRule = StateRule()
    filter: str = "nearest"
    wrap: str = "clamp"
    channel: str | None = None
    encoder: str | None = None  # for codec schemes named without a variant
    effort: str | None = None

    def __post_init__(self) -> None:
        from ..names import FILTERS, WRAP_MODES

        if not isinstance(self.rule, StateRule):
            raise InputTypeError(f"rule must be an omaps.StateRule, got {type(self.rule).__name__}", param="rule")
        checks.choice(self.filter, "filter", FILTERS)
        checks.choice(self.wrap, "wrap", WRAP_MODES)
        if self.channel is not None and (isinstance(self.channel, bool) or not isinstance(self.channel, (str, int))):
            raise InputTypeError(f"channel must be a band name or an index, got {type(self.channel).__name__}",
                                 param="channel")
        check_choice("encoder", self.encoder, ENCODERS)
        check_choice("effort", self.effort, tuple(EFFORTS))

    def test(self, texture: AlphaTexture):
        """The alpha test of a texture under these rules, filter and addressing."""
        return self.rule.alpha_test(texture, self.filter, self.wrap)

    def grid(self, texture: AlphaTexture):
        """The footprint grid of a texture under these states, filter and addressing."""
        return self.test(texture).grid()

    def settings(self) -> dict:
        return {**self.rule.settings(), "filter": self.filter, "wrap": self.wrap, "channel": self.channel,
                "encoder": self.encoder, "effort": self.effort}


def scheme_map(scheme: Scheme, grid) -> np.ndarray:
    """The map a scheme stores for the corpus pair (decoded when compressed): (N, N) square,
    (2, 4**L) micromaps, or the footprint cells' states for ``texel``."""
    if scheme.kind == "texel":
        return states.FLAG_TO_STATE[grid.cells_within_texture()[0]]
    if scheme.kind == "micromap":
        m = bake_pair_triangles(grid, scheme.level)
        if scheme.representation == "raw":
            return m
        return _hierarchical(scheme, m)[0]  # lossless: the decoded maps equal the baked ones
    codec = scheme.codec
    assert codec is not None, scheme  # a square scheme has its codec
    m = bake_square(grid, codec.map_size)
    if not codec.compressed:
        return m
    return codec.encode_many(m[None], scheme.encoder, scheme.effort)[1][0]


def _hierarchical(scheme: Scheme, m: np.ndarray) -> tuple[np.ndarray, int]:
    """A hierarchical micromap scheme's pair (2, 4**L) encoded and decoded again: (the decoded
    micromaps, the bits stored). ``succinct``: the two triangles' blobs, each its exact bits;
    ``csm``: one blob of both triangles' micromaps with common subtrees merged."""
    from ..codecs import csm_bits, csm_decode, csm_encode, succinct_decode, succinct_encode_many

    level = scheme.level
    if scheme.representation == "succinct":
        data, starts, bits = succinct_encode_many(m, level)
        decoded = np.stack([succinct_decode(data[starts[i]:starts[i + 1]], level) for i in range(len(m))])
        total = int(bits.sum())
    else:
        blob, n_nodes = csm_encode(m, level)
        decoded = csm_decode(blob, level, len(m))
        total = csm_bits(n_nodes, len(m))
    if not np.array_equal(decoded, m):
        raise RuntimeError(f"internal error: {scheme.name} did not decode to the baked micromaps")
    return decoded, total


def scheme_bits(scheme: Scheme, width: int, height: int, m: np.ndarray) -> int:
    """Storage bits of a scheme's map of the corpus pair: ``Scheme.bits_for``, or for a
    hierarchical micromap (``succinctL``, ``csmL``) the exact size of its encoding of ``m``."""
    bits = scheme.bits_for(width, height)
    if bits is None:
        bits = _hierarchical(scheme, m)[1]
    return int(bits)


def scheme_savings(scheme: Scheme, grid, m: np.ndarray) -> float:
    """Savings of a map the scheme made (regions of equal area; border cells of a linear
    footprint have half area, which ``texel_limit`` weighs)."""
    return texel_limit(grid) if scheme.kind == "texel" else known_fraction(m)


@dataclass
class TextureResult:
    name: str
    width: int
    height: int
    savings: dict[str, float]
    bits: dict[str, int]
    maps: dict[str, np.ndarray] = field(default_factory=dict)  # only when asked for
    alpha: np.ndarray | None = None  # the coverage values, only when maps are kept
    path: str | None = None


@typed
def evaluate_texture(texture, schemes, config: EvalConfig = EvalConfig(),
                     keep_maps: bool = False) -> TextureResult:
    """Every scheme's savings and bits on one texture (the corpus pair over its whole area).

    Parameters
    ----------
    texture : AlphaTexture, numpy array or path
        What ``omaps.texture.as_texture`` takes: (H, W) or (H, W, C) uint8 / uint16 / bool /
        float arrays (greyscale, LA, RGBA; RGB with ``config.channel``), or an image file
        (read through ``config.channel``).
    schemes : str or list
        Scheme names (``"sq16,vq2,tri3"`` or a list) or ``Scheme`` objects.
    config : EvalConfig
        The state rule, filter, wrap, channel and encoder settings.
    keep_maps : bool
        Keep each scheme's map (decoded) and the coverage values in the result.

    Returns
    -------
    TextureResult
        ``savings[name]`` (the fraction of uniformly spread hits that land in T or O regions)
        and ``bits[name]`` per scheme (for ``succinctL`` and ``csmL`` the exact size of this
        texture's pair, which varies with its states).

    Examples
    --------
    >>> import numpy as np
    >>> y, x = np.mgrid[:64, :64]
    >>> disc = np.where((x - 31.5) ** 2 + (y - 31.5) ** 2 < 24 ** 2, 255, 0).astype(np.uint8)
    >>> r = evaluate_texture(disc, "sq16,tri3")
    >>> r.savings, r.bits
    ({'sq16': 0.890625, 'tri3': 0.734375}, {'sq16': 512, 'tri3': 256})
    >>> r = evaluate_texture(disc, "tri5,succinct5,csm5")   # lossless: tri5's savings, fewer bits
    >>> r.savings["succinct5"] == r.savings["csm5"] == r.savings["tri5"], r.bits
    (True, {'tri5': 4096, 'succinct5': 996, 'csm5': 2230})
    """
    if not isinstance(config, EvalConfig):
        raise InputTypeError(f"config must be an omaps.EvalConfig, got {type(config).__name__}", param="config")
    keep_maps = checks.boolean(keep_maps, "keep_maps")
    schemes = parse_schemes(schemes, EVAL_KINDS, config.encoder, config.effort, "evaluate_texture")
    if not isinstance(texture, AlphaTexture):  # (an AlphaTexture was read with its channel already)
        texture = as_texture(texture, channel=config.channel)
    grid = config.grid(texture)
    savings, bits, kept = {}, {}, {}
    for s in schemes:
        m = scheme_map(s, grid)
        savings[s.name] = scheme_savings(s, grid, m)
        bits[s.name] = scheme_bits(s, texture.width, texture.height, m)
        if keep_maps:
            kept[s.name] = m
    return TextureResult(texture.name, texture.width, texture.height, savings, bits, kept,
                         texture.values if keep_maps else None)


def _work(item, scheme_names, config, keep_maps, min_size):
    """Load (if a path) and evaluate one texture; None when it is below ``min_size``.
    Schemes travel by name: worker processes rebuild them from the registry."""
    schemes = parse_schemes(scheme_names, EVAL_KINDS, config.encoder, config.effort)
    path = None
    if isinstance(item, AlphaTexture):
        tex = item
    elif isinstance(item, tuple):  # (name, array): read through the channel here
        tex = AlphaTexture.from_array(item[0], item[1], config.channel)
    else:
        path = item
        tex = load_alpha(item, config.channel)
    if min(tex.width, tex.height) < min_size:
        return None
    r = evaluate_texture(tex, schemes, config, keep_maps)
    r.path = path
    return r


def warm_up(schemes: list[Scheme], config: EvalConfig) -> None:
    """Compile the kernels once in this process, so the workers (spawned: numba's threads do not
    survive a fork) load them from numba's cache instead of each compiling them."""
    tex = AlphaTexture("warm-up", np.array([[0, 128], [255, 0]], dtype=np.uint8), 255)
    evaluate_texture(tex, schemes, config)


@typed
def evaluate_many(items, schemes: list[Scheme], config: EvalConfig = EvalConfig(), jobs: int | None = None,
                  keep_maps: bool = False, min_size: int = 0, progress: bool = True, unreadable: list | None = None,
                  errors: dict | None = None):
    """Evaluate textures (AlphaTexture objects, paths, or (name, array) pairs). Returns
    (results, skipped_small):
    results in input order; paths of textures below ``min_size`` in ``skipped_small``.

    A texture that cannot be read raises its ``InputError``, unless ``unreadable`` is a list:
    then it gets ``(path, problem)`` and the others go on."""
    items = list(items)
    names = [s.name for s in schemes]
    jobs = os.cpu_count() or 1 if jobs is None else max(1, int(jobs))
    jobs = min(jobs, max(1, len(items)))
    bar = tqdm(total=len(items), desc="textures", unit="tex", disable=not progress, leave=False)
    out = []

    def take(get):
        try:
            out.append(get())
        except InputError as exc:
            if unreadable is None:
                raise
            out.append(exc)
        bar.update()

    try:
        if jobs == 1:
            for it in items:
                take(lambda: _work(it, names, config, keep_maps, min_size))
        else:
            warm_up(schemes, config)
            with process_pool(jobs) as pool:
                futures = [pool.submit(_work, it, names, config, keep_maps, min_size) for it in items]
                for f in futures:
                    take(f.result)
    finally:
        bar.close()
    results = [r for r in out if isinstance(r, TextureResult)]
    skipped = [_label(it) for it, r in zip(items, out) if r is None]
    if unreadable is not None:
        unreadable += [(_label(it), r.problem) for it, r in zip(items, out) if isinstance(r, InputError)]
        if errors is not None:  # the errors themselves (their parameter), by the input's label
            errors.update((_label(it), r) for it, r in zip(items, out) if isinstance(r, InputError))
    return results, skipped


def _label(item) -> str:
    if isinstance(item, tuple):
        return str(item[0])
    return item.name if isinstance(item, AlphaTexture) else str(item)


@typed
def mean_results(results: list[TextureResult], scheme_names: list[str]) -> dict[str, dict]:
    """Mean savings and mean bits per scheme over the textures (each texture weighs the same)."""
    out = {}
    for name in scheme_names:
        if results:
            bits = [r.bits[name] for r in results]
            mean_bits = bits[0] if len(set(bits)) == 1 else float(np.mean(bits))
            out[name] = {"savings": float(np.mean([r.savings[name] for r in results])), "bits": mean_bits}
    return out
