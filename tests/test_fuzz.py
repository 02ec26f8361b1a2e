"""Fuzzing the readers (issue 11), as astc-encoder and meshoptimizer fuzz their decoders.

Every reader of a file omaps takes -- images (``texture.load_alpha``, and the glTF reader's base
colour images), glTF JSON and GLB scenes (``scene.gltf.load_scene``, then the OMM geometry made
from the scene), OMM folders (``omm.verify``, i.e. ``omaps omm --verify``), UV arrays
(``omm.inputs.load_uvs``), codec blocks (``omaps decode``), the hierarchical micromaps' blobs
(``succinct_check``/``csm_check``, then their decoders and lookups) and the micromap extensions of
a glTF file (``EXT_mesh_opacity_micromap``, ``OMAPS_pair_opacity_maps``) -- gets hypothesis-mutated copies of
small valid files written here by our own code: bytes flipped, set, inserted, deleted, truncated;
JSON values replaced by wrong types, negative or huge numbers, NaN; keys removed; GLB headers and
chunk lengths changed; OMM files resized. Each example must give a valid result whose basic
invariants hold, or an ``InputError`` whose message names the file (for a blob in memory, the
problem); any other exception fails.

The fuzz tests carry the ``fuzz`` marker (``pytest -m fuzz``, or ``-m "not fuzz"`` to leave them
out). They are derandomized with no example database, so CI runs the same examples every time;
``OMAPS_FUZZ_SCALE=N`` multiplies the number of examples (and changes which are drawn) for a
deeper local run.
"""

from __future__ import annotations

import base64
import contextlib
import copy
import io
import json
import math
import os
import struct
import tempfile
import traceback
import warnings
import zlib
from functools import lru_cache

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from PIL import Image

from conftest import SCENES, TEXTURES, needs_scenes, needs_shared
from gltf_files import png_bytes, write_quad_gltf
from omaps.alpha_test import MaterialRules
from omaps.cli.main import main
from omaps.codecs import codec_names, get_codec
from omaps.errors import InputError
from omaps import omm_format
from omaps.omm.inputs import scene_spec, load_geometries, load_uvs, texture_spec
from omaps.omm.pipeline import OmmSettings, build
from omaps.omm.verify import verify
from omaps.sampling import FILTERS, WRAP_MODES
from omaps.scene import load_scene
from omaps.scene.gltf import UNCHECKED
from omaps.scene.model import ALPHA_MODES
from omaps.texture import load_alpha
from omaps.codecs.bits import kernel_bytes

pytestmark = pytest.mark.fuzz

SCALE = max(1, int(os.environ.get("OMAPS_FUZZ_SCALE", "1")))


def fuzz_settings(n: int):
    return settings(max_examples=n * SCALE, deadline=None, derandomize=SCALE == 1, database=None,
                    suppress_health_check=list(HealthCheck))


@contextlib.contextmanager
def quiet():
    """Scene and Pillow warnings are expected on corrupt input; the outcome is what is checked."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


# the glTF reader's last resort for an exception its checks missed: the fuzz tests require that
# every problem is caught by a check that says what is wrong, so they never accept this message
SAFETY_NET = UNCHECKED + " ("


def expect_input_error(call, *paths):
    """Run ``call``: its result, or None after an InputError naming one of ``paths`` (a file, or
    a folder the file lies in). Any other exception propagates and fails the test."""
    try:
        out = call()
        event("a valid result")  # pytest --hypothesis-show-statistics shows the mix of outcomes
        return out
    except InputError as exc:
        event("InputError")
        named = [os.path.abspath(p) for p in paths]
        assert exc.path is not None, f"InputError without a file: {exc}"
        got = os.path.abspath(exc.path)
        assert any(got == p or got.startswith(p + os.sep) for p in named), f"{exc} names none of {paths}"
        assert str(exc).startswith(f"{exc.path}: ") and exc.problem
        assert not exc.problem.startswith(SAFETY_NET), "no check caught this: " + "".join(
            traceback.format_exception(exc.__context__))
        return None


# -- byte mutations ------------------------------------------------------------------------------

INTERESTING = (0, 1, 2, 3, 4, 7, 8, 0x7F, 0x80, 0xFF, 0x100, 0x7FFF, 0x8000, 0xFFFF, 0x10000, 0x7FFFFFFF,
               0x80000000, 0xFFFFFFFE, 0xFFFFFFFF)


@st.composite
def mutated_bytes(draw, data: bytes, max_ops: int = 4) -> bytes:
    """``data`` after 1..max_ops of: flip a bit, set a byte, write an interesting 16/32-bit value
    (either endianness), insert random bytes, delete a span, duplicate a span, truncate."""
    b = bytearray(data)
    for _ in range(draw(st.integers(1, max_ops) | st.just(1))):  # often a single change
        op = draw(st.sampled_from(("flip", "byte", "word", "insert", "delete", "duplicate", "truncate")))
        n = len(b)
        if op == "truncate":
            b = b[:draw(st.integers(0, max(0, n - 1)))]
        elif op == "insert":
            i = draw(st.integers(0, n))
            b[i:i] = draw(st.binary(min_size=1, max_size=16))
        elif n == 0:
            continue
        elif op == "flip":
            b[draw(st.integers(0, n - 1))] ^= 1 << draw(st.integers(0, 7))
        elif op == "byte":
            b[draw(st.integers(0, n - 1))] = draw(st.sampled_from((0, 1, 0x7F, 0x80, 0xFF)) | st.integers(0, 255))
        elif op == "word":
            size = draw(st.sampled_from((2, 4)))
            if n >= size:
                i = draw(st.integers(0, n - size))
                v = draw(st.sampled_from(INTERESTING)) & ((1 << 8 * size) - 1)
                b[i:i + size] = v.to_bytes(size, draw(st.sampled_from(("little", "big"))))
        elif op == "delete":
            i = draw(st.integers(0, n - 1))
            del b[i:i + draw(st.integers(1, 32))]
        else:  # duplicate
            i = draw(st.integers(0, n - 1))
            j = min(n, i + draw(st.integers(1, 32)))
            k = draw(st.integers(0, n))
            b[k:k] = b[i:j]
    return bytes(b)


def fix_png_crcs(data: bytes) -> bytes:
    """Recompute the CRC of every whole chunk, so mutations reach the decoder past the checksums
    (as libpng's fuzzers do)."""
    b = bytearray(data)
    pos = 8
    while pos + 12 <= len(b):
        length = int.from_bytes(b[pos:pos + 4], "big")
        end = pos + 8 + length
        if end + 4 > len(b):
            break
        b[end:end + 4] = zlib.crc32(bytes(b[pos + 4:end])).to_bytes(4, "big")
        pos = end + 4
    return bytes(b)


# -- JSON mutations ------------------------------------------------------------------------------

ODD_VALUES = (None, True, False, 0, -1, 1, 2, 3, 7, 255, 65536, 2 ** 31, -(2 ** 31), 2 ** 53, 10 ** 400, 0.5, -0.5,
              1e308, -1e308, math.nan, math.inf, -math.inf, "", "x", "data:", "data:,", "0", [], [0], [None],
              [1, 2], [math.nan] * 4, {}, {"index": 0})
# keys a glTF reader looks at, inserted where they are not
ODD_KEYS = ("byteStride", "byteOffset", "byteLength", "count", "sparse", "normalized", "bufferView", "buffer",
            "matrix", "translation", "rotation", "scale", "children", "mesh", "mode", "indices", "material",
            "texCoord", "sampler", "source", "uri", "extensions", "extensionsRequired", "KHR_texture_transform",
            "EXT_texture_webp", "alphaCutoff", "alphaMode", "baseColorFactor", "magFilter", "wrapS", "scene",
            "COLOR_0", "TEXCOORD_1", "componentType", "type", "min", "max")


def json_paths(doc, prefix=()):
    """Every (path to a value) in a JSON document, containers included."""
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += json_paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += json_paths(v, prefix + (i,))
    return out


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


@st.composite
def mutated_json(draw, doc, max_ops: int = 3, where=None):
    """A deep copy of ``doc`` after 1..max_ops of: replace a value by an odd one, nudge a number
    (+-1, x2, /2, negate), delete a key or list item, duplicate or truncate a list, insert a
    reader's key with an odd value. ``where``: a predicate on paths (tuples of keys) choosing
    which values are mutated (default: all)."""
    d = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, max_ops))):
        paths = [p for p in json_paths(d)[1:] if where is None or where(p)]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent, key = _get(d, path[:-1]), path[-1]
        value = parent[key]
        op = draw(st.sampled_from(("replace", "nudge", "delete", "list", "insert")))
        if op == "replace":
            parent[key] = copy.deepcopy(draw(st.sampled_from(ODD_VALUES)))
        elif op == "nudge" and isinstance(value, (int, float)) and not isinstance(value, bool):
            f = draw(st.sampled_from((lambda v: v + 1, lambda v: v - 1, lambda v: v * 2, lambda v: v // 2,
                                      lambda v: -v, lambda v: v + 4, lambda v: v * 1000)))
            parent[key] = f(value)
        elif op == "delete":
            del parent[key]
        elif op == "list" and isinstance(value, list) and value:
            if draw(st.booleans()):
                value.append(copy.deepcopy(value[draw(st.integers(0, len(value) - 1))]))
            else:
                del value[draw(st.integers(0, len(value) - 1)):]
        elif op == "insert" and isinstance(value, dict):
            value[draw(st.sampled_from(ODD_KEYS))] = copy.deepcopy(draw(st.sampled_from(ODD_VALUES)))
        else:
            parent[key] = copy.deepcopy(draw(st.sampled_from(ODD_VALUES)))
    return d


