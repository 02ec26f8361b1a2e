"""``omaps omm`` end to end: texture + UVs, glTF (synthetic and the shared scenes), --from,
--verify, and bad input (exit 2, nothing written)."""

import base64
import json
import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import omm_decoder
import reference as ref
from conftest import SHARED
from omaps import states
from omaps.alpha_test import StateRule
from omaps.bake import GROW_TEXEL, bake_micromap_rows, bake_pair_squares
from omaps.cli import main
from omaps.omm import pairs
from omaps.texture import AlphaTexture

SCENES = SHARED / "data" / "scenes"
needs_scenes = pytest.mark.skipif(not SCENES.is_dir(), reason=f"scenes not found at {SCENES} (../shared is absent)")


def test_texture_input_writes_and_verifies(tex_and_uvs, tmp_path, capsys):
    png, uvs, a, tris = tex_and_uvs
    out = tmp_path / "omm"
    assert main(["omm", str(png), str(uvs), "-o", str(out), "--level", "3", "--filter", "linear",
                 "--wrap", "wrap", "--cutoff", "0.3"]) == 0
    assert sorted(os.listdir(out)) == ["omm.json", "omm_data.bin", "omm_index.bin", "omm_triangles.bin",
                                       "omm_usage.json"]
    grid = StateRule("cutoff", cutoff=0.3).alpha_test(AlphaTexture("m", a, 255), "linear", "wrap").grid()
    baked = bake_micromap_rows(grid, tris, 3, GROW_TEXEL)  # real geometry is baked with growth
    assert states.is_conservative(bake_micromap_rows(grid, tris, 3), baked)
    for t, (lv, s) in enumerate(omm_decoder.triangle_states(out)):
        s = np.array(s * (64 if lv is None else 1))
        known = baked[t] != states.C
        np.testing.assert_array_equal(s[known], baked[t][known])
        assert np.all(s[~known] >= 2)
    capsys.readouterr()
    assert main(["omm", "--verify", str(out)]) == 0
    assert "every micro-triangle against a re-bake" in capsys.readouterr().out
    # tamper with one micromap: the re-bake catches it
    data = bytearray((out / "omm_data.bin").read_bytes())
    data[0] ^= 0b01
    (out / "omm_data.bin").write_bytes(bytes(data))
    assert main(["omm", "--verify", str(out)]) == 1
    assert "differ from a re-bake" in capsys.readouterr().err


