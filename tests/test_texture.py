"""Texture input through Pillow: formats, alpha sources, bit depths, channel choice, bad files."""

import math
import numpy as np
import pytest
from PIL import Image

from omaps import states
from omaps.errors import InputError
from omaps.alpha_test import StateRule
from omaps.texture import AlphaTexture, find_images, load_alpha


@pytest.fixture
def alpha(rng):
    a = rng.integers(0, 256, size=(13, 21)).astype(np.uint8)  # non-power-of-two on purpose
    a[0, :3] = [0, 30, 31]
    a[1, :3] = [224, 225, 255]
    return a


def _rgba(alpha):
    rgb = np.zeros(alpha.shape + (3,), np.uint8)
    rgb[..., 1] = 200
    return np.dstack([rgb, alpha])


@pytest.mark.parametrize("ext", ["png", "tga", "tif", "webp"])
def test_rgba_formats(tmp_path, alpha, ext):
    p = tmp_path / f"t.{ext}"
    kw = {"lossless": True} if ext == "webp" else {}
    Image.fromarray(_rgba(alpha), "RGBA").save(p, **kw)
    t = load_alpha(p)
    assert (t.width, t.height, t.maxval) == (21, 13, 255)
    np.testing.assert_array_equal(t.values, alpha)


def test_bmp_with_alpha_bitfields(tmp_path, alpha):
    # Pillow writes 32-bit BMPs without an alpha mask, so build a BITMAPV4HEADER one by hand
    import struct
    h, w = alpha.shape
    bgra = np.dstack([np.zeros_like(alpha), np.full_like(alpha, 200), np.zeros_like(alpha), alpha])
    pixels = bgra.tobytes()
    info = struct.pack("<IiiHHIIiiII", 108, w, -h, 1, 32, 3, len(pixels), 2835, 2835, 0, 0)
    info += struct.pack("<IIII", 0x00FF0000, 0x0000FF00, 0x000000FF, 0xFF000000)
    info += struct.pack("<I", 0x73524742) + bytes(36 + 12)
    header = b"BM" + struct.pack("<IHHI", 14 + len(info) + len(pixels), 0, 0, 14 + len(info))
    p = tmp_path / "t.bmp"
    p.write_bytes(header + info + pixels)
    np.testing.assert_array_equal(load_alpha(p).values, alpha)


def test_dds_rgba(tmp_path, alpha):
    p = tmp_path / "t.dds"
    Image.fromarray(_rgba(alpha), "RGBA").save(p)
    np.testing.assert_array_equal(load_alpha(p).values, alpha)


def test_la_and_mask_and_jpeg(tmp_path, alpha):
    Image.fromarray(np.dstack([alpha, alpha]), "LA").save(tmp_path / "la.png")
    np.testing.assert_array_equal(load_alpha(tmp_path / "la.png").values, alpha)
    Image.fromarray(alpha, "L").save(tmp_path / "mask.png")
    np.testing.assert_array_equal(load_alpha(tmp_path / "mask.png").values, alpha)
    Image.fromarray(alpha, "L").save(tmp_path / "mask.jpg", quality=100)
    j = load_alpha(tmp_path / "mask.jpg").values.astype(int)
    assert np.abs(j - alpha).max() <= 8  # lossy, but it is the mask


def test_palette_with_trns(tmp_path):
    idx = np.array([[0, 1, 2], [2, 1, 0]], np.uint8)
    im = Image.fromarray(idx, "P")
    im.putpalette([0, 0, 0, 255, 0, 0, 0, 255, 0] + [0] * (256 * 3 - 9))
    im.save(tmp_path / "p.png", transparency=bytes([0, 128, 255]))
    np.testing.assert_array_equal(load_alpha(tmp_path / "p.png").values, [[0, 128, 255], [255, 128, 0]])


def test_palette_without_trns_is_an_error(tmp_path):
    im = Image.fromarray(np.zeros((4, 4), np.uint8), "P")
    im.putpalette([0, 0, 0] * 256)
    im.save(tmp_path / "p.png")
    with pytest.raises(InputError, match="p.png: palette image without transparency"):
        load_alpha(tmp_path / "p.png")


def test_16bit_mask_scaled(tmp_path):
    a16 = np.array([[0, 30 * 257, 30 * 257 + 1], [225 * 257 - 1, 225 * 257, 65535]], np.uint16)
    Image.fromarray(a16).save(tmp_path / "m16.png")
    t = load_alpha(tmp_path / "m16.png")
    assert t.maxval == 65535
    np.testing.assert_array_equal(t.values, a16)
    s = StateRule().classify(t)
    np.testing.assert_array_equal(s, [[states.T, states.T, states.C], [states.C, states.O, states.O]])