def dumps(doc) -> str:
    return json.dumps(doc, allow_nan=True)


# -- seeds: small valid files written by our own code ---------------------------------------------

def _image_bytes(im: Image.Image, fmt: str, **kw) -> bytes:
    buf = io.BytesIO()
    im.save(buf, format=fmt, **kw)
    return buf.getvalue()


@lru_cache(maxsize=None)
def image_seeds() -> dict[str, bytes]:
    """One small image per reader path: RGBA, LA, palette with tRNS, 16-bit grey, RGB (no alpha),
    in the formats the README lists."""
    rng = np.random.default_rng(11)
    alpha = (rng.random((6, 7)) * 255).astype(np.uint8)
    alpha[:, :2] = 0
    alpha[:, -2:] = 255
    rgba = np.dstack([alpha, 255 - alpha, np.full_like(alpha, 90), alpha])
    im = Image.fromarray(rgba, "RGBA")
    pal = im.convert("P")
    pal.info["transparency"] = 0
    grey16 = Image.fromarray(alpha.astype(np.uint16) * 257)
    return {
        "rgba.png": _image_bytes(im, "PNG"),
        "la.png": _image_bytes(im.convert("LA"), "PNG"),
        "palette.png": _image_bytes(pal, "PNG", transparency=0),
        "grey16.png": _image_bytes(grey16, "PNG"),
        "rgba.tga": _image_bytes(im, "TGA", compression="tga_rle"),
        "rgba.bmp": _image_bytes(im, "BMP"),
        "rgba.tif": _image_bytes(im, "TIFF"),
        "rgba.webp": _image_bytes(im, "WEBP", lossless=True),
        "rgba.dds": _image_bytes(im, "DDS"),
        "palette.gif": _image_bytes(pal, "GIF", transparency=0),
        "rgb.jpg": _image_bytes(im.convert("RGB"), "JPEG", quality=90),
    }


def check_texture(tex) -> None:
    v = tex.values
    assert v.ndim == 2 and v.shape[0] > 0 and v.shape[1] > 0 and v.dtype.kind == "u"
    assert tex.maxval in (255, 65535) and int(v.max()) <= tex.maxval
    a8 = tex.alpha8
    assert np.all((a8 >= 0) & (a8 <= 255))


def _buffer_uri(blob: bytes) -> str:
    return "data:application/octet-stream;base64," + base64.b64encode(blob).decode()


@lru_cache(maxsize=None)
def gltf_seed() -> dict:
    """A small glTF document that uses most of what the reader reads: a node hierarchy with TRS
    and a matrix, two primitives (indexed triangles; a strip), a sparse accessor, normalized
    interleaved vertex colours with a byte stride, two materials (MASK; BLEND with
    KHR_texture_transform and a nearest / clamp sampler), images as data URIs."""
    with tempfile.TemporaryDirectory() as d:
        path = write_quad_gltf(os.path.join(d, "q.gltf"), np.array([[0, 255], [255, 128]], np.uint8),
                               nodes=[{"translation": [1, 2, 3]}])
        with open(path) as f:
            doc = json.load(f)
    # buffer 1: sparse indices (u8), sparse values (2 x f32), colours (4 x u8 RGBA, stride 8)
    sparse_idx = np.array([1, 3, 0, 0], np.uint8).tobytes()
    sparse_val = np.array([[0.5, 0.5], [0.25, 0.75]], np.float32).tobytes()
    colours = np.zeros((4, 8), np.uint8)
    colours[:, :4] = [[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 200], [9, 9, 9, 255]]
    blob = sparse_idx + sparse_val + colours.tobytes()
    doc["buffers"].append({"byteLength": len(blob), "uri": _buffer_uri(blob)})
    v0 = len(doc["bufferViews"])
    doc["bufferViews"] += [{"buffer": 1, "byteOffset": 0, "byteLength": 4},
                           {"buffer": 1, "byteOffset": 4, "byteLength": 16},
                           {"buffer": 1, "byteOffset": 20, "byteLength": 32, "byteStride": 8}]
    a0 = len(doc["accessors"])
    doc["accessors"] += [
        {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2",
         "sparse": {"count": 2, "indices": {"bufferView": v0, "componentType": 5121},
                    "values": {"bufferView": v0 + 1}}},
        {"bufferView": v0 + 2, "componentType": 5121, "normalized": True, "count": 4, "type": "VEC4"},
    ]
    doc["meshes"][0]["primitives"].append(
        {"attributes": {"POSITION": 0, "TEXCOORD_0": a0, "COLOR_0": a0 + 1}, "mode": 5, "material": 1})
    doc["materials"].append({"name": "blend", "alphaMode": "BLEND",
                             "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.9],
                                                      "baseColorTexture": {"index": 1, "extensions": {
                                                          "KHR_texture_transform": {"offset": [0.5, 0],
                                                                                    "rotation": 0.1,
                                                                                    "scale": [2, 1]}}}}})
    doc["samplers"].append({"magFilter": 9728, "wrapS": 33071, "wrapT": 33648})
    doc["textures"].append({"source": 1, "sampler": 1})
    doc["images"].append({"uri": "data:image/png;base64,"
                                 + base64.b64encode(png_bytes(np.array([[0, 40, 255]], np.uint8))).decode()})
    doc["nodes"] = [{"children": [1], "rotation": [0, 0.6, 0, 0.8]},
                    {"mesh": 0, "scale": [2, 2, 2]},
                    {"mesh": 0, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 5, 0, 0, 1]}]
    doc["scenes"] = [{"nodes": [0, 2]}]
    doc["extensionsUsed"] = ["KHR_texture_transform"]
    return doc


