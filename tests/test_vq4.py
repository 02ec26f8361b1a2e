"""VQ4 and VQ4x64: layout, total decoders, random access, conservative encoders, the corpus
acceptance, the command line."""

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from conftest import needs_shared, real_textures, tile_maps
from omaps import states
from omaps.alpha_test import StateRule
from omaps.bake import bake_square, known_fraction
from omaps.cli import main
from omaps.codecs import vec4, vq4_block, vq4_encode
from omaps.codecs.vq4_block import VQ4Block
from omaps.sampling import footprint_grid
from omaps.texture import load_alpha
from omaps.codecs.bits import kernel_bytes

T, O, C = states.T, states.O, states.C


def reference_decode(block: bytes) -> np.ndarray:
    """Decoder written from docs/FORMAT.md alone: big-integer bit fields, numpy flips/rotations."""
    x = int.from_bytes(block, "little")

    def field(pos, n):
        return (x >> pos) & ((1 << n) - 1)

    sizes = [17, 17, 17, 18, 18] + [20] * 8
    pos = [256 + sum(sizes[:j]) for j in range(13)]
    out = np.empty((32, 32), dtype=np.uint8)
    for vy in range(8):
        for vx in range(8):
            idx = field(4 * (8 * vy + vx), 4)
            if idx < 3:
                vec = np.full((4, 4), idx)
            else:
                j = idx - 3
                e = field(pos[j], sizes[j])
                vec = np.empty((4, 4), dtype=np.uint8)
                for ey in range(4):
                    for ex in range(4):
                        k = 4 * ey + ex
                        if j < 3:  # two-value
                            c, p = e >> (1 + k) & 1, e & 1
                        elif j == 3:  # vertical partition: left / right halves
                            c, p = e >> (2 + k) & 1, e >> (ex // 2) & 1
                        elif j == 4:  # horizontal partition: top / bottom halves
                            c, p = e >> (2 + k) & 1, e >> (ey // 2) & 1
                        else:  # four VQ2 codes, sub-vector 2*sy + sx
                            code = e >> (5 * (2 * (ey // 2) + ex // 2)) & 31
                            c, p = code >> (1 + 2 * (ey % 2) + ex % 2) & 1, code & 1
                        vec[ey, ex] = C if c else (O if p else T)
                q = 2 * (vy // 4) + vx // 4
                t = field(503 + 3 * (q - 1), 3) if q else 0
                if t & 4:
                    vec = np.fliplr(vec)
                if t & 2:
                    vec = np.flipud(vec)
                if t & 1:
                    vec = np.rot90(vec)  # a quarter turn anticlockwise as displayed
            out[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = vec
    return out


@settings(max_examples=150, deadline=None)
@given(st.binary(min_size=64, max_size=64))
def test_decoders_are_total_and_agree(data):
    m = vq4_block.decode(data)
    assert m.shape == (32, 32) and m.max() <= 2
    np.testing.assert_array_equal(m, reference_decode(data))
    blk = kernel_bytes(data)
    ys, xs = np.mgrid[0:32, 0:32]
    got = vq4_block.lookup_batch(blk[None], np.zeros(1024, np.int64), xs.ravel(), ys.ravel())
    np.testing.assert_array_equal(got.reshape(32, 32), m)
    assert vq4_block.lookup(blk, 31, 0) == m[0, 31]
    assert VQ4Block.unpack(data).pack() == data  # every pattern round-trips


@settings(max_examples=30, deadline=None)
@given(st.binary(min_size=256, max_size=256))
def test_x64_is_four_blocks(data):
    m = vq4_block.decode_x64(data)
    for k in range(4):
        y, x = 32 * (k >> 1), 32 * (k & 1)
        np.testing.assert_array_equal(m[y:y + 32, x:x + 32], reference_decode(data[64 * k:64 * (k + 1)]))
    blk = kernel_bytes(data)
    ys, xs = np.mgrid[0:64, 0:64]
    got = vq4_block.lookup_batch_x64(blk[None], np.zeros(4096, np.int64), xs.ravel(), ys.ravel())
    np.testing.assert_array_equal(got.reshape(64, 64), m)


def test_bad_sizes():
    with pytest.raises(ValueError, match="64 bytes"):
        vq4_block.decode(b"\0" * 63)
    with pytest.raises(ValueError, match="256 bytes"):
        vq4_block.decode_x64(b"\0" * 64)
    with pytest.raises(ValueError, match="32x32"):
        vq4_encode.encode(np.zeros((16, 16), np.uint8))


# ---- entry kinds ------------------------------------------------------------------------------

patterns = st.tuples(st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)).map(lambda p: (p[0], p[1] & ~p[0]))


@given(patterns, st.integers(0, 3))
def test_projection_fits_and_round_trips(p, kind):
    kt, ko = vec4.project(kind, *p)
    assert kt & ~p[0] == 0 and ko & ~p[1] == 0  # only known -> C
    assert vec4.project(kind, kt, ko) == (kt, ko)  # it fits the kind
    code = vec4.entry_code(kind, kt, ko)
    assert 0 <= code < 1 << vec4.KIND_BITS[kind]
    assert vec4.entry_pattern(kind, code) == (kt, ko)


@given(st.integers(0, 0xFFFF), st.integers(0, 7))
def test_mask_transforms_match_position_tables(m, t):
    shown = vec4.transform_mask(m, t)
    assert shown == sum(1 << int(vec4.FWD4[t, e]) for e in range(16) if m >> e & 1)
    assert vec4.untransform_mask(shown, t) == m


# ---- encoders ------------------------------------------------------------------------------

random_maps = arrays(np.uint8, (32, 32), elements=st.sampled_from([T, O, C]))


@st.composite
def blob_maps(draw):
    """Maps with spatial coherence, like real ones: T outside, O inside, a C band between."""
    cx, cy = draw(st.floats(0, 32)), draw(st.floats(0, 32))
    r_in, band = draw(st.floats(0, 20)), draw(st.floats(0, 6))
    wob = draw(st.floats(0, 5))
    y, x = np.mgrid[0:32, 0:32] + 0.5
    d = np.hypot(x - cx, y - cy) + wob * np.sin(x / 2) * np.cos(y / 3)
    return np.where(d < r_in, O, np.where(d < r_in + band, C, T)).astype(np.uint8)


@pytest.mark.parametrize("encoder, effort", [("paper", "medium"), ("best", "fast"), ("best", "medium"),
                                             ("best", "thorough")])
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(m=st.one_of(random_maps, blob_maps()))
def test_encoders_are_conservative(m, encoder, effort):
    blk = vq4_encode.encode(m, encoder, effort)
    data = blk.pack()
    assert len(data) == 64
    d = vq4_block.decode(data)
    assert states.is_conservative(m, d)
    np.testing.assert_array_equal(d, reference_decode(data))
    assert (d[m != C] != C).sum() <= (m != C).sum()


def _fill(vectors, rng, uniform_share=0.5):
    m = np.zeros((32, 32), np.uint8)
    for vy in range(8):
        for vx in range(8):
            if rng.random() < uniform_share:
                m[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = rng.integers(0, 3)
            else:
                m[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = vectors[rng.integers(0, len(vectors))]
    return m


def _thirteen(rng):
    """Three T/C or O/C vectors, a left/right and a top/bottom partition, eight general vectors
    (O, T and C together): one vector per entry, none symmetric left/right."""
    def asym(make):
        while True:
            g = make().astype(np.uint8)
            if not np.array_equal(g, np.fliplr(g)) and len(np.unique(g)) > 1:
                return g
    v = [asym(lambda: np.where(rng.random((4, 4)) < 0.5, p, C)) for p in (T, T, O)]
    v.append(asym(lambda: np.where(rng.random((4, 4)) < .3, C, np.repeat([[T, T, O, O]], 4, 0))))
    v.append(asym(lambda: np.where(rng.random((4, 4)) < .3, C, np.repeat([[O], [O], [T], [T]], 4, 1))))
    for _ in range(8):
        v.append(asym(lambda: np.where(rng.random((4, 4)) < .3, C,
                                       np.kron([[T, O], [O, T]] if rng.random() < .5 else [[O, T], [O, O]],
                                               np.ones((2, 2), int)))))
    return v


def test_vectors_that_fit_the_kinds_are_lossless(rng):
    """13 distinct vectors, one per entry of each kind: every encoder is lossless."""
    for _ in range(5):
        m = _fill(_thirteen(rng), rng, 0.2)
        for enc, eff in [("best", "fast"), ("best", "medium"), ("paper", "medium")]:
            np.testing.assert_array_equal(vq4_encode.encode(m, enc, eff).decode(), m, err_msg=f"{enc} {eff}")


def test_transforms_share_entries(rng):
    """The top-right quadrant holds the top-left's 13 vectors mirrored left/right: lossless only
    with its transform set to the mirror (26 distinct vectors otherwise)."""
    gen = _thirteen(rng)
    m = np.full((32, 32), T, np.uint8)
    for i, g in enumerate(gen):
        vy, vx = divmod(i, 4)
        m[4 * vy:4 * vy + 4, 4 * vx:4 * vx + 4] = g
        m[4 * vy:4 * vy + 4, 28 - 4 * vx:32 - 4 * vx] = np.fliplr(g)
    for effort in ("fast", "medium", "thorough"):
        blk = vq4_encode.encode(m, "best", effort)
        np.testing.assert_array_equal(blk.decode(), m)
        assert blk.transforms[1] == 4  # reflect left/right


def test_x64_encodes_quadrants():
    y, x = np.mgrid[0:64, 0:64] + 0.5
    d = np.hypot(x - 30, y - 35)
    m = np.where(d < 18, O, np.where(d < 21, C, T)).astype(np.uint8)
    data = vq4_encode.encode_x64(m, "best", "fast")
    assert len(data) == 256
    dec = vq4_block.decode_x64(data)
    assert states.is_conservative(m, dec) and known_fraction(dec) > 0.9
    for k, q in enumerate(vq4_encode.split_x64(m)):
        np.testing.assert_array_equal(vq4_block.decode(data[64 * k:64 * (k + 1)]),
                                      vq4_encode.encode(q, "best", "fast").decode())


# ---- many blocks at once (issue 14: maps -> bytes in bulk) -----------------------------------

ENTRY_BITS = [17, 17, 17, 18, 18] + [20] * 8  # docs/FORMAT.md's codebook


def reference_pack(indices, entries, transforms) -> bytes:
    """Packer written from docs/FORMAT.md alone: one big integer, fields OR-ed in at their bits
    (the per-field packer ``VQ4Block.pack`` had before issue 14)."""
    x = 0
    for v in range(64):
        x |= int(indices[v]) << (4 * v)
    for j in range(13):
        x |= int(entries[j]) << (256 + sum(ENTRY_BITS[:j]))
    for q in (1, 2, 3):
        x |= int(transforms[q]) << (503 + 3 * (q - 1))
    return x.to_bytes(64, "little")


@st.composite
def symbolic_blocks(draw):
    """n random symbolic blocks: every field anywhere in its range (transforms[:, 0] = 0)."""
    n = draw(st.integers(1, 6))
    idx = draw(arrays(np.int64, (n, 64), elements=st.integers(0, 15)))
    ent = np.array([[draw(st.integers(0, (1 << w) - 1)) for w in ENTRY_BITS] for _ in range(n)], np.int64)
    tr = draw(arrays(np.int64, (n, 4), elements=st.integers(0, 7)))
    tr[:, 0] = 0
    return idx, ent, tr


@settings(max_examples=200, deadline=None)
@given(symbolic_blocks())
def test_bulk_pack_is_the_formats_packing(fields):
    idx, ent, tr = fields
    got = vq4_block.pack_many(idx, ent, tr)
    assert got.shape == (len(idx), 64) and got.dtype == np.uint8
    for i in range(len(idx)):
        want = reference_pack(idx[i], ent[i], tr[i])
        assert got[i].tobytes() == want
        assert VQ4Block(idx[i], ent[i], tr[i]).pack() == want
    np.testing.assert_array_equal(vq4_block.pack_many(idx, ent, tr[:, 1:]), got)  # quadrants 1..3 alone
    for a, b in zip(vq4_block.unpack_many(got), (idx, ent, tr)):
        np.testing.assert_array_equal(a, b)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(min_size=256, max_size=256), min_size=1, max_size=3))
def test_bulk_decode_and_unpack_of_any_bytes(datas):
    maps64 = np.frombuffer(b"".join(datas), np.uint8).reshape(-1, 256)
    blocks = maps64.reshape(-1, 64)
    maps = vq4_block.decode_many(blocks)
    idx, ent, tr = vq4_block.unpack_many(blocks)
    for i in range(len(blocks)):
        data = blocks[i].tobytes()
        np.testing.assert_array_equal(maps[i], reference_decode(data))
        assert reference_pack(idx[i], ent[i], tr[i]) == data
    np.testing.assert_array_equal(vq4_block.pack_many(idx, ent, tr), blocks)
    got64 = vq4_block.decode_many_x64(maps64)
    for i, data in enumerate(datas):
        np.testing.assert_array_equal(got64[i], vq4_block.decode_x64(data))
        for k in range(4):  # the x64 map's quadrant k is its block k
            y, x = 32 * (k >> 1), 32 * (k & 1)
            np.testing.assert_array_equal(got64[i, y:y + 32, x:x + 32], maps[4 * i + k])


def test_bulk_pack_rejects_fields_out_of_range():
    idx, ent, tr = np.zeros((2, 64), np.int64), np.zeros((2, 13), np.int64), np.zeros((2, 4), np.int64)
    for arr, k, v in [(idx, (1, 5), 16), (ent, (0, 2), 1 << 17), (ent, (1, 4), 1 << 18), (ent, (0, 12), 1 << 20),
                      (tr, (1, 3), 8), (ent, (0, 0), -1)]:
        bad = arr.copy()
        bad[k] = v
        args = [bad if a is arr else a for a in (idx, ent, tr)]
        with pytest.raises(ValueError, match="does not fit"):
            vq4_block.pack_many(*args)
    ent[0, 12] = (1 << 20) - 1  # the widest entry's largest code fits
    assert vq4_block.pack_many(idx, ent, tr).shape == (2, 64)
    tr[0, 0] = 1
    with pytest.raises(ValueError, match="top-left"):
        vq4_block.pack_many(idx, ent, tr)
    with pytest.raises(ValueError, match="256"):
        vq4_block.decode_many_x64(np.zeros((1, 64), np.uint8))


# ---- the corpus acceptance --------------------------------------------------------------------

REAL = real_textures(min_size=64)


@pytest.fixture(scope="module")
def corpus_maps():
    rule = StateRule()
    out = []
    for p in REAL:
        g = footprint_grid(rule.classify(load_alpha(p)))
        out.append({n: bake_square(g, n) for n in (16, 32, 64)})
    return out


@needs_shared
def test_corpus_acceptance(corpus_maps):
    sq = {n: np.mean([known_fraction(m[n]) for m in corpus_maps]) for n in (16, 32, 64)}
    res = {}
    for enc, eff in [("paper", "medium"), ("best", "fast"), ("best", "thorough")]:
        s4, s64 = [], []
        for m in corpus_maps:
            data = vq4_encode.encode(m[32], enc, eff).pack()
            assert len(data) == 64
            d = vq4_block.decode(data)
            assert states.is_conservative(m[32], d)
            s4.append(known_fraction(d))
            data = vq4_encode.encode_x64(m[64], enc, eff)
            assert len(data) == 256
            d = vq4_block.decode_x64(data)
            assert states.is_conservative(m[64], d)
            s64.append(known_fraction(d))
        res[enc, eff] = np.mean(s4), np.mean(s64)
        print(f"\nVQ4 {enc}/{eff}: vq4 {res[enc, eff][0]:.4f} = {res[enc, eff][0] / sq[16]:.4f} x sq16 "
              f"({res[enc, eff][0] / sq[32]:.3f} of sq32); vq4x64 {res[enc, eff][1]:.4f} = "
              f"{res[enc, eff][1] / sq[32]:.4f} x sq32 ({res[enc, eff][1] / sq[64]:.3f} of sq64)")
    best = res["best", "thorough"]
    assert best[0] >= 1.18 * sq[16]
    assert best[1] >= 1.14 * sq[32]
    for other in (res["paper", "medium"], res["best", "fast"]):
        assert best[0] > other[0] and best[1] > other[1]


@pytest.fixture(scope="module")
def tile_maps32():
    return tile_maps(REAL[::8], 32, limit=200)


@needs_shared
@pytest.mark.parametrize("encoder, effort", [("paper", "medium"), ("best", "fast"), ("best", "medium"),
                                             ("best", "thorough")])
def test_codec_bytes_are_the_packed_blocks_on_tile_maps(tile_maps32, encoder, effort):
    """What eval / trace / omm store (the registry's ``encode_many``, packed and decoded in bulk)
    is, byte for byte, the encoder's symbolic blocks packed field by field, and decodes to the
    format's maps; a vq4x64 map is its four quadrants' blocks."""
    from omaps.codecs import get_codec
    from omaps.codecs.options import EFFORTS, ENCODERS

    maps = tile_maps32 if encoder == "best" and effort != "thorough" else np.ascontiguousarray(tile_maps32[::5])
    blocks, decoded = get_codec("vq4").encode_many(maps, encoder, effort)
    idx, ent, tr = vq4_encode.encode_many_arrays(maps, ENCODERS.index(encoder), EFFORTS[effort])
    assert [b.tobytes() for b in blocks] == [reference_pack(idx[i], ent[i], tr[i]) for i in range(len(maps))]
    np.testing.assert_array_equal(blocks, vq4_encode.encode_blocks(maps, encoder, effort))
    for i in range(0, len(maps), 9):
        np.testing.assert_array_equal(decoded[i], reference_decode(blocks[i].tobytes()))
    assert states.is_conservative(maps, decoded)
    n = len(maps) // 4
    m64 = maps[:4 * n].reshape(n, 2, 2, 32, 32).transpose(0, 1, 3, 2, 4).reshape(n, 64, 64)
    b64, d64 = get_codec("vq4x64").encode_many(m64, encoder, effort)
    np.testing.assert_array_equal(b64, blocks[:4 * n].reshape(n, 256))
    assert b64[0].tobytes() == vq4_encode.encode_x64(m64[0], encoder, effort)
    np.testing.assert_array_equal(d64[:, 32:, :32], decoded[2:4 * n:4])


# ---- CLI -------------------------------------------------------------------------------------

@pytest.mark.parametrize("codec, size, nbytes", [("vq4", 32, 64), ("vq4x64", 64, 256)])
def test_cli_encode_decode(tmp_path, capsys, codec, size, nbytes):
    from PIL import Image
    y, x = np.mgrid[0:128, 0:128]
    a = np.clip(255 - 8 * np.abs(np.hypot(x - 60, y - 68) - 40), 0, 255).astype(np.uint8)
    Image.fromarray(a).save(tmp_path / "ring.png")
    out = tmp_path / f"ring.{codec}"
    assert main(["encode", str(tmp_path / "ring.png"), "--codec", codec, "--effort", "fast", "-o", str(out)]) == 0
    assert out.stat().st_size == nbytes
    capsys.readouterr()
    assert main(["decode", str(out), "--codec", codec, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert np.array(data["states"]).shape == (size, size)
    decode = vq4_block.decode if codec == "vq4" else vq4_block.decode_x64
    np.testing.assert_array_equal(data["states"], decode(out.read_bytes()))
    assert main(["decode", str(tmp_path / "ring.png"), "--codec", codec]) == 2
    assert f"a {codec} block is {nbytes} bytes" in capsys.readouterr().err
    assert main(["eval", str(tmp_path / "ring.png"), "--schemes", f"{codec}-fast,{codec}-paper", "--quiet"]) == 0


def test_parallel_encoding_equals_one_process(tmp_path):
    """``workers.encode_maps`` (trace and omm --from) gives one process's blocks with 2 workers,
    and ``omm --from vq4 --jobs 2`` writes the same files as ``--jobs 1``."""
    from PIL import Image

    from omaps.codecs import get_codec
    from omaps.workers import encode_maps

    rng = np.random.default_rng(5)
    maps = np.stack([np.kron(rng.integers(0, 3, (8, 8)), np.ones((4, 4), np.uint8)) for _ in range(40)]).astype(np.uint8)
    codec = get_codec("vq4")
    one = codec.encode_many(maps, "best", "fast")
    two = encode_maps(codec, maps, "best", "fast", jobs=2)
    np.testing.assert_array_equal(one[0], two[0])
    np.testing.assert_array_equal(one[1], two[1])

    y, x = np.mgrid[0:128, 0:128]
    a = np.clip(255 - 8 * np.abs(np.hypot(x - 60, y - 68) - 40), 0, 255).astype(np.uint8)
    Image.fromarray(a).save(tmp_path / "ring.png")
    np.save(tmp_path / "uvs.npy", rng.random((64, 3, 2)))
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"omm{jobs}"
        assert main(["omm", str(tmp_path / "ring.png"), str(tmp_path / "uvs.npy"), "-o", str(out), "--from",
                     "vq4-fast", "--jobs", jobs, "--quiet"]) == 0
        outs.append({p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.suffix == ".bin"})
    assert outs[0] == outs[1] and "pair_blocks.bin" in outs[0]
    assert main(["omm", str(tmp_path / "ring.png"), str(tmp_path / "uvs.npy"), "-o", str(tmp_path / "bad"),
                 "--from", "vq4", "--jobs", "0"]) == 2
