"""Small glTF files written from scratch for tests: a unit quad (two triangles) in the z = 0
plane, textured so that the image appears upright seen from +z: vertex (x, y) has UV (x, 1 - y)
(glTF's v runs down the image). Nothing here uses omaps."""

import base64
import io
import json

import numpy as np
from PIL import Image

QUAD_POS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_UV = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
QUAD_IDX = np.array([0, 1, 2, 0, 2, 3], np.uint16)


def png_bytes(alpha: np.ndarray) -> bytes:
    rgba = np.zeros(alpha.shape + (4,), np.uint8)
    rgba[..., 1] = 180
    rgba[..., 3] = alpha
    buf = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(buf, format="PNG")
    return buf.getvalue()


def write_quad_gltf(path, alpha, *, nodes=None, material=None, sampler=None, uv_transform=None,
                    image_uri=None, extra_images=(), bin_uri=None, positions=QUAD_POS, uvs=QUAD_UV,
                    indices=QUAD_IDX):
    """Write a .gltf with one mesh (the quad) and its material. ``alpha``: the base colour
    texture's alpha (uint8 image) embedded as a data URI unless ``image_uri`` names a file
    (written beside it unless it is meant to be missing: pass alpha=None). ``nodes``: list of
    node dicts (default one node). ``bin_uri``: store the buffer in that file instead of a data
    URI (not written when it is to be missing: pass bin_uri with 'missing' in it)."""
    path = str(path)
    folder = path.rsplit("/", 1)[0]
    pos = np.ascontiguousarray(positions, np.float32).tobytes()
    uv = np.ascontiguousarray(uvs, np.float32).tobytes()
    idx = np.ascontiguousarray(indices, np.uint16).tobytes()
    pad = (-len(idx)) % 4
    blob = pos + uv + idx + b"\0" * pad
    if bin_uri:
        if "missing" not in bin_uri:
            with open(f"{folder}/{bin_uri}", "wb") as f:
                f.write(blob)
        buffer = {"byteLength": len(blob), "uri": bin_uri}
    else:
        buffer = {"byteLength": len(blob),
                  "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}
    n = len(positions)
    pmin = np.asarray(positions, np.float32).min(axis=0).tolist()
    pmax = np.asarray(positions, np.float32).max(axis=0).tolist()
    images = []
    if image_uri:
        if alpha is not None:
            with open(f"{folder}/{image_uri}", "wb") as f:
                f.write(png_bytes(alpha))
        images.append({"uri": image_uri})
    else:
        images.append({"uri": "data:image/png;base64," + base64.b64encode(png_bytes(alpha)).decode()})
    for uri in extra_images:
        images.append({"uri": uri})
    tex_info = {"index": 0}
    if uv_transform:
        tex_info["extensions"] = {"KHR_texture_transform": uv_transform}
    mat = {"name": "leaf", "alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
           "pbrMetallicRoughness": {"baseColorTexture": tex_info}}
    mat.update(material or {})
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes or [{}])))}],
        "nodes": [dict(mesh=0, **nd) for nd in (nodes or [{}])],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                    "material": 0}]}],
        "materials": [mat],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [sampler or {"magFilter": 9729, "wrapS": 10497, "wrapT": 10497}],
        "images": images,
        "buffers": [buffer],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(pos)},
                        {"buffer": 0, "byteOffset": len(pos), "byteLength": len(uv)},
                        {"buffer": 0, "byteOffset": len(pos) + len(uv), "byteLength": len(idx)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3", "min": pmin, "max": pmax},
                      {"bufferView": 1, "componentType": 5126, "count": n, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": len(indices), "type": "SCALAR"}],
    }
    if uv_transform:
        doc["extensionsUsed"] = ["KHR_texture_transform"]
    with open(path, "w") as f:
        json.dump(doc, f)
    return path



def edit_json(path, fn):
    """Apply ``fn`` to a .gltf file's JSON document in place; returns the path as a string."""
    with open(path) as f:
        doc = json.load(f)
    fn(doc)
    with open(path, "w") as f:
        json.dump(doc, f)
    return str(path)


def grid_scene(path, alpha, k=24, seed=0):
    """A k x k grid of vertices in the z = 0 plane, 2 (k-1)^2 triangles, with UVs scattered at
    random over [-0.1, 1.1]² (seeded) on the texture ``alpha``: many distinct small triangles."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(k, dtype=np.float32), np.arange(k, dtype=np.float32))
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(k * k, np.float32)], axis=1)
    uv = (rng.random((k * k, 2)) * 1.2 - 0.1).astype(np.float32)
    v = np.arange(k * k).reshape(k, k)
    a, b, c, d = v[:-1, :-1].ravel(), v[:-1, 1:].ravel(), v[1:, :-1].ravel(), v[1:, 1:].ravel()
    idx = np.stack([np.stack([a, b, c], 1), np.stack([b, d, c], 1)], 1).reshape(-1)
    return write_quad_gltf(str(path), alpha, positions=pos, uvs=uv, indices=idx)


def instanced_field(src, instanced_path, nodes_path, translations, rotations, scales, parent=None,
                    required=True):
    """From a .glb whose default scene is one node holding a mesh (the palm), two files of the same
    field under one parent node (``parent``: its translation, rotation, scale): ``instanced_path``,
    that node with ``EXT_mesh_gpu_instancing`` (float accessors in a buffer view appended to the
    binary chunk; listed in ``extensionsRequired`` when ``required``), and ``nodes_path``, the same
    placements as separate child nodes (their translation, rotation and scale: the accessors'
    float32 values exactly; None: not written)."""
    import pygltflib

    t = np.asarray(translations, np.float32)
    r = np.asarray(rotations, np.float32)
    s = np.asarray(scales, np.float32)
    parent = parent or {}

    def load():
        g = pygltflib.GLTF2().load(str(src))
        (root,) = g.scenes[g.scene or 0].nodes
        assert g.nodes[root].mesh is not None and not g.nodes[root].children
        return g, root

    def parent_node(g, children):
        g.nodes.append(pygltflib.Node(children=children, **{k: [float(x) for x in v] for k, v in parent.items()}))
        g.scenes[g.scene or 0].nodes = [len(g.nodes) - 1]

    g, root = load()
    blob = bytearray(g.binary_blob())
    attrs = {}
    for name, arr, kind in (("TRANSLATION", t, "VEC3"), ("ROTATION", r, "VEC4"), ("SCALE", s, "VEC3")):
        blob += b"\0" * (-len(blob) % 4)
        g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=arr.nbytes))
        blob += arr.tobytes()
        g.accessors.append(pygltflib.Accessor(bufferView=len(g.bufferViews) - 1, componentType=5126,
                                              count=len(arr), type=kind))
        attrs[name] = len(g.accessors) - 1
    g.buffers[0].byteLength = len(blob)
    g.set_binary_blob(bytes(blob))
    g.nodes[root].extensions = {"EXT_mesh_gpu_instancing": {"attributes": attrs}}
    g.extensionsUsed = sorted(set(g.extensionsUsed or []) | {"EXT_mesh_gpu_instancing"})
    if required:
        g.extensionsRequired = sorted(set(g.extensionsRequired or []) | {"EXT_mesh_gpu_instancing"})
    parent_node(g, [root])
    g.save(str(instanced_path))
    if nodes_path is None:
        return
    g, root = load()
    mesh = g.nodes[root].mesh
    kids = []
    for k in range(len(t)):
        g.nodes.append(pygltflib.Node(mesh=mesh, translation=[float(x) for x in t[k]],
                                      rotation=[float(x) for x in r[k]], scale=[float(x) for x in s[k]]))
        kids.append(len(g.nodes) - 1)
    parent_node(g, kids)
    g.save(str(nodes_path))


DRACO = "KHR_draco_mesh_compression"


def draco_bytes(positions, uvs, indices, bits=14, uv_bits=12):
    """Draco data of a triangle mesh (Google's encoder, DracoPy): (bytes, POSITION's and
    TEXCOORD_0's unique ids in it)."""
    import DracoPy

    data = DracoPy.encode(np.asarray(positions, np.float32), np.asarray(indices, np.uint32).reshape(-1, 3),
                          quantization_bits=bits, tex_coord=np.asarray(uvs, np.float64),
                          tex_coord_quantization_bits=uv_bits, preserve_order=True)
    mesh = DracoPy.decode(data)
    ids = {a["attribute_type"]: a["unique_id"] for a in mesh.attributes}
    return data, {"POSITION": ids[0], "TEXCOORD_0": ids[3]}  # (Draco's types: 0 position, 3 texture coordinate)


def write_draco_gltf(path, alpha, positions, uvs, indices, required=True, **draco):
    """``write_quad_gltf``'s scene with its primitive's geometry in ``KHR_draco_mesh_compression``
    (a buffer of its own); its accessors keep their types and counts but no data, as the
    extension's fallback-less files have them."""
    data, ids = draco_bytes(positions, uvs, indices, **draco)
    write_quad_gltf(path, alpha, positions=positions, uvs=uvs, indices=indices)

    def fn(doc):
        doc["buffers"].append({"byteLength": len(data),
                               "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()})
        doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteOffset": 0, "byteLength": len(data)})
        for a in doc["accessors"]:
            a.pop("bufferView", None)
        prim = doc["meshes"][0]["primitives"][0]
        prim["extensions"] = {DRACO: {"bufferView": len(doc["bufferViews"]) - 1, "attributes": ids}}
        doc["extensionsUsed"] = [DRACO]
        if required:
            doc["extensionsRequired"] = [DRACO]
    return edit_json(path, fn)


def dracoify_glb(src, out, bits=14, uv_bits=12):
    """A .glb with every triangle primitive's POSITION, TEXCOORD_0 and indices moved into
    ``KHR_draco_mesh_compression`` data (its other attributes dropped), read with pygltflib and
    numpy (plain float / unsigned accessors, as the palm has)."""
    import pygltflib

    g = pygltflib.GLTF2().load(str(src))
    blob = bytearray(g.binary_blob())

    def read(ai):
        a = g.accessors[ai]
        v = g.bufferViews[a.bufferView]
        dt = np.dtype({5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}[a.componentType])
        k = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[a.type]
        stride = v.byteStride or dt.itemsize * k
        start = (v.byteOffset or 0) + (a.byteOffset or 0)
        rows = [np.frombuffer(bytes(blob[start + i * stride:start + i * stride + dt.itemsize * k]), dt)
                for i in range(a.count)]
        return np.array(rows).reshape(a.count, k)

    for mesh in g.meshes:
        for p in mesh.primitives:
            assert p.mode in (None, 4) and p.indices is not None
            data, ids = draco_bytes(read(p.attributes.POSITION), read(p.attributes.TEXCOORD_0),
                                    read(p.indices).ravel(), bits, uv_bits)
            blob += b"\0" * (-len(blob) % 4)
            g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
            blob += data
            p.extensions = {DRACO: {"bufferView": len(g.bufferViews) - 1, "attributes": ids}}
            for name in ("NORMAL", "TANGENT", "COLOR_0", "TEXCOORD_1"):
                setattr(p.attributes, name, None)
            for ai in (p.attributes.POSITION, p.attributes.TEXCOORD_0, p.indices):
                g.accessors[ai].bufferView = None
                g.accessors[ai].byteOffset = None
                g.accessors[ai].sparse = None
    g.buffers[0].byteLength = len(blob)
    g.set_binary_blob(bytes(blob))
    g.extensionsUsed = sorted(set(g.extensionsUsed or []) | {DRACO})
    g.extensionsRequired = sorted(set(g.extensionsRequired or []) | {DRACO})
    g.save(str(out))


MESHOPT = "EXT_meshopt_compression"


def glb_parts(path):
    """A .glb's JSON document and binary chunk (plain struct reading)."""
    import struct

    raw = open(path, "rb").read()
    n = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20:20 + n])
    rest = raw[20 + n:]
    return doc, (bytes(rest[8:8 + struct.unpack_from("<I", rest, 0)[0]]) if rest else b"")


def write_glb_parts(path, doc, blob):
    """A .glb from a JSON document and a binary chunk."""
    import struct

    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob = bytes(blob) + b"\0" * (-len(blob) % 4)
    with open(path, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + 8 + len(blob)))
        f.write(struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942) + blob)