@lru_cache(maxsize=None)
def glb_seed() -> tuple[dict, bytes]:
    """The seed document as a GLB's JSON (buffer 0 without a URI) and its BIN chunk's bytes."""
    doc = copy.deepcopy(gltf_seed())
    uri = doc["buffers"][0].pop("uri")
    return doc, base64.b64decode(uri.split(",", 1)[1])


def glb_bytes(doc: dict, blob: bytes) -> bytes:
    """A GLB container: header, JSON chunk, BIN chunk, each padded to 4 bytes."""
    text = dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(blob), b"BIN\0") + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def check_scene_geometry(path: str) -> None:
    """Read a scene as ``omaps omm`` does (reader, alpha triangles, pairs, alpha tests) and check
    the scene model's invariants; an InputError must name the scene file."""
    scene = expect_input_error(lambda: load_scene(path), path)
    if scene is None:
        return
    check_scene(scene)
    expect_input_error(lambda: load_geometries(scene_spec(path)), path)


def check_scene(scene) -> None:
    nmat, ntex = len(scene.materials), len(scene.textures)
    for m in scene.materials:
        assert m.alpha_mode in ALPHA_MODES and m.filter in FILTERS
        assert m.wrap_u in WRAP_MODES and m.wrap_v in WRAP_MODES
        assert -1 <= m.texture < ntex and isinstance(m.texcoord, int) and m.texcoord >= 0
        assert len(m.base_colour) == 4 and all(isinstance(x, (int, float)) for x in m.base_colour)
        assert isinstance(m.cutoff, (int, float))
    for t in scene.textures:
        assert (t.alpha is None) == (t.problem is not None) and t.maxval in (255, 65535)
        if t.alpha is not None:
            assert t.alpha.ndim == 2 and t.alpha.size and int(t.alpha.max()) <= t.maxval
            assert t.rgb is not None and t.rgb.shape == t.alpha.shape + (3,)
    for mesh in scene.meshes:
        for p in mesh.primitives:
            nv = len(p.positions)
            assert p.positions.shape == (nv, 3) and p.uvs.shape == (nv, 2) and np.isfinite(p.uvs).all()
            assert p.triangles.ndim == 2 and p.triangles.shape[1] == 3 and p.triangles.dtype.kind == "i"
            assert p.triangles.size == 0 or (p.triangles.min() >= 0 and p.triangles.max() < nv)
            assert p.unknown.shape == (len(p.triangles),) and p.unknown.dtype == bool
            assert 0 <= p.material < nmat
            if p.vertex_alpha is not None:
                assert p.vertex_alpha.shape == (nv,) and np.all((p.vertex_alpha >= 0) & (p.vertex_alpha <= 1))
    for mi, mat in scene.instances:
        assert 0 <= mi < len(scene.meshes) and mat.shape == (4, 4)
    for k, m in enumerate(scene.materials):
        if scene.alpha_tested()[k]:
            scene.alpha_test(k, MaterialRules())


# -- images --------------------------------------------------------------------------------------

@st.composite
def fuzzed_image(draw):
    name = draw(st.sampled_from(sorted(image_seeds())))
    data = draw(mutated_bytes(image_seeds()[name]))
    if name.endswith(".png") and draw(st.booleans()):
        data = fix_png_crcs(data)
    return name, data


@fuzz_settings(250)
@given(fuzzed_image(), st.sampled_from((None, "A", "R", "L", "1")))
def test_fuzzed_image_bytes(image, channel):
    """``load_alpha`` (every command's texture reader) on mutated image bytes."""
    name, data = image
    with tempfile.TemporaryDirectory() as d, quiet():
        path = os.path.join(d, name)
        with open(path, "wb") as f:
            f.write(data)
        tex = expect_input_error(lambda: load_alpha(path, channel), path)
        if tex is not None:
            check_texture(tex)


@fuzz_settings(100)
@given(fuzzed_image())
def test_fuzzed_image_in_a_gltf_scene(image):
    """The glTF reader's own image decoding: a base colour image that cannot be decoded is a
    texture with a ``problem`` (a warning), never an exception."""
    name, data = image
    doc = copy.deepcopy(gltf_seed())
    doc["images"][0] = {"uri": name}
    with tempfile.TemporaryDirectory() as d, quiet():
        with open(os.path.join(d, name), "wb") as f:
            f.write(data)
        path = os.path.join(d, "scene.gltf")
        with open(path, "w") as f:
            f.write(dumps(doc))
        scene = load_scene(path)  # an image problem is a warning, so this always loads
        check_scene(scene)
        tex = scene.textures[scene.materials[0].texture]
        assert tex.name == name
        expect_input_error(lambda: load_geometries(scene_spec(path)), path)


# -- glTF JSON and GLB ---------------------------------------------------------------------------

@fuzz_settings(300)
@given(mutated_json(gltf_seed()), st.booleans(), st.data())
def test_fuzzed_gltf_json(doc, byte_level, data):
    """The glTF reader on mutated JSON: wrong types, negative / huge indices and counts, missing
    keys, NaN, bad strides, offsets and data URIs; sometimes then mutated as text."""
    text = dumps(doc).encode()
    if byte_level:
        text = data.draw(mutated_bytes(text, 2))
    with tempfile.TemporaryDirectory() as d, quiet():
        path = os.path.join(d, "scene.gltf")
        with open(path, "wb") as f:
            f.write(text)
        check_scene_geometry(path)


GLB_FIELDS = {"magic": 0, "version": 4, "length": 8, "json length": 12, "json type": 16}


