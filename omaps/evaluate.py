"""The corpus evaluation: every scheme's savings and bits on every texture, in parallel."""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from .sampling import footprint_grid
from .schemes import Scheme, parse_schemes
from .texel_states import StateRule
from .texture import AlphaTexture, load_alpha


@dataclass(frozen=True)
class EvalConfig:
    rule: StateRule = StateRule()
    filter: str = "nearest"
    wrap: str = "clamp"
    channel: str | None = None

    def grid(self, texture: AlphaTexture):
        """The footprint grid of a texture under these states, filter and addressing."""
        return footprint_grid(self.rule.classify(texture), self.filter, self.wrap)


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


def evaluate_texture(texture: AlphaTexture, schemes: list[Scheme], config: EvalConfig = EvalConfig(),
                     keep_maps: bool = False) -> TextureResult:
    grid = config.grid(texture)
    savings, bits, kept = {}, {}, {}
    for s in schemes:
        m = s.bake(grid)
        savings[s.name] = s.savings_of(grid, m)
        bits[s.name] = int(s.bits_for(texture.width, texture.height))
        if keep_maps:
            kept[s.name] = m
    return TextureResult(texture.name, texture.width, texture.height, savings, bits, kept,
                         texture.values if keep_maps else None)


def _work(item, scheme_names, config, keep_maps, min_size):
    """Load (if a path) and evaluate one texture; None when it is below ``min_size``.
    Schemes travel by name: worker processes rebuild them from the registry."""
    schemes = parse_schemes(scheme_names)
    path = None
    if isinstance(item, AlphaTexture):
        tex = item
    else:
        path = item
        tex = load_alpha(item, config.channel)
    if min(tex.width, tex.height) < min_size:
        return None
    r = evaluate_texture(tex, schemes, config, keep_maps)
    r.path = path
    return r


def warm_up(schemes: list[Scheme], config: EvalConfig) -> None:
    """Compile the kernels once in this process, so forked workers start with them."""
    tex = AlphaTexture("warm-up", np.array([[0, 128], [255, 0]], dtype=np.uint8), 255)
    evaluate_texture(tex, schemes, config)


def evaluate_many(items, schemes: list[Scheme], config: EvalConfig = EvalConfig(), jobs: int | None = None,
                  keep_maps: bool = False, min_size: int = 0, progress: bool = True):
    """Evaluate textures (AlphaTexture objects or paths). Returns (results, skipped_small):
    results in input order; paths of textures below ``min_size`` in ``skipped_small``."""
    items = list(items)
    names = [s.name for s in schemes]
    jobs = os.cpu_count() or 1 if jobs is None else max(1, int(jobs))
    jobs = min(jobs, max(1, len(items)))
    bar = tqdm(total=len(items), desc="textures", unit="tex", disable=not progress, leave=False)
    out = []
    try:
        if jobs == 1:
            for it in items:
                out.append(_work(it, names, config, keep_maps, min_size))
                bar.update()
        else:
            warm_up(schemes, config)
            with ProcessPoolExecutor(max_workers=jobs) as pool:
                futures = [pool.submit(_work, it, names, config, keep_maps, min_size) for it in items]
                for f in futures:
                    out.append(f.result())
                    bar.update()
    finally:
        bar.close()
    results = [r for r in out if r is not None]
    skipped = [_label(it) for it, r in zip(items, out) if r is None]
    return results, skipped


def _label(item) -> str:
    return item.name if isinstance(item, AlphaTexture) else str(item)


def mean_results(results: list[TextureResult], scheme_names: list[str]) -> dict[str, dict]:
    """Mean savings and mean bits per scheme over the textures (each texture weighs the same)."""
    out = {}
    for name in scheme_names:
        if results:
            bits = [r.bits[name] for r in results]
            mean_bits = bits[0] if len(set(bits)) == 1 else float(np.mean(bits))
            out[name] = {"savings": float(np.mean([r.savings[name] for r in results])), "bits": mean_bits}
    return out