def test_from_square_maps_and_codec(tex_and_uvs, tmp_path, capsys):
    png, uvs, a, tris = tex_and_uvs
    for source, n in (("sq8", 8), ("vq2", 16)):
        out = tmp_path / source
        extra = ["--effort", "fast"] if source == "vq2" else []
        assert main(["omm", str(png), str(uvs), "-o", str(out), "--from", source] + extra) == 0
        summary = json.loads((out / "omm.json").read_text())
        assert summary["statistics"]["levels"] == {str(n.bit_length() - 1): 9}
        grid = StateRule("cutoff", cutoff=0.5).alpha_test(AlphaTexture("m", a, 255)).grid()
        # a UV array's pairs: triangles 2k (A) and 2k+1 (B), corners in their own vertex order
        corner_uv = np.zeros((5, 6, 2))
        corner_uv[:, 0:3] = tris[0::2]
        corner_uv[:4, 3:6] = tris[1::2]
        sq = bake_pair_squares(grid, corner_uv, np.arange(5) < 4, n, GROW_TEXEL)
        pair_of, corners, _ = pairs.corpus_pairing(9)
        np.testing.assert_array_equal(pair_of, np.arange(9) // 2)
        expanded = pairs.expand(sq, pair_of, corners)
        per = omm_decoder.triangle_states(out)
        for t, (lv, s) in enumerate(per):
            s = np.array(s * (4 ** (n.bit_length() - 1) if lv is None else 1))
            want = expanded[t]
            if source == "sq8":  # uncompressed: exactly the square map
                np.testing.assert_array_equal(s[want != 2], want[want != 2])
                assert np.all(s[want == 2] >= 2)
            else:  # compressed: conservative against the uncompressed map
                assert np.all((s >= 2) | (s == want))
        assert main(["omm", "--verify", str(out)]) == 0
    assert (tmp_path / "vq2" / "pair_blocks.bin").stat().st_size == 5 * 32
    capsys.readouterr()
    blocks = bytearray((tmp_path / "vq2" / "pair_blocks.bin").read_bytes())
    blocks[0] ^= 0xFF
    (tmp_path / "vq2" / "pair_blocks.bin").write_bytes(bytes(blocks))
    assert main(["omm", "--verify", str(tmp_path / "vq2")]) == 1
    assert "decoded pair block" in capsys.readouterr().err


@pytest.mark.parametrize("args,msg", [
    (["--level", "13"], "level must be an integer from 0 to 12"),
    (["--level", "3", "--dynamic", "2"], "exclude each other"),
    (["--from", "sq12"], "power of two"),
    (["--from", "vq9"], "unknown scheme 'vq9'"),
    (["--from", "tri3"], "--from takes texture, a square scheme"),
    (["--from", "csm13"], "level"),
    (["--from", "sq8", "--dynamic", "2"], "--dynamic needs the texture source"),
    (["--cutoff", "2"], "cutoff must be in"),
])
def test_bad_options(tex_and_uvs, tmp_path, capsys, args, msg):
    png, uvs, _, _ = tex_and_uvs
    out = tmp_path / "o"
    assert main(["omm", str(png), str(uvs), "-o", str(out)] + args) == 2
    assert msg in capsys.readouterr().err
    assert not out.exists()


def test_bad_inputs(tex_and_uvs, tmp_path, capsys):
    png, uvs, _, _ = tex_and_uvs
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros((3, 4, 2)))
    out = tmp_path / "o"
    assert main(["omm", str(png), str(bad), "-o", str(out)]) == 2
    assert f"{bad}: UV triangles must have shape" in capsys.readouterr().err
    assert main(["omm", str(png), "-o", str(out)]) == 2
    assert "needs a .npy array" in capsys.readouterr().err
    assert main(["omm", str(tmp_path / "nope.glb"), "-o", str(out)]) == 2
    assert "no such file" in capsys.readouterr().err
    (tmp_path / "broken.glb").write_bytes(b"glTF garbage")
    assert main(["omm", str(tmp_path / "broken.glb"), "-o", str(out)]) == 2
    assert "broken.glb" in capsys.readouterr().err
    assert main(["omm", "--verify", str(tmp_path / "none")]) == 2
    assert not out.exists()


# ---- synthetic glTF ------------------------------------------------------------------------