@st.composite
def fuzzed_glb(draw):
    doc, blob = glb_seed()
    how = draw(st.sampled_from(("bytes", "header", "json")))
    if how == "json":  # a mutated document in a well-formed container
        return glb_bytes(draw(mutated_json(doc)), blob)
    data = bytearray(glb_bytes(doc, blob))
    if how == "bytes":
        return draw(mutated_bytes(bytes(data)))
    json_len = struct.unpack_from("<I", data, 12)[0]
    fields = dict(GLB_FIELDS, **{"bin length": 20 + json_len, "bin type": 24 + json_len})
    for _ in range(draw(st.integers(1, 2))):
        at = fields[draw(st.sampled_from(sorted(fields)))]
        value = draw(st.sampled_from(INTERESTING) | st.integers(0, len(data) + 16)
                     | st.sampled_from((0x46546C67, 0x4E4F534A, 0x004E4942)))  # glTF, JSON, BIN
        struct.pack_into("<I", data, at, value)
    return bytes(data)


@fuzz_settings(250)
@given(fuzzed_glb())
def test_fuzzed_glb_bytes(data):
    """The GLB container: wrong magic, version, total and chunk lengths and types, bytes
    flipped / inserted / truncated anywhere, and mutated JSON inside a sound container."""
    with tempfile.TemporaryDirectory() as d, quiet():
        path = os.path.join(d, "scene.glb")
        with open(path, "wb") as f:
            f.write(data)
        check_scene_geometry(path)


# -- OMM folders ---------------------------------------------------------------------------------

OMM_UVS = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]], [[0.1, 0.1], [0.5, 0.2], [0.3, 0.9]],
                    [[0.6, 0.6], [0.9, 0.7], [0.6, 0.95]], [[0.2, 0.2], [0.2, 0.2], [0.2, 0.2]]], np.float64)


@pytest.fixture(scope="module")
def omm_seeds(tmp_path_factory):
    """OMM folders written by ``omaps.omm.write``: 4-state at level 2 from the texture, 2-state
    dynamic, and pair maps through vq2 (with pair_blocks.bin and omm_pairs.bin); their recorded
    input (a texture and a UV array) lies beside them, so ``verify`` re-bakes."""
    from omaps.omm import write

    root = tmp_path_factory.mktemp("omm_seeds")
    alpha = np.zeros((8, 8), np.uint8)
    alpha[2:6, 1:7] = 255
    alpha[3, 3] = 120
    tex_path, uv_path = root / "leaf.png", root / "uvs.npy"
    tex_path.write_bytes(png_bytes(alpha))
    np.save(uv_path, OMM_UVS)
    spec = texture_spec(str(tex_path), str(uv_path))
    geoms, _, _ = load_geometries(spec)
    out = {}
    for name, s in {"level2": OmmSettings(level=2),
                    "dynamic2state": OmmSettings(format="2state", dynamic_scale=1.0, max_level=3, promotion="hashed"),
                    "vq2": OmmSettings(source="vq2", encoder="best", effort="fast")}.items():
        folder = root / name
        write(folder, build(geoms, s), {"input": spec, "skipped_primitives": [], "warnings": []})
        out[name] = {f: (folder / f).read_bytes() for f in sorted(os.listdir(folder))}
    return out, (str(tex_path), str(uv_path))


@st.composite
def omm_mutations(draw, files: dict):
    """A folder's files after 1..3 of: a .bin file's bytes mutated (resized, truncated, values
    set), a JSON file's values mutated or its text damaged, a file removed."""
    files = dict(files)
    for _ in range(draw(st.integers(1, 3))):
        name = draw(st.sampled_from(sorted(files)))
        op = draw(st.sampled_from(("bytes", "bytes", "json", "remove")))
        if op == "remove":
            del files[name]
            if not files:
                break
        elif op == "json" and name.endswith(".json") and _parses(files[name]):
            files[name] = dumps(draw(mutated_json(json.loads(files[name])))).encode()
        else:
            files[name] = draw(mutated_bytes(files[name], 3))
    return files


def _parses(raw: bytes) -> bool:
    try:
        json.loads(raw)
        return True
    except ValueError:  # a JSON file an earlier mutation damaged
        return False


def check_omm_result(res, problems, done) -> None:
    assert isinstance(problems, list) and all(isinstance(p, str) for p in problems) and done
    n_maps = len(res.triangles)
    assert np.all((res.index >= -4) & (res.index < n_maps))
    for t in range(len(res.index)):
        s = res.triangle_states(t)
        assert s.ndim == 1 and len(s) >= 1 and s.max() <= 3
    for i in range(n_maps):
        lv = int(res.triangles["level"][i])
        assert len(res.micromap_states(i)) == 4 ** lv


@fuzz_settings(250)
@given(st.data())
def test_fuzzed_omm_folder(omm_seeds, data):
    """``omaps omm --verify`` (``omm.verify``: the layout checks of ``omm.files.read``, the pair
    blocks, the re-bake) on mutated OMM folders."""
    seeds, inputs = omm_seeds
    files = data.draw(omm_mutations(seeds[data.draw(st.sampled_from(sorted(seeds)))]))
    with tempfile.TemporaryDirectory() as d, quiet():
        folder = os.path.join(d, "omm")
        os.mkdir(folder)
        for name, raw in files.items():
            with open(os.path.join(folder, name), "wb") as f:
                f.write(raw)
        out = expect_input_error(lambda: verify(folder), folder, *inputs)
        if out is not None:
            check_omm_result(*out)


# -- UV arrays and codec blocks --------------------------------------------------------------------

@lru_cache(maxsize=None)
def npy_seed() -> bytes:
    buf = io.BytesIO()
    np.save(buf, OMM_UVS.astype(np.float32))
    return buf.getvalue()


@fuzz_settings(150)
@given(mutated_bytes(npy_seed()))
def test_fuzzed_uv_array(data):
    """``load_uvs`` (``omaps omm TEXTURE UVS.npy``, ``omaps bake --uvs``) on mutated .npy bytes."""
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "uvs.npy")
        with open(path, "wb") as f:
            f.write(data)
        uvs = expect_input_error(lambda: load_uvs(path), path)
        if uvs is not None:
            assert uvs.ndim == 3 and uvs.shape[1:] == (3, 2) and uvs.dtype.kind == "f"


CODECS = ("sq4", "sq16", *codec_names())  # two raw sizes and every codec of the registry (plug-ins' too)


@fuzz_settings(200)
@given(st.sampled_from(CODECS), st.data())
def test_fuzzed_codec_blocks_decode_totally(name, data):
    """Decoders are total: every block of the right size decodes to states 0..2 (or, for a raw
    map holding the unused code 3, an InputError), and the random-access lookup agrees."""
    codec = get_codec(name)
    block = data.draw(st.binary(min_size=codec.block_bytes, max_size=codec.block_bytes)
                      | st.sampled_from((b"\xff" * codec.block_bytes, b"\xaa" * codec.block_bytes)))
    try:
        m = codec.decode(block)
    except InputError as exc:
        assert name.startswith("sq") and "3" in exc.problem
        return
    n = codec.map_size
    assert m.shape == (n, n) and m.max() <= 2
    arr = kernel_bytes(block)
    ys, xs = np.divmod(np.arange(n * n), n)
    for x, y in zip(xs[::7], ys[::7]):
        assert codec.lookup(arr, int(x), int(y)) == m[y, x]


