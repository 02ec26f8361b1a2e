"""The deck's experiment "higher resolution => greater savings", on the real shared corpus."""

import numpy as np
import pytest

from conftest import needs_shared, real_textures
from omaps.corpus.evaluate import evaluate_many, mean_results
from omaps.schemes import DEFAULT_SCHEMES, parse_schemes

pytestmark = needs_shared


@pytest.fixture(scope="module")
def corpus():
    paths = real_textures(min_size=64)
    schemes = parse_schemes(DEFAULT_SCHEMES + ("sq128", "tri6"))
    results, _ = evaluate_many(paths, schemes, jobs=2, progress=False)
    return results, mean_results(results, [s.name for s in schemes])


def test_higher_resolution_greater_savings(corpus):
    results, mean = corpus
    sq = [mean[f"sq{n}"]["savings"] for n in (4, 8, 16, 32, 64, 128)]
    tri = [mean[f"tri{lv}"]["savings"] for lv in (2, 3, 4, 5, 6)]
    assert np.all(np.diff(sq) > 0) and np.all(np.diff(tri) > 0)
    # ... though the gains diminish: the last doubling gains less than an early one
    assert sq[-1] - sq[-2] < sq[2] - sq[1]
    assert tri[-1] - tri[-2] < tri[1] - tri[0]
    assert sq[-1] < mean["texel"]["savings"]


def test_per_texture_monotone(corpus):
    results, _ = corpus
    for r in results:
        for a, b in [("sq16", "sq32"), ("sq32", "sq64"), ("tri3", "tri4"), ("tri4", "tri5")]:
            assert r.savings[a] <= r.savings[b] <= r.savings["texel"], r.name


def test_square_pairs_beat_per_triangle_maps_at_equal_bits(corpus):
    """sqN costs 2*N^2 bits and triL 4^(L+1): compare each sqN with the per-triangle curve
    interpolated (linearly in log2 bits) at the same storage, inside the range measured."""
    _, mean = corpus
    tri_bits = np.log2([mean[f"tri{lv}"]["bits"] for lv in range(2, 7)])
    tri_sav = [mean[f"tri{lv}"]["savings"] for lv in range(2, 7)]
    for n in (8, 16, 32, 64):
        at_same_bits = np.interp(np.log2(mean[f"sq{n}"]["bits"]), tri_bits, tri_sav)
        assert mean[f"sq{n}"]["savings"] > at_same_bits, n
    # the lossless ceiling of a 256-bit compressed 16x16 pair against tri3's 256 bits (about 1.36)
    ratio = mean["sq16"]["savings"] / mean["tri3"]["savings"]
    assert 1.2 < ratio < 1.6
