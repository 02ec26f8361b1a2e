"""VQ4-synth: the synthesised index-2 vector carried by the codebook's order, a total decoder
checked against one written from docs/FORMAT.md, random access, a conservative encoder never
below VQ4's, the corpus, the command line."""

import json
from itertools import permutations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import needs_shared, real_textures
from omaps import states
from omaps.alpha_test import StateRule
from omaps.bake import bake_square, known_fraction
from omaps.cli import main
from omaps.codecs import get_codec, vq4_block, vq4_encode, vq4_synth_block as sb, vq4_synth_encode as se
from omaps.codecs.vq4_block import VQ4Block
from omaps.sampling import footprint_grid
from omaps.texture import load_alpha
from omaps.codecs.bits import kernel_bytes
from test_vq4 import _thirteen, blob_maps, random_maps, reference_decode

T, O, C = states.T, states.O, states.C
SIZES = [17, 17, 17, 18, 18] + [20] * 8
POS = [256 + sum(SIZES[:j]) for j in range(13)]


def _rank(seq):
    """Lehmer rank by brute force: the position of ``seq`` among the sorted permutations of its
    (distinct) values."""
    return sorted(permutations(sorted(seq))).index(tuple(seq))


def reference_synth(block: bytes) -> np.ndarray:
    """The map from FORMAT.md alone: VQ4's (test_vq4's reference decoder), then index 2 shows the
    two-value vector x = 6 (rho - 1) + sigma when the general codes are distinct and rho >= 1."""
    x = int.from_bytes(block, "little")

    def field(pos, n):
        return (x >> pos) & ((1 << n) - 1)

    out = reference_decode(block)
    gen = [field(POS[j], 20) for j in range(5, 13)]
    if len(set(gen)) < 8 or _rank(gen) == 0:
        return out
    two = [field(POS[j], 17) for j in range(3)]
    ranks = {p: i for i, p in enumerate(sorted(set(permutations(range(3)))))}
    order = tuple(int(np.argsort(np.argsort(two, kind="stable"), kind="stable")[i]) for i in range(3))
    sigma = ranks[order]  # ties: later equal codes count as larger, as a stable order has them
    code = 6 * (_rank(gen) - 1) + sigma
    if code >= 1 << 17:
        return out
    vec = np.array([[C if code >> (1 + 4 * ey + ex) & 1 else (O if code & 1 else T) for ex in range(4)]
                    for ey in range(4)], dtype=np.uint8)
    for v in range(64):
        if field(4 * v, 4) != 2:
            continue
        vy, vx = divmod(v, 8)
        q = 2 * (vy // 4) + vx // 4
        t = field(503 + 3 * (q - 1), 3) if q else 0
        shown = vec
        if t & 4:
            shown = np.fliplr(shown)
        if t & 2:
            shown = np.flipud(shown)
        if t & 1:
            shown = np.rot90(shown)
        out[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = shown
    return out


def _lookup_all(data):
    blk = kernel_bytes(data)
    return np.array([[sb.lookup(blk, x, y) for x in range(32)] for y in range(32)], dtype=np.uint8)


@settings(max_examples=150, deadline=None)
@given(st.binary(min_size=64, max_size=64))
def test_decoder_is_total_and_agrees(data):
    m = sb.decode(data)
    assert m.shape == (32, 32) and m.max() <= 2
    np.testing.assert_array_equal(m, reference_synth(data))
    np.testing.assert_array_equal(_lookup_all(data), m)
    back = sb.VQ4SynthBlock.unpack(data)
    np.testing.assert_array_equal(sb.decode(back.pack()), m)  # the order moves, the map does not


def test_random_blocks_use_both_meanings(rng):
    """Both meanings of index 2 occur among random blocks (the reference test exercises both)."""
    codes = [sb.synth_code(rng.integers(0, 256, 64).astype(np.uint8)) for _ in range(200)]
    assert sum(c == sb.NO_EXTRA for c in codes) > 20 and sum(c != sb.NO_EXTRA for c in codes) > 20


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, (1 << 20) - 1), min_size=8, max_size=8, unique=True),
       st.lists(st.integers(0, (1 << 17) - 1), min_size=3, max_size=3, unique=True),
       st.integers(-1, (1 << 17) - 1), st.integers(0, 2 ** 32))