@fuzz_settings(60)
@given(st.sampled_from(CODECS), st.data())
def test_fuzzed_block_file_through_omaps_decode(name, data):
    """``omaps decode FILE --codec NAME`` on block files of any content and size: exit 0 with a
    map, or exit 2 naming the file."""
    codec = get_codec(name)
    size = data.draw(st.sampled_from((codec.block_bytes, codec.block_bytes, 0, codec.block_bytes + 1, 3)))
    block = data.draw(st.binary(min_size=size, max_size=size))
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "block.bin")
        with open(path, "wb") as f:
            f.write(block)
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = main(["decode", path, "--codec", name, "--json"])
        if rc == 0:
            m = np.array(json.loads(out.getvalue())["states"])
            assert m.shape == (codec.map_size, codec.map_size) and m.max() <= 2
        else:
            assert rc == 2 and err.getvalue().startswith(f"omaps: error: {path}: "), err.getvalue()


# -- real files as seeds (skipped without ../shared) -----------------------------------------------

@needs_shared
@fuzz_settings(60)
@given(st.data())
def test_fuzzed_real_textures(data):
    """Mutations of real texture files (read from ../shared, written only to a temporary folder)."""
    files = sorted(TEXTURES.glob("*.png"))[:12]
    src = data.draw(st.sampled_from(files))
    raw = data.draw(mutated_bytes(src.read_bytes()))
    if data.draw(st.booleans()):
        raw = fix_png_crcs(raw)
    with tempfile.TemporaryDirectory() as d, quiet():
        path = os.path.join(d, src.name)
        with open(path, "wb") as f:
            f.write(raw)
        tex = expect_input_error(lambda: load_alpha(path), path)
        if tex is not None:
            check_texture(tex)


@lru_cache(maxsize=None)
def smallpine_doc() -> dict:
    """smallpine's glTF with its buffer and image URIs made absolute (the mutated copy is written
    elsewhere; the data stays in ../shared)."""
    folder = SCENES / "smallpine"
    doc = json.loads((folder / "scene.gltf").read_text())
    for item in doc.get("buffers", []) + doc.get("images", []):
        if "uri" in item:
            item["uri"] = str(folder / item["uri"])
    return doc


@needs_scenes
@fuzz_settings(30)
@given(st.data())
@pytest.mark.long
def test_fuzzed_real_scene_json(data):
    """Mutations of a real glTF (smallpine): its JSON mutated, its buffer read from ../shared."""
    doc = data.draw(mutated_json(smallpine_doc()))
    with tempfile.TemporaryDirectory() as d, quiet():
        path = os.path.join(d, "scene.gltf")
        with open(path, "w") as f:
            f.write(dumps(doc))
        check_scene_geometry(path)


@lru_cache(maxsize=None)
def palm_glb() -> tuple[dict, bytes]:
    """palm.glb's JSON chunk (parsed) and BIN chunk (images in buffer views), read from ../shared."""
    data = (SCENES / "palm.glb").read_bytes()
    json_len = struct.unpack_from("<I", data, 12)[0]
    bin_len = struct.unpack_from("<I", data, 20 + json_len)[0]
    return json.loads(data[20:20 + json_len]), data[28 + json_len:28 + json_len + bin_len]


@needs_scenes
@fuzz_settings(20)
@given(st.data())
def test_fuzzed_real_glb(data):
    """Mutations of a real GLB (palm.glb): its JSON chunk mutated and packed again with its BIN
    chunk (geometry and both images in buffer views), written to a temporary folder."""
    doc, blob = palm_glb()
    with tempfile.TemporaryDirectory() as d, quiet():
        path = os.path.join(d, "palm.glb")
        with open(path, "wb") as f:
            f.write(glb_bytes(data.draw(mutated_json(doc)), blob))
        check_scene_geometry(path)


# -- the CLI: exit 2 and "omaps: error: FILE: ..." for each reader -----------------------------------

def _cli_error(argv, path, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"omaps: error: {path}: "), err
    return err


def test_cli_corrupt_image(tmp_path, capsys):
    path = tmp_path / "leaf.png"
    path.write_bytes(image_seeds()["rgba.png"][:60])
    out = tmp_path / "leaf.vq2"
    _cli_error(["encode", str(path), "--codec", "vq2", "-o", str(out)], path, capsys)
    assert not out.exists()


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_cli_corrupt_scene(tmp_path, capsys, suffix):
    doc, blob = copy.deepcopy(glb_seed()) if suffix == ".glb" else (copy.deepcopy(gltf_seed()), None)
    doc["accessors"][0]["count"] = -3
    path = tmp_path / f"scene{suffix}"
    path.write_bytes(glb_bytes(doc, blob) if suffix == ".glb" else dumps(doc).encode())
    out = tmp_path / "omm"
    _cli_error(["omm", str(path), "-o", str(out)], path, capsys)
    assert not out.exists()


def test_cli_corrupt_omm_folder(omm_seeds, tmp_path, capsys):
    folder = tmp_path / "omm"
    folder.mkdir()
    for name, raw in omm_seeds[0]["level2"].items():
        (folder / name).write_bytes(raw[:-3] if name == omm_format.TRIANGLES_FILE else raw)
    _cli_error(["omm", "--verify", str(folder)], folder / omm_format.TRIANGLES_FILE, capsys)


def test_cli_corrupt_uv_array(tmp_path, capsys):
    tex = tmp_path / "leaf.png"
    tex.write_bytes(png_bytes(np.full((4, 4), 255, np.uint8)))
    uvs = tmp_path / "uvs.npy"
    uvs.write_bytes(npy_seed()[:40])
    _cli_error(["omm", str(tex), str(uvs), "-o", str(tmp_path / "omm")], uvs, capsys)


def test_cli_corrupt_block(tmp_path, capsys):
    path = tmp_path / "map.sq4"
    path.write_bytes(b"\xff" * get_codec("sq4").block_bytes)  # code 3 is no state
    _cli_error(["decode", str(path), "--codec", "sq4"], path, capsys)


# -- regressions: crashes the fuzzing found, and cases found by reading the reader -----------------

def _edit(path_and_value):
    def apply(doc):
        *keys, last = path_and_value[0]
        target = _get(doc, keys)
        if path_and_value[1] is _DELETE:
            del target[last]
        else:
            target[last] = path_and_value[1]
        return doc
    return apply


