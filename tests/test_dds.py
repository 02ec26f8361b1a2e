"""``MSFT_texture_dds``: a texture's DDS image (BC-compressed, as engines store textures) is the one
sampled, decoded by Pillow; a scene whose texture is a DDS traces exactly as the same scene with
the DDS's decoded pixels in a PNG; a DDS that cannot be decoded is a warning naming it."""

from __future__ import annotations

import base64
import io
import json

import numpy as np
import pytest
from PIL import Image

from gltf_files import edit_json, grid_scene
from omaps.cli.main import main
from omaps.scene import load_scene


def _alpha(seed=4, size=64):
    """Soft blobs: alpha gradients that BC3's interpolated alpha only approximates."""
    rng = np.random.default_rng(seed)
    a = rng.random((size // 8, size // 8))
    a = np.kron(a, np.ones((8, 8)))
    a = np.clip((a - 0.3) * 3, 0, 1) * 215 + rng.integers(0, 40, (size, size))  # (varied within BC blocks)
    return a.astype(np.uint8)


def _dds(alpha, pixel_format="DXT5"):
    rgba = np.zeros(alpha.shape + (4,), np.uint8)
    rgba[..., 1] = 180
    rgba[..., 3] = alpha
    buf = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(buf, format="DDS", pixel_format=pixel_format)
    return buf.getvalue()


def _with_dds(path, dds: bytes, mime="image/vnd-ms.dds"):
    """The texture's DDS image through MSFT_texture_dds; its own source (the fallback) kept."""
    def fn(doc):
        doc["images"].append({"uri": f"data:{mime};base64," + base64.b64encode(dds).decode()})
        doc["textures"][0]["extensions"] = {"MSFT_texture_dds": {"source": len(doc["images"]) - 1}}
        doc["extensionsUsed"] = ["MSFT_texture_dds"]
    return edit_json(path, fn)


@pytest.mark.parametrize("pixel_format", ["DXT5", "DXT1"])
def test_the_dds_image_is_sampled_and_traces_as_its_pixels_in_a_png(tmp_path, pixel_format):
    alpha = _alpha()
    dds = _dds(alpha, pixel_format)
    decoded = np.asarray(Image.open(io.BytesIO(dds)).convert("RGBA"))[..., 3]
    assert not np.array_equal(decoded, alpha) or pixel_format == "DXT1"  # (BC3's alpha is lossy)
    fallback = np.full_like(alpha, 255)  # an opaque fallback: what a reader ignoring the extension sees
    a = _with_dds(grid_scene(tmp_path / "dds.gltf", fallback, k=12, seed=2), dds)
    b = grid_scene(tmp_path / "png.gltf", decoded, k=12, seed=2)
    sa = load_scene(a)
    (tex,) = [t for t in sa.textures if t.alpha is not None]
    assert np.array_equal(tex.alpha, decoded) and not np.array_equal(tex.alpha, fallback)
    opts = ["--schemes", "none,sq16,tri3", "--size", "64", "--quiet"]
    for name, path in (("dds", a), ("png", b)):
        assert main(["trace", path, "--json", str(tmp_path / f"{name}.json"), *opts]) == 0
    x, y = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("dds", "png"))
    for s in ("none", "sq16", "tri3"):
        assert x["schemes"][s]["alpha_tests_per_primary_ray"] == y["schemes"][s]["alpha_tests_per_primary_ray"]
    assert x["passed"] and x["schemes"]["none"]["alpha_tests_per_primary_ray"] > 0


def test_a_dds_that_cannot_be_decoded_is_a_warning_naming_it(tmp_path):
    a = _with_dds(grid_scene(tmp_path / "dds.gltf", _alpha(), k=6), b"DDS " + b"\0" * 40)
    with pytest.warns(UserWarning, match="cannot be decoded"):
        s = load_scene(a)
    (tex,) = [t for t in s.textures if t.name.startswith("image")]
    assert tex.alpha is None and "cannot be decoded" in tex.problem