def test_arrange_carries_the_extra(gen, two, extra, seed):
    rng = np.random.default_rng(seed)
    ent = np.array(two + [int(rng.integers(0, 1 << 18)), int(rng.integers(0, 1 << 18))] + gen)
    blk = VQ4Block(rng.integers(0, 16, 64), ent, rng.integers(0, 8, 3))
    data = sb.VQ4SynthBlock(blk, extra).pack()
    assert sb.synth_code(kernel_bytes(data)) == extra
    assert sb.VQ4SynthBlock.unpack(data).extra == extra
    # every vector but index 2's shows what VQ4 shows
    plain = blk.decode()
    got = sb.decode(data)
    for v in np.flatnonzero(blk.indices != 2):
        vy, vx = divmod(int(v), 8)
        sl = np.s_[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4]
        np.testing.assert_array_equal(got[sl], plain[sl])
    assert sb.lehmer_rank(np.array(gen)) == _rank(gen)


@settings(max_examples=80, deadline=None)
@given(st.permutations(list(range(8))).filter(lambda p: p != list(range(8))),
       st.lists(st.integers(0, 2), min_size=3, max_size=3), st.integers(0, 2 ** 32))
def test_blocks_with_equal_two_value_codes_pack_back(order, two, seed):
    """A block whose general codes are distinct and out of order carries a synthesised vector even
    when two of its two-value codes are equal (the decoder ranks ties as not smaller): unpacking
    such stored bytes and packing them again keeps the extra and the map."""
    rng = np.random.default_rng(seed)
    gen = np.sort(rng.choice(1 << 20, 8, replace=False))[order]
    ent = np.array([int(c) for c in two] + [int(rng.integers(0, 1 << 18)) for _ in range(2)] + gen.tolist())
    data = VQ4Block(rng.integers(0, 16, 64), ent, rng.integers(0, 8, 3)).pack()  # stored as is
    m = sb.decode(data)
    back = sb.VQ4SynthBlock.unpack(data)
    again = back.pack()
    assert sb.VQ4SynthBlock.unpack(again).extra == back.extra
    np.testing.assert_array_equal(sb.decode(again), m)
    np.testing.assert_array_equal(sb.decode(again), reference_synth(data))


def test_equal_two_value_codes_example():
    """The case that raised: general codes with the last two swapped (rank 1), two-value codes
    1, 1, 0 (rank 3): index 2 shows two-value code 6 (1 - 1) + 3 = 3."""
    gen = [13, 14, 15, 16, 17, 18, 20, 19]
    blk = VQ4Block(np.full(64, 2), np.array([1, 1, 0, 0, 0] + gen), [0, 0, 0])
    data = blk.pack()
    back = sb.VQ4SynthBlock.unpack(data)
    assert back.extra == 3
    np.testing.assert_array_equal(sb.decode(back.pack()), sb.decode(data))


def test_extra_needs_distinct_codes():
    blk = VQ4Block(np.zeros(64), np.zeros(13, np.int64), [0, 0, 0])
    with pytest.raises(ValueError, match="distinct"):
        sb.VQ4SynthBlock(blk, 5).pack()
    assert sb.decode(sb.VQ4SynthBlock(blk).pack()).max() == T  # plain VQ4: equal codes are fine


@pytest.mark.parametrize("encoder, effort", [("paper", "medium"), ("best", "fast"), ("best", "medium")])
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(m=st.one_of(random_maps, blob_maps()))
def test_encoder_is_conservative_and_never_below_vq4(m, encoder, effort):
    data = se.encode(m, encoder, effort).pack()
    d = reference_synth(data)
    assert ((d == m) | (d == C)).all()  # brute force: every cell equal or C
    np.testing.assert_array_equal(sb.decode(data), d)
    assert (d != C).sum() >= (vq4_encode.encode(m, encoder, effort).decode() != C).sum()