_DELETE = object()
GLTF_REGRESSIONS = [  # (a change to the seed document, what the error says)
    ((("samplers", 0), None), "sampler 0 is None, not an object"),  # was AttributeError
    ((("accessors", 1, "count"), 0), "has 0 elements, POSITION has 4"),  # was IndexError downstream
    ((("accessors", 0, "byteOffset"), -8), "byteOffset is -8"),  # read memory before the buffer
    ((("bufferViews", 5, "byteStride"), 2), "smaller than one element"),  # overlapping elements
    ((("bufferViews", 0, "byteStride"), -12), "byteStride is -12"),  # negative strides
    ((("accessors", 4, "bufferView"), _DELETE), None),  # zeros: a valid result
    ((("accessors", 4), {"componentType": 5121, "normalized": True, "count": 2 ** 30, "type": "VEC4"}),
     "has no bufferView and 1073741824 elements"),  # a 4 GiB allocation the file does not pay for
    ((("nodes", 2, "children"), [1]), "node 1 has two parents"),  # shared subtrees grow exponentially
    ((("nodes", 1, "scale"), [2, 2]), "scale must be 3 finite numbers"),  # was ValueError: unpacking
    ((("nodes", 1, "scale"), [2, math.inf, 2]), "scale must be 3 finite numbers"),
    ((("nodes", 1, "scale"), [2, 10 ** 400, 2]), "cannot read glTF (OverflowError"),  # pygltflib's float()
    ((("materials", 1, "pbrMetallicRoughness", "baseColorFactor"), [1, 1, 1]), "baseColorFactor must be 4"),
    ((("materials", 0, "alphaCutoff"), math.nan), "alphaCutoff must be 1 finite number"),
    ((("materials", 0, "alphaMode"), 5), "unknown alphaMode '5'"),  # pygltflib makes it a string
    ((("samplers", 1, "wrapS"), 5), "wrapS is 5, not a glTF wrap mode"),  # was read as REPEAT
    ((("samplers", 1, "wrapS"), [33071]), "cannot read glTF (TypeError"),  # pygltflib's int()
    ((("meshes", 0, "primitives", 0, "indices"), 0), "indices accessor 0 is not of an unsigned integer type"),
    ((("meshes", 0, "primitives", 1, "mode"), 9), "mode is 9, outside 0..6"),
    ((("buffers", 1, "uri"), "data:application/octet-stream,abc"), "is not base64 data"),
    ((("buffers", 1, "uri"), "bin\0ary.bin"), "holds a NUL character"),  # was ValueError: embedded null
    ((("materials", 1, "pbrMetallicRoughness", "baseColorTexture", "extensions", "KHR_texture_transform",
       "offset"), [0, "x"]), "texture transform offset must be 2 finite numbers"),
]


@pytest.mark.parametrize("change, message", GLTF_REGRESSIONS, ids=[str(c[0][0]) for c in GLTF_REGRESSIONS])
def test_gltf_regressions(tmp_path, change, message):
    doc = _edit(change)(copy.deepcopy(gltf_seed()))
    path = tmp_path / "scene.gltf"
    path.write_text(dumps(doc))
    with quiet():
        if message is None:
            check_scene(load_scene(path))
            return
        with pytest.raises(InputError) as info:
            load_scene(path)
    assert info.value.path == str(path) and message in info.value.problem, info.value.problem


def test_image_regressions(tmp_path):
    """Pillow raises more than OSError on hostile files: a GIF declaring 65535 x 6 ... pixels
    (DecompressionBombError) and a DDS with unknown pixel format flags (NotImplementedError)
    were uncaught; they are errors naming the file; a glTF image with the first is an error naming
    the scene (Pillow's decompression-bomb limit: never decoded), with the second a warning."""
    gif = bytearray(image_seeds()["palette.gif"])
    gif[6:10] = b"\xff\xff\xff\xff"  # logical screen 65535 x 65535
    dds = bytearray(image_seeds()["rgba.dds"])
    struct.pack_into("<I", dds, 80, 0x4100)  # pixel format flags: no known combination
    for name, data, kind in (("big.gif", bytes(gif), "DecompressionBombError"),
                             ("odd.dds", bytes(dds), "NotImplementedError")):
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(InputError, match=kind) as info:
            load_alpha(path)
        assert info.value.path == str(path)
        doc = copy.deepcopy(gltf_seed())
        doc["images"][0] = {"uri": name}
        scene_path = tmp_path / "scene.gltf"
        scene_path.write_text(dumps(doc))
        if kind == "DecompressionBombError":
            with quiet(), pytest.raises(InputError, match="decompression-bomb limit") as info:
                load_scene(scene_path)
            assert info.value.path == str(scene_path) and name in info.value.problem
            continue
        with quiet():
            scene = load_scene(scene_path)
        assert kind in scene.textures[0].problem and scene.textures[0].alpha is None


def test_uv_array_and_omm_regressions(omm_seeds, tmp_path):
    """np.load's EOFError / SyntaxError on a damaged header, and omm.json fields of the wrong type
    (settings null: TypeError; format null: an InputError naming no file), were uncaught."""
    for cut in (20, 60, 100):
        path = tmp_path / f"uvs{cut}.npy"
        path.write_bytes(npy_seed()[:cut])
        with pytest.raises(InputError) as info:
            load_uvs(path)
        assert info.value.path == str(path)
    for key, value, message in (("settings", None, "settings is None"), ("format", None, "format None"),
                                ("input", {"kind": "texture"}, "input.texture is None"),
                                ("pair_blocks", {"codec": "nope"}, "pair_blocks.codec is 'nope'")):
        folder = tmp_path / f"omm_{key}"
        folder.mkdir()
        for name, raw in omm_seeds[0]["vq2"].items():
            if name == omm_format.SUMMARY_FILE:
                summary = json.loads(raw)
                summary[key] = value
                raw = dumps(summary).encode()
            (folder / name).write_bytes(raw)
        with pytest.raises(InputError) as info:
            verify(folder)
        assert info.value.path == str(folder / omm_format.SUMMARY_FILE) and message in info.value.problem


# -- URIs of an untrusted asset (docs/guide/untrusted.md) ------------------------------------------

URI_PARTS = ["..", ".", "inside.bin", "outside", "secret.bin", "link", "sub", "%2e%2e", "%2E%2e", "%2f", "%5c",
             "\\", "C:", "c:", "", "%00"]
URI_PREFIXES = ["", "/", "//", "\\\\", "file://", "file:///", "file:", "http://", "https://", "HTTP://", "ftp://",
                "C:\\", "C:/", "data:", "{outside}/", "{asset}/", "file://{outside}/", "file://localhost{outside}/"]


@st.composite
def asset_uris(draw):
    """A buffer URI drawn from absolute paths, ``..``, symbolic links, schemes, percent-encoded
    ``..`` and separators, Windows drive letters and back-slashes."""
    relative = draw(st.booleans())  # half of them relative paths ending in a file name, often readable
    prefix = "" if relative else draw(st.sampled_from(URI_PREFIXES))
    parts = draw(st.lists(st.sampled_from(URI_PARTS), min_size=0 if relative else 1, max_size=5))
    if relative:
        parts.append(draw(st.sampled_from(["inside.bin", "secret.bin", "outside"])))
    sep = draw(st.sampled_from(["/", "/", "/", "\\", "%2F"]))
    return prefix + sep.join(parts)


