"""The table of docs/guide/untrusted.md's cases, run through ``omaps omm``: each URI, the options,
the exit code and the message (paths shortened). Run from the repository root:
``python docs/scripts/untrusted_table.py``. Writes only under a temporary folder."""

import base64
import io
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
from PIL import Image


def png() -> bytes:
    buf = io.BytesIO()
    a = np.zeros((16, 16, 4), np.uint8)
    a[:, 8:, 3] = 255
    Image.fromarray(a, "RGBA").save(buf, format="PNG")
    return buf.getvalue()


def quad() -> bytes:
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32).tobytes()
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32).tobytes()
    return pos + uv + np.array([0, 1, 2, 0, 2, 3], np.uint16).tobytes()


def scene(buffer_uri: str, image_uri: str) -> dict:
    return {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                        "material": 0}]}],
            "materials": [{"alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
            "textures": [{"source": 0}], "images": [{"uri": image_uri}],
            "buffers": [{"byteLength": 92, "uri": buffer_uri}],
            "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                            {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                           "min": [0, 0, 0], "max": [1, 1, 0]},
                          {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                          {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}]}


def main() -> None:
    top = os.path.realpath(tempfile.mkdtemp())
    asset, outside = os.path.join(top, "asset"), os.path.join(top, "outside")
    os.makedirs(asset)
    os.makedirs(outside)
    for folder in (asset, outside):
        open(os.path.join(folder, "quad.bin"), "wb").write(quad())
        open(os.path.join(folder, "leaf.png"), "wb").write(png())
    os.symlink(os.path.join(outside, "quad.bin"), os.path.join(asset, "link.bin"))
    inline = "data:image/png;base64," + base64.b64encode(png()).decode()
    cases = [("absolute buffer path", os.path.join(outside, "quad.bin"), inline),
             (".. out of the folder", "../outside/quad.bin", inline),
             ("symlink out of the folder", "link.bin", inline),
             ("percent-encoded ..", "%2e%2e/outside/quad.bin", inline),
             ("file: image", "quad.bin", "file://" + os.path.join(outside, "leaf.png")),
             ("http: image", "quad.bin", "http://127.0.0.1:9/leaf.png")]
    rows = []
    for k, (what, buf, img) in enumerate(cases):
        path = os.path.join(asset, f"case{k}.gltf")
        json.dump(scene(buf, img), open(path, "w"))
        for options in ([], ["--root", top], ["--allow-outside"]):
            out = os.path.join(top, "out", f"case{k}.glb")
            r = subprocess.run([sys.executable, "-m", "omaps.cli", "omm", path, "--level", "2", "--quiet", "-o", out,
                                *options], capture_output=True, text=True)
            msg = " ".join(ln for ln in r.stderr.splitlines() if "error" in ln or "warning" in ln)
            msg = msg.replace(top, "TMP") or "(baked)"
            uri = buf if what.endswith("folder") or "buffer" in what or "percent" in what else img
            uri = uri.replace(top, "TMP")
            opt = " ".join(o.replace(top, "TMP") for o in options) or "(none)"
            rows.append(f"| {what} | `{uri}` | `{opt}` | {r.returncode} | {msg.replace('|', '/')} |")
            if os.path.exists(out):
                os.remove(out)
    print("| case | URI | options | exit | message |\n|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