def _gltf(tmp_path, image_uri="alpha.png", material=None, sampler=None, tex_ext=None, alpha=None, factor=1.0):
    """A quad (two triangles, the corpus pair's UVs scaled by 1) with a base colour texture."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], dtype=np.uint16)
    blob = pos.tobytes() + uv.tobytes() + idx.tobytes()
    if alpha is not None:
        rgba = np.zeros(alpha.shape + (4,), np.uint8)
        rgba[..., 3] = alpha
        Image.fromarray(rgba, "RGBA").save(tmp_path / "alpha.png")
    tex_info = {"index": 0}
    if tex_ext:
        tex_info["extensions"] = {"KHR_texture_transform": tex_ext}
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"name": "quad", "primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                                    "material": 0}]}],
        "materials": [material or {"alphaMode": "MASK", "alphaCutoff": 0.5,
                                   "pbrMetallicRoughness": {"baseColorTexture": tex_info,
                                                            "baseColorFactor": [1, 1, 1, factor]}}],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [sampler or {"magFilter": 9728, "wrapS": 33071, "wrapT": 33648}],
        "images": [{"uri": image_uri}],
        "buffers": [{"byteLength": len(blob),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                        {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    }
    if tex_ext:
        doc["extensionsUsed"] = ["KHR_texture_transform"]
    (tmp_path / "scene.gltf").write_text(json.dumps(doc))
    return tmp_path / "scene.gltf"


def test_gltf_mask_sampler_and_cutoff(tmp_path, rng):
    alpha = rng.integers(0, 256, size=(8, 8)).astype(np.uint8)
    alpha[0, 0] = 170  # 170/255 * 0.75 is exactly the cut-off: float rounding could go either way
    alpha[5, 6] = 171  # just above
    path = _gltf(tmp_path, alpha=alpha, factor=0.75)
    out = tmp_path / "o"
    assert main(["omm", str(path), "-o", str(out), "--level", "4", "--no-special"]) == 0
    summary = json.loads((out / "omm.json").read_text())
    g = summary["geometries"][0]
    assert (g["filter"], g["wrap_u"], g["wrap_v"], g["inclusive"]) == ("nearest", "clamp", "mirror", True)
    # independent expectation: texel opaque iff 0.75 * a / 255 >= 0.5 (unknown at equality),
    # nearest, on the corpus pair
    img = np.where(0.75 * alpha.astype(int) * 2 > 255, states.O, states.T).astype(np.uint8)
    img[0.75 * alpha.astype(int) * 2 == 255] = states.C
    assert img[0, 0] == states.C and img[5, 6] == states.O
    from omaps.pair import PAIR
    from omaps.sampling import footprint_grid

    grid = footprint_grid(img, "nearest", "clamp", "mirror")
    want = bake_micromap_rows(grid, PAIR, 4, GROW_TEXEL)  # real geometry is baked with growth
    assert states.is_conservative(bake_micromap_rows(grid, PAIR, 4), want)
    per = omm_decoder.triangle_states(out)
    for t in (0, 1):
        s = np.array(per[t][1])
        np.testing.assert_array_equal(np.minimum(s, states.C), want[t])  # unknown-T/O (2, 3) are C
    assert main(["omm", "--verify", str(out)]) == 0


def test_gltf_texture_transform(tmp_path, rng):
    alpha = np.zeros((8, 8), np.uint8)
    alpha[:, 4:] = 255  # right half opaque
    # scale 3/8 and offset 5/8 in u: the quad reads only texels 5..7 (and, grown by a hair, the
    # edge of texel 4) of the right half -> fully opaque
    path = _gltf(tmp_path, alpha=alpha, tex_ext={"offset": [0.625, 0.0], "scale": [0.375, 1.0]},
                 sampler={"magFilter": 9728, "wrapS": 33071, "wrapT": 33071})
    assert main(["omm", str(path), "-o", str(tmp_path / "o"), "--level", "3"]) == 0
    assert omm_decoder.read_folder(tmp_path / "o")[2] == [-2, -2]
    # scale 3/8, no offset: texels 0..2 (and the edge of texel 3) of the left half -> fully transparent
    path = _gltf(tmp_path, alpha=alpha, tex_ext={"offset": [0.0, 0.0], "scale": [0.375, 1.0]},
                 sampler={"magFilter": 9728, "wrapS": 33071, "wrapT": 33071})
    assert main(["omm", str(path), "-o", str(tmp_path / "o"), "--level", "3"]) == 0
    assert omm_decoder.read_folder(tmp_path / "o")[2] == [-1, -1]


def test_gltf_missing_texture_warns_and_falls_back(tmp_path, capsys):
    path = _gltf(tmp_path, image_uri="gone.png")
    assert main(["omm", str(path), "-o", str(tmp_path / "o"), "--level", "3", "--promote", "transparent"]) == 0
    err = capsys.readouterr().err
    assert "'gone.png'" in err and "unknown (all C)" in err
    assert omm_decoder.read_folder(tmp_path / "o")[2] == [-3, -3]


def test_gltf_without_alpha_tested_material(tmp_path, capsys):
    path = _gltf(tmp_path, alpha=np.zeros((2, 2), np.uint8), material={"alphaMode": "OPAQUE"})
    assert main(["omm", str(path), "-o", str(tmp_path / "o")]) == 2
    assert "no alpha-tested primitive" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# ---- the shared scenes ---------------------------------------------------------------------

@needs_scenes
@pytest.mark.long
def test_palm(tmp_path, capsys):
    out = tmp_path / "palm"
    assert main(["omm", str(SCENES / "palm.glb"), "-o", str(out), "--dynamic", "4", "--max-level", "5"]) == 0
    s = json.loads((out / "omm.json").read_text())
    assert s["statistics"]["triangles"] == 3840
    # alphaCutoff 0.25, compared on the raw 8-bit values
    assert s["geometries"][0]["alpha_mode"] == "MASK" and s["geometries"][0]["threshold"] == 0.25 * 255
    assert s["skipped_primitives"][0]["reason"].startswith("opaque")
    assert 0.2 < s["statistics"]["known_area_fraction"] < 1
    assert main(["omm", "--verify", str(out)]) == 0
    # the UV convention against the image: a micro-triangle stated opaque has only opaque texels
    from omaps.scene import alpha_triangles, load_scene

    scene = load_scene(SCENES / "palm.glb")
    at = alpha_triangles(scene)  # the alpha-tested triangles, in the order omm writes them
    assert at.count == 3840 and len(set(at.material.tolist())) == 1
    tex = scene.textures[scene.materials[at.material[0]].texture]
    assert tex.maxval == 255
    per = omm_decoder.triangle_states(out)
    a = tex.alpha
    h, w = a.shape
    for t in range(0, 3840, 193):  # a sample: the exact rational reference costs ~10 ms a micro-triangle
        lv, st_ = per[t]
        if lv is None:
            continue
        from omaps.birdcurve import uv_micro_triangles

        micro = uv_micro_triangles(at.uv[t], lv)
        for k in np.flatnonzero(np.array(st_) < 2)[:12]:
            lo, hi = ref.bilinear_extremes(a, "wrap", "wrap", list(micro[k] * [w, h]))  # exact, bilinear
            assert lo / 255 >= 0.25 if st_[k] == 1 else hi / 255 < 0.25


@needs_scenes
def test_smallpine_blend_and_vq2(tmp_path, capsys):
    out = tmp_path / "pine"
    assert main(["omm", str(SCENES / "smallpine" / "scene.gltf"), "-o", str(out), "--from", "vq2",
                 "--effort", "fast", "--format", "2state", "--promote", "hashed"]) == 0
    s = json.loads((out / "omm.json").read_text())
    assert s["statistics"]["triangles"] == 1442 and s["geometries"][0]["state_rule"] == "levels"
    assert s["statistics"]["micromaps"] < s["statistics"]["micromaps_without_reuse"]
    warnings = [x for x in capsys.readouterr().err.splitlines() if "warning" in x]
    # the one reader names the missing normal map once, as not needed; the base colour is read
    assert len(warnings) == 1 and "M_TreeAtlas_normal.png" in warnings[0] and "not needed" in warnings[0]
    assert main(["omm", "--verify", str(out)]) == 0
    # the tracer's pairs (shared edges): at least 1442 / 2 pairs, every triangle in one
    blocks = s["pair_blocks"]["blocks"]
    assert 721 <= blocks < 1442 and s["pair_blocks"]["codec"] == "vq2"
    assert Path(out / "pair_blocks.bin").stat().st_size == blocks * 32
    rec = np.fromfile(out / "omm_pairs.bin", dtype=[("pair", "<i4"), ("corners", "u1", (3,)), ("pad", "u1")])
    assert len(rec) == 1442 and set(np.unique(rec["pair"])) == set(range(blocks))
    assert np.all(np.bincount(rec["pair"]) <= 2)


def test_verify_an_output_without_micromaps(tmp_path, capsys):
    """A texture opaque everywhere: every triangle is a special index and no micromap is stored;
    --verify checks it (it raised an IndexError indexing the empty records)."""
    rgba = np.zeros((16, 16, 4), np.uint8)
    rgba[..., 3] = 255
    Image.fromarray(rgba, "RGBA").save(tmp_path / "leaf.png")
    np.save(tmp_path / "uv.npy", np.array([[[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]]], np.float32))
    out = str(tmp_path / "out")
    assert main(["omm", str(tmp_path / "leaf.png"), str(tmp_path / "uv.npy"), "-o", out, "--level", "2"]) == 0
    assert "0 micromaps after reuse" in capsys.readouterr().out
    assert main(["omm", "--verify", out]) == 0
    assert f"{out}: OK (1 triangle, 0 micromaps" in capsys.readouterr().out