@lru_cache(maxsize=1)
def _uri_tree() -> str:
    """tmp/asset/{scene.gltf, inside.bin, sub/, link -> ../outside}, tmp/outside/secret.bin: the
    inside buffer's quad at the origin, the outside one's (the same size) moved to x = 100."""
    top = tempfile.mkdtemp()
    asset, outside = os.path.join(top, "asset"), os.path.join(top, "outside")
    os.makedirs(os.path.join(asset, "sub"))
    os.makedirs(os.path.join(outside, "sub"))
    os.symlink(outside, os.path.join(asset, "link"))
    doc, blob = glb_seed()
    n = doc["accessors"][0]["count"]
    moved = bytearray(blob)
    pos = np.frombuffer(blob, np.float32, 3 * n, doc["bufferViews"][0].get("byteOffset", 0)).copy()
    pos[0::3] += 100
    off = doc["bufferViews"][0].get("byteOffset", 0)
    moved[off:off + pos.nbytes] = pos.tobytes()
    for folder, data in ((asset, blob), (outside, bytes(moved)), (os.path.join(asset, "sub"), blob),
                         (os.path.join(outside, "sub"), bytes(moved))):
        for name in ("inside.bin", "secret.bin"):
            with open(os.path.join(folder, name), "wb") as f:
                f.write(data)
    with open(os.path.join(outside, "outside"), "wb") as f:
        f.write(bytes(moved))
    return top


@fuzz_settings(300)
@given(asset_uris())
def test_fuzzed_asset_uris_never_read_outside(uri):
    """Whatever the URI, a scene loads only from a file under its folder (its geometry the inside
    quad's, at the origin) or is refused with an InputError naming the file; a URI with a scheme
    or a Windows path never loads."""
    top = _uri_tree()
    asset, outside = os.path.join(top, "asset"), os.path.join(top, "outside")
    uri = uri.format(asset=asset, outside=outside)
    doc, _ = glb_seed()
    doc = copy.deepcopy(doc)
    doc["buffers"][0]["uri"] = uri
    fd, path = tempfile.mkstemp(suffix=".gltf", dir=asset)
    with os.fdopen(fd, "w") as f:
        f.write(dumps(doc))
    try:
        with quiet():
            try:
                scene = load_scene(path)
            except InputError as exc:
                assert exc.path == path and UNCHECKED not in exc.problem, exc
                event("refused")
                return
        event("read")
        xs = np.concatenate([p.positions[:, 0] for m in scene.meshes for p in m.primitives])
        assert xs.max() < 50, f"{uri!r} read the outside quad"
        low = uri.lower()
        assert not low.startswith(("http", "ftp", "c:", "\\", "//")) and "\\" not in uri, uri
    finally:
        os.remove(path)


# -- hierarchical micromaps: succinct and csm blobs -------------------------------------------------
# Their readers take a blob, a level and (csm) a micromap count. ``check`` validates every field a
# lookup reads; ``decode`` checks first. Each example: an InputError, or states 0..2 that the
# random-access lookups (numba kernels, no bounds checks: run only on blobs ``check`` passed) give
# too, at every micro-triangle tried.

ODD_LEVELS = (-1, 13, 2.5, "3", None, True)