def test_16bit_rgba_png(tmp_path):
    # Pillow reads 16-bit RGBA PNGs as 8-bit RGBA (high byte): alpha still in range and ordered
    import struct
    import zlib
    w, h = 3, 1
    alpha16 = [0, 32896, 65535]
    raw = b"".join(b"\x00" + b"".join(struct.pack(">HHHH", 0, 0, 0, a) for a in alpha16) for _ in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 6, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
    (tmp_path / "rgba16.png").write_bytes(png)
    t = load_alpha(tmp_path / "rgba16.png")
    np.testing.assert_allclose(t.alpha8[0], [0, 128.5, 255], atol=0.6)


def test_channel_choice(tmp_path, alpha):
    rgb = np.dstack([alpha, 255 - alpha, np.zeros_like(alpha)])
    Image.fromarray(rgb, "RGB").save(tmp_path / "rgb.png")
    with pytest.raises(InputError, match="rgb.png: image has no alpha channel"):
        load_alpha(tmp_path / "rgb.png")
    np.testing.assert_array_equal(load_alpha(tmp_path / "rgb.png", "R").values, alpha)
    np.testing.assert_array_equal(load_alpha(tmp_path / "rgb.png", "g").values, 255 - alpha)
    np.testing.assert_array_equal(load_alpha(tmp_path / "rgb.png", "1").values, 255 - alpha)
    with pytest.raises(InputError, match="no channel 'A'"):
        load_alpha(tmp_path / "rgb.png", "A")
    with pytest.raises(InputError, match="no channel '7'"):
        load_alpha(tmp_path / "rgb.png", "7")


def test_bad_files(tmp_path):
    with pytest.raises(InputError, match="nope.png: no such file"):
        load_alpha(tmp_path / "nope.png")
    (tmp_path / "text.png").write_text("hello")
    with pytest.raises(InputError, match="text.png: not an image"):
        load_alpha(tmp_path / "text.png")
    Image.fromarray(np.zeros((64, 64), np.uint8)).save(tmp_path / "full.png")
    data = (tmp_path / "full.png").read_bytes()
    (tmp_path / "trunc.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="trunc.png"):
        load_alpha(tmp_path / "trunc.png")
    with pytest.raises(InputError, match="is a folder"):
        load_alpha(tmp_path)
    with pytest.raises(InputError, match="empty image"):
        AlphaTexture("e", np.zeros((0, 4), np.uint8), 255)


def test_find_images(tmp_path, alpha):
    (tmp_path / "sub").mkdir()
    Image.fromarray(alpha).save(tmp_path / "sub" / "b.png")
    Image.fromarray(alpha).save(tmp_path / "a.tga")
    (tmp_path / "notes.txt").write_text("x")
    images, skipped = find_images([tmp_path])
    assert [p.split("/")[-1] for p in images] == ["a.tga", "b.png"]
    assert [p.split("/")[-1] for p in skipped] == ["notes.txt"]
    with pytest.raises(InputError, match="no such file or folder"):
        find_images([tmp_path / "missing"])


def test_state_rules():
    t = AlphaTexture("t", np.array([[0, 30, 31, 127, 128, 224, 225, 255]], np.uint8), 255)
    np.testing.assert_array_equal(StateRule().classify(t)[0], [0, 0, 2, 2, 2, 2, 1, 1])
    np.testing.assert_array_equal(StateRule(t_max=31, o_min=224).classify(t)[0], [0, 0, 0, 2, 2, 1, 1, 1])
    np.testing.assert_array_equal(StateRule("cutoff", cutoff=0.5).classify(t)[0], [0, 0, 0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(StateRule("cutoff", cutoff=0.0).classify(t)[0], [0, 1, 1, 1, 1, 1, 1, 1])
    for bad in (dict(mode="x"), dict(t_max=200, o_min=100), dict(mode="cutoff", cutoff=1.5),
                dict(t_max=float("nan"))):
        with pytest.raises(InputError):
            StateRule(**bad)


# ---- numpy arrays, as a numpy user passes them ---------------------------------------------------

from hypothesis import given, settings, strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

from omaps.corpus import evaluate_texture  # noqa: E402


@pytest.mark.parametrize("mode,shape", [("L", ()), ("LA", (2,)), ("RGBA", (4,))])
def test_array_equals_the_same_pixels_as_a_file(tmp_path, alpha, mode, shape):
    """An (H, W[, C]) array and a PNG of the same pixels give the same texture (the file read by
    Pillow is the reference)."""
    if mode == "L":
        px = alpha
    elif mode == "LA":
        px = np.dstack([np.full_like(alpha, 90), alpha])
    else:
        px = _rgba(alpha)
    Image.fromarray(px, mode).save(tmp_path / "t.png")
    from_file = load_alpha(tmp_path / "t.png")
    from_array = load_alpha(px)
    assert from_array.maxval == from_file.maxval == 255
    np.testing.assert_array_equal(from_array.values, from_file.values)
    for ch in ("R", 0) if mode == "RGBA" else ():
        np.testing.assert_array_equal(load_alpha(px, ch).values, load_alpha(tmp_path / "t.png", ch).values)


def test_array_rgb_needs_a_channel_and_bad_shapes_are_named():
    rgb = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(InputError, match="no alpha channel"):
        load_alpha(rgb)
    np.testing.assert_array_equal(load_alpha(rgb, "G").values, rgb[..., 1])
    with pytest.raises(InputError, match="1 to 4 channels"):
        load_alpha(np.zeros((4, 4, 5), np.uint8))
    with pytest.raises(InputError, match="no channel 'G'"):
        load_alpha(np.zeros((4, 4), np.uint8), "G")
    with pytest.raises(InputError, match="shape"):
        load_alpha(np.zeros((2, 2, 2, 2), np.uint8))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32, np.float64, bool])
def test_state_rule_takes_arrays(dtype):
    """``StateRule(...).alpha_test`` and ``classify`` take a plain array of every dtype a numpy
    user holds, greyscale or RGBA; states agree with the rule written out on the values."""
    a8 = np.array([[0, 30, 31, 127, 128, 224, 225, 255]], np.uint8)
    if dtype is bool:
        arr, frac = a8 > 127, (a8 > 127).astype(float)
    elif np.dtype(dtype).kind == "f":
        arr = (a8 / 255.0).astype(dtype)
        frac = arr.astype(np.float64)
    elif dtype is np.uint16:
        arr, frac = a8.astype(np.uint16) * 257, a8 / 255.0
    else:
        arr, frac = a8, a8 / 255.0
    for pixels in (arr, np.dstack([np.zeros_like(arr)] * 3 + [arr])):
        got = StateRule("cutoff", cutoff=0.5).alpha_test(pixels).texel_states()
        assert got.tolist() == np.where(frac > 0.5, states.O, states.T).tolist()
        lv = StateRule("levels").classify(pixels)
        want = np.where(frac * 255 <= 30 + 1e-9, states.T, np.where(frac * 255 >= 225 - 1e-9, states.O, states.C))
        assert lv.tolist() == want.tolist()


def test_float_alpha_is_kept_exactly():
    """A float alpha of exactly the cut-off does not pass ``alpha > cutoff`` (it did once, as
    0.5 was quantised to 16 bits: 127.502 in 8-bit units)."""
    tex = load_alpha(np.array([[0.5, 0.25, 0.75]], np.float32))
    assert tex.alpha8.tolist() == [[127.5, 63.75, 191.25]]
    for c in (0.25, 0.5, 0.75):
        got = StateRule("cutoff", cutoff=c).classify(tex)
        assert got.tolist() == [[states.O if a > c else states.T for a in (0.5, 0.25, 0.75)]]


@settings(max_examples=40, deadline=None)
@given(hnp.arrays(np.float64, st.tuples(st.integers(1, 6), st.integers(1, 6)),
                  elements=st.floats(0, 1, allow_nan=False)),
       st.floats(0, 1, allow_nan=False))
def test_float_cutoff_matches_the_shader(a, cutoff):
    """Property: on float arrays the cutoff rule's texel states are the shader's ``a > cutoff``."""
    got = StateRule("cutoff", cutoff=cutoff).classify(a)
    want = np.where(a > cutoff, states.O, states.T)
    np.testing.assert_array_equal(got, want)


def test_evaluate_texture_takes_an_array_and_names():
    y, x = np.mgrid[:32, :32]
    disc = ((x - 15.5) ** 2 + (y - 15.5) ** 2 < 12 ** 2).astype(np.uint8) * 255
    rgba = np.dstack([np.zeros_like(disc)] * 3 + [disc])
    a = evaluate_texture(disc, "sq8,tri2")
    b = evaluate_texture(rgba, ["sq8", "tri2"])
    assert a.savings == b.savings and set(a.savings) == {"sq8", "tri2"}
    assert a.bits == {"sq8": 128, "tri2": 64}


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=True, width=64), st.floats(allow_nan=True, width=64), st.booleans())
def test_the_one_comparison_against_exact_rationals(a, thr, inclusive):
    """``alpha_test.passes`` (the shader's comparison, in numba and on arrays) and its mirror
    ``below`` against the comparison of exact rationals; NaN neither passes nor is below."""
    from fractions import Fraction

    from omaps.alpha_test import below, passes

    def exact(x, y):  # x > y (>= when inclusive), exactly
        if math.isnan(x) or math.isnan(y):
            return False
        if math.isinf(x) or math.isinf(y):
            return x > y or (inclusive and x == y)
        return Fraction(x) > Fraction(y) or (inclusive and Fraction(x) == Fraction(y))

    assert bool(passes(a, thr, inclusive)) == exact(a, thr)
    assert bool(below(a, thr, inclusive)) == exact(thr, a)
    assert bool(passes.py_func(np.array([a]), thr, inclusive)[0]) == exact(a, thr)