def test_uniform_maps_are_lossless():
    for s in (T, O, C):
        m = np.full((32, 32), s, np.uint8)
        np.testing.assert_array_equal(sb.decode(se.encode(m).pack()), m)


def test_a_fourth_two_value_vector_is_kept(rng):
    """VQ4's thirteen vectors and a fourteenth two-value one, no uniform C: 14 vectors for 13
    entries, lossless only through the synthesised vector."""
    kept = 0
    for _ in range(5):
        vecs = _thirteen(rng)
        extra = np.where(rng.random((4, 4)) < 0.5, O, C).astype(np.uint8)
        extra[0, 0], extra[3, 3] = O, C
        pool = vecs + [extra]
        m = np.zeros((32, 32), np.uint8)
        for v in range(64):
            vy, vx = divmod(v, 8)
            g = pool[v] if v < 14 else np.full((4, 4), rng.integers(0, 2)) if rng.random() < 0.3 \
                else pool[rng.integers(0, 14)]
            m[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = g
        blk = se.encode(m)
        d = sb.decode(blk.pack())
        assert states.is_conservative(m, d)
        kept += bool((d == m).all() and blk.extra != sb.NO_EXTRA)
    assert kept >= 3


def test_registered():
    codec = get_codec("vq4-synth")
    assert (codec.map_size, codec.bits, codec.block_bytes) == (32, 512, 64)
    m = np.zeros((32, 32), np.uint8)
    m[:, 13:] = O
    m[5:9, 2:30] = C
    blocks, dec = codec.encode_many(m[None], "best", "fast")
    assert states.is_conservative(m, dec[0])
    assert int(codec.lookup(blocks[0], 20, 0)) == dec[0][0, 20]


# ---- the corpus: never above sq32, never below vq4 ------------------------------------------------

REAL = real_textures(min_size=64)


@needs_shared
def test_corpus_between_vq4_and_sq32():
    rule = StateRule()
    synth, plain = [], []
    for p in REAL:
        m = bake_square(footprint_grid(rule.classify(load_alpha(p))), 32)
        d = sb.decode(se.encode(m, "best", "fast").pack())
        assert states.is_conservative(m, d)
        synth.append(known_fraction(d))
        plain.append(known_fraction(vq4_block.decode(vq4_encode.encode(m, "best", "fast").pack())))
        assert plain[-1] <= synth[-1] <= known_fraction(m)
    print(f"\nvq4-synth-fast {np.mean(synth):.4f}, vq4-fast {np.mean(plain):.4f}")


def test_cli(tmp_path, capsys):
    from PIL import Image
    y, x = np.mgrid[0:128, 0:128]
    a = np.clip(255 - 8 * np.abs(np.hypot(x - 60, y - 68) - 40), 0, 255).astype(np.uint8)
    Image.fromarray(a).save(tmp_path / "ring.png")
    out = tmp_path / "ring.vq4s"
    assert main(["encode", str(tmp_path / "ring.png"), "--codec", "vq4-synth", "--effort", "fast", "-o", str(out)]) == 0
    assert out.stat().st_size == 64
    capsys.readouterr()
    assert main(["decode", str(out), "--codec", "vq4-synth", "--json"]) == 0
    np.testing.assert_array_equal(json.loads(capsys.readouterr().out)["states"], sb.decode(out.read_bytes()))
    assert main(["eval", str(tmp_path / "ring.png"), "--schemes", "sq32,vq4-synth,vq4-synth-fast", "--quiet",
                 "--json", str(tmp_path / "r.json")]) == 0
    r = json.loads((tmp_path / "r.json").read_text())
    text = json.dumps(r)
    assert "vq4-synth-fast" in text
    assert main(["eval", str(tmp_path / "ring.png"), "--schemes", "vq4-synth-bogus", "--quiet"]) == 2