@lru_cache(maxsize=None)
def hierarchical_seeds() -> dict[int, tuple[bytes, bytes, int]]:
    """Per level 0..6: a succinct blob of one structured micromap and a csm blob of three."""
    from omaps.codecs import csm_encode, succinct_encode

    rng = np.random.default_rng(29)
    out = {}
    for level in range(7):
        maps = []
        for _ in range(3):
            coarse = int(rng.integers(0, level + 1))
            m = np.repeat(rng.integers(0, 3, 4 ** coarse), 4 ** (level - coarse)).astype(np.uint8)
            flips = rng.integers(0, 4 ** level, 1 + 4 ** level // 8)
            m[flips] = rng.integers(0, 3, len(flips))
            maps.append(m)
        out[level] = (succinct_encode(maps[0], level), csm_encode(np.stack(maps), level)[0], 3)
    return out


@st.composite
def hierarchical_blob(draw, which: int):
    """(blob, level, count): a seed blob (mutated or not) at its level or another, or random
    bytes; now and then an odd level."""
    level = draw(st.integers(0, 6))
    seed = hierarchical_seeds()[level][which]
    blob = draw(st.just(seed) | mutated_bytes(seed) | st.binary(max_size=64))
    lv = draw(st.just(level) | st.integers(0, 12) | st.sampled_from(ODD_LEVELS))
    count = draw(st.just(3) | st.integers(0, 5) | st.sampled_from((-1, 2 ** 31, 2 ** 40, 1.5)))
    return blob, lv, count


def _micro_triangles(data, level: int, n: int = 48) -> list[int]:
    rng = np.random.default_rng(len(data))
    return sorted(set(rng.integers(0, 4 ** level, n).tolist()) | {0, 4 ** level - 1})


@fuzz_settings(300)
@given(hierarchical_blob(0), st.sampled_from((0, 0, 0, 3, 8)))
def test_fuzzed_succinct_blobs(case, start):
    from omaps.codecs import succinct_check, succinct_decode, succinct_lookup

    blob, level, _ = case
    try:
        bits = succinct_check(blob, level, start)
    except InputError:
        event("InputError")
        with pytest.raises(InputError):
            succinct_decode(blob, level, start)
        return
    event("a valid blob")
    assert start + bits <= 8 * len(blob)
    m = succinct_decode(blob, level, start)
    assert m.shape == (4 ** level,) and m.max() <= 2
    arr = kernel_bytes(blob)
    for k in _micro_triangles(blob, level):
        assert succinct_lookup(arr, start, level, k) == m[k]


@fuzz_settings(300)
@given(hierarchical_blob(1))
def test_fuzzed_csm_blobs(case):
    from omaps.codecs import csm_check, csm_decode, csm_lookup

    blob, level, count = case
    try:
        arr = csm_check(blob, level, count)
    except InputError:
        event("InputError")
        with pytest.raises(InputError):
            csm_decode(blob, level, count)
        return
    event("a valid blob")
    small = count * 4 ** level <= 1 << 16  # decode materialises every micromap
    m = csm_decode(blob, level, count) if small else None
    for t in range(min(count, 8)):
        for k in _micro_triangles(blob, level, 16):
            got = csm_lookup(arr, level, t, k)
            assert 0 <= got <= 2 and (m is None or got == m[t, k])
    if m is not None:
        assert m.shape == (count, 4 ** level) and (m.size == 0 or m.max() <= 2)


def test_hierarchical_regressions():
    """Blobs the fuzz tests found or that state a rule: each refused with its problem named."""
    from omaps.codecs import csm_check, csm_decode, csm_encode, succinct_decode, succinct_encode

    cases = [
        (lambda: succinct_decode(b"", 3), "header runs past"),
        (lambda: succinct_decode(b"\xff", 1), "run past the end"),  # n_T 1, internal root: its 4 leaves missing
        (lambda: succinct_decode(bytes([0b11111111]) * 4, 2), "node count"),  # n_T = 7: not 1 mod 4
        (lambda: succinct_decode(bytes([0b1101]), 1), "code 3"),  # n_T 1, a leaf root holding code 3
        (lambda: csm_decode(b"\x01\x00\x00\x00" + b"\xff" * 4, 2, 1), "references itself"),
        (lambda: csm_decode(b"\xff\xff\xff\xff", 2, 1), "bits, the data"),  # 2^32 - 1 nodes
        (lambda: csm_decode(csm_encode(np.arange(16)[None] % 3, 2)[0], 1, 1), "deeper than the level"),
        (lambda: csm_decode(csm_encode(np.arange(16)[None] % 3, 2)[0], 2, 2 ** 40), "bits, the data"),
    ]
    for call, message in cases:
        with pytest.raises(InputError, match=message):
            call()
    for level in range(0, 7, 3):  # valid blobs read the same as before the checks
        m = (np.arange(4 ** level) // 5 % 3).astype(np.uint8)
        assert np.array_equal(succinct_decode(succinct_encode(m, level), level), m)
        blob, _ = csm_encode(np.stack([m, m[::-1]]), level)
        assert csm_check(blob, level, 2).tobytes() == blob


# -- EXT_mesh_opacity_micromap (and OMAPS_pair_opacity_maps) in a glTF file -------------------------

@lru_cache(maxsize=None)
def micromap_gltf_seed() -> dict:
    """A quad baked by ``omaps omm --from vq2`` into a .gltf: both extensions, data URIs only."""
    alpha = np.zeros((16, 16), np.uint8)
    alpha[:, :7] = 255
    alpha[3:6, 10:13] = 255
    with tempfile.TemporaryDirectory() as d:
        src = write_quad_gltf(os.path.join(d, "q.gltf"), alpha)
        out = os.path.join(d, "o.gltf")
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["omm", src, "-o", out, "--quiet", "--from", "vq2"]) == 0
        with open(out) as f:
            doc = json.load(f)
    assert "EXT_mesh_opacity_micromap" in doc["extensions"] and "OMAPS_pair_opacity_maps" in doc["extensions"]
    return doc


def _extension_path(doc):
    """Paths into the extensions' JSON and the bufferViews, accessors and buffer they add (not
    their ``extras``): where the micromap readers look."""
    ext = doc["extensions"]["EXT_mesh_opacity_micromap"]["micromaps"][0]
    pair = doc["extensions"]["OMAPS_pair_opacity_maps"]["maps"][0]
    prim = doc["meshes"][0]["primitives"][0]["extensions"]
    views = {ext["data"], ext["triangles"], pair["blocks"], prim["OMAPS_pair_opacity_maps"]["pairs"]}
    views |= {doc["accessors"][prim["EXT_mesh_opacity_micromap"]["micromapIndices"]]["bufferView"]}
    accessors = {prim["EXT_mesh_opacity_micromap"]["micromapIndices"]}

    def where(path):
        if "extras" in path:
            return False
        return (path[:1] == ("extensions",) or "extensions" in path[:5] and path[:1] == ("meshes",)
                or path[:1] == ("extensionsUsed",)
                or (len(path) >= 2 and path[0] == "bufferViews" and path[1] in views)
                or (len(path) >= 2 and path[0] == "accessors" and path[1] in accessors)
                or path[:2] == ("buffers", len(doc["buffers"]) - 1) and path[2:] != ("uri",))
    return where


@fuzz_settings(300)
@given(st.data())
def test_fuzzed_micromap_extension_json(data):
    """The micromap extensions' JSON (and the bufferViews, accessor and byteLength they use)
    mutated, now and then their binary records too: the scene loads and its stored micromaps
    trace (``omm``, ``file:vq2``), or an InputError names the file and the problem."""
    from omaps.scene.alpha import alpha_triangles
    from omaps.schemes import get_scheme
    from omaps.trace.stored import stored_maps

    seed = micromap_gltf_seed()
    doc = data.draw(mutated_json(seed, max_ops=3, where=_extension_path(seed)))
    last = len(doc.get("buffers") or []) - 1
    if data.draw(st.booleans()) and last >= 0 and isinstance(doc["buffers"][last], dict) \
            and isinstance(doc["buffers"][last].get("uri"), str) and "," in doc["buffers"][last]["uri"]:
        head, b64 = doc["buffers"][last]["uri"].split(",", 1)
        blob = data.draw(mutated_bytes(base64.b64decode(b64), max_ops=2))
        doc["buffers"][last]["uri"] = head + "," + base64.b64encode(blob).decode()
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "m.gltf")
        with open(path, "w") as f:
            f.write(dumps(doc))
        with quiet():
            scene = expect_input_error(lambda: load_scene(path), path)
            if scene is None:
                return
            at = alpha_triangles(scene)
            for name in ("omm", "file:vq2"):
                sm = expect_input_error(lambda: stored_maps(at, scene, get_scheme(name)), path)
                if sm is not None:
                    assert len(sm.rows) == at.count and (not at.count or sm.rows.max() >= 0)


MICROMAP_REGRESSIONS = [  # (path, value) in the seed, the problem named
    (("extensions", "EXT_mesh_opacity_micromap", "micromaps", 0, "usageCounts"), [-1], "usage entry"),
    (("extensions", "EXT_mesh_opacity_micromap", "micromaps", 0, "usageLevels"), [13], "usage entry"),
    (("extensions", "EXT_mesh_opacity_micromap", "micromaps", 0, "data"), 2 ** 40, "bufferView"),
    (("extensions", "EXT_mesh_opacity_micromap", "micromaps", 0, "triangles"), "4", "not a bufferView index"),
    (("extensions", "EXT_mesh_opacity_micromap", "micromaps"), {}, "micromaps array"),
    (("meshes", 0, "primitives", 0, "extensions", "EXT_mesh_opacity_micromap", "micromap"), 1, "does not exist"),
    (("meshes", 0, "primitives", 0, "extensions", "EXT_mesh_opacity_micromap", "micromapBaseTriangle"), -1,
     "micromapBaseTriangle"),
    (("meshes", 0, "primitives", 0, "extensions", "EXT_mesh_opacity_micromap", "micromapBaseTriangle"), 2 ** 62,
     "references micromap triangle"),
    (("meshes", 0, "primitives", 0, "extensions", "OMAPS_pair_opacity_maps", "maps"), -1, "does not exist"),
    (("extensions", "OMAPS_pair_opacity_maps", "maps", 0, "codec"), "vq8", "not a codec"),
    (("extensions", "OMAPS_pair_opacity_maps", "maps", 0, "blockBytes"), 64, "blockBytes"),
]


@pytest.mark.parametrize("path, value, message", MICROMAP_REGRESSIONS, ids=[str(c[0][-1]) for c in MICROMAP_REGRESSIONS])
def test_micromap_extension_regressions(tmp_path, path, value, message):
    doc = copy.deepcopy(micromap_gltf_seed())
    _get(doc, path[:-1])[path[-1]] = value
    p = tmp_path / "m.gltf"
    p.write_text(dumps(doc))
    with pytest.raises(InputError, match=message) as exc:
        load_scene(str(p))
    assert exc.value.path == str(p) and UNCHECKED not in exc.value.problem
