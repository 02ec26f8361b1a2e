"""Texture input through Pillow: formats, alpha sources, bit depths, channel choice, bad files."""

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