def meshoptify_glb(src, out, fallback=None, index_mode="TRIANGLES", filters=None):
    """A .glb whose mesh bufferViews (vertex attributes and triangle indices) are
    ``EXT_meshopt_compression`` streams made by meshoptimizer's own encoder (zeux's C library,
    the ``meshoptimizer`` package), version 0 attributes and version 1 triangles; the other views
    (images) copied as they are. ``fallback``: None, the placeholder fallback buffer the extension
    describes (no data: the extension required); ``b"..."`` a fallback buffer of the
    views' uncompressed length holding that byte repeated (a data URI: the extension only used,
    and a reader that reads the fallback reads garbage). ``index_mode``: TRIANGLES or INDICES.
    ``filters``: {bufferView index: (filter name, encoded element bytes)} replacing a view's
    bytes before encoding with bytes encoded for that filter. Returns the triangle lists as
    the decoder gives them back: TRIANGLES may rotate a triangle's corners (its winding kept),
    so {accessor index: uint32 indices} for a plain twin (``with_indices``)."""
    import meshoptimizer as mo

    mo.encode_vertex_version(0)
    mo.encode_index_version(1)
    doc, blob = glb_parts(src)
    views, accessors = doc["bufferViews"], doc["accessors"]
    index_views = {}
    for mesh in doc["meshes"]:
        for p in mesh["primitives"]:
            if "indices" in p:
                a = accessors[p["indices"]]
                index_views[a["bufferView"]] = (p["indices"], p.get("mode", 4))
    attribute_views = {accessors[ai]["bufferView"] for mesh in doc["meshes"] for p in mesh["primitives"]
                       for ai in p["attributes"].values()}
    body = bytearray()
    decoded = {}
    for vi, v in enumerate(views):
        off, length = v.get("byteOffset", 0), v["byteLength"]
        data = blob[off:off + length]
        body += b"\0" * (-len(body) % 4)
        if vi in index_views:
            ai, mode = index_views[vi]
            a = accessors[ai]
            size = {5123: 2, 5125: 4}[a["componentType"]]
            assert a.get("byteOffset", 0) == 0 and length == size * a["count"]
            idx = np.frombuffer(data, "<u2" if size == 2 else "<u4").astype(np.uint32)
            if index_mode == "TRIANGLES" and mode == 4:
                enc = mo.encode_index_buffer(idx, len(idx), int(idx.max()) + 1)
                decoded[ai] = np.asarray(mo.decode_index_buffer(len(idx), 4, enc), np.uint32).ravel()
                ext = {"mode": "TRIANGLES"}
            else:
                enc = mo.encode_index_sequence(idx, len(idx), int(idx.max()) + 1)
                decoded[ai] = idx
                ext = {"mode": "INDICES"}
            ext.update(byteStride=size, count=len(idx))
        elif vi in attribute_views:
            stride = v.get("byteStride") or next(
                np.dtype({5126: "f4", 5125: "u4", 5123: "u2", 5121: "u1"}[a["componentType"]]).itemsize
                * {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
                for a in accessors if a.get("bufferView") == vi)
            assert stride % 4 == 0 and length % stride == 0
            name, data = (filters or {}).get(vi, ("NONE", data))
            enc = mo.encode_vertex_buffer(np.frombuffer(data, np.uint8).reshape(-1, stride), length // stride, stride)
            ext = {"mode": "ATTRIBUTES", "byteStride": stride, "count": length // stride}
            if name != "NONE":
                ext["filter"] = name
        else:
            v["byteOffset"] = len(body)
            v["buffer"] = 0
            body += data
            continue
        ext.update(buffer=0, byteOffset=len(body), byteLength=len(enc))
        body += enc
        v["buffer"] = 1
        v.setdefault("extensions", {})[MESHOPT] = ext
    placeholder = {"byteLength": len(blob), "extensions": {MESHOPT: {"fallback": True}}}
    if fallback is not None:
        placeholder["uri"] = ("data:application/octet-stream;base64,"
                              + base64.b64encode(fallback * len(blob)).decode())
    doc["buffers"] = [{"byteLength": len(body)}, placeholder]
    doc["extensionsUsed"] = sorted(set(doc.get("extensionsUsed", [])) | {MESHOPT})
    if fallback is None:
        doc["extensionsRequired"] = sorted(set(doc.get("extensionsRequired", [])) | {MESHOPT})
    write_glb_parts(out, doc, body)
    return decoded


def with_indices(src, out, indices):
    """A plain copy of a .glb with the index accessors ``indices`` ({accessor: uint32 array})
    rewritten (as 32-bit indices appended to its binary chunk)."""
    doc, blob = glb_parts(src)
    blob = bytearray(blob)
    for ai, idx in indices.items():
        blob += b"\0" * (-len(blob) % 4)
        doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": 4 * len(idx)})
        blob += np.asarray(idx, "<u4").tobytes()
        doc["accessors"][ai].update(bufferView=len(doc["bufferViews"]) - 1, byteOffset=0, componentType=5125)
    doc["buffers"] = [{"byteLength": len(blob)}]
    write_glb_parts(out, doc, blob)
