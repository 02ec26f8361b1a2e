"""Merged-subtree micromaps (``csmL``) of a forest of over a million *unique* alpha-tested
triangles, the scale of the merged-subtree paper's headline scene (1.2 M unique alpha-masked
triangles at level 10 in under 6 MiB).

The scene is built from the shared forest.glb (its own seed, into a temporary folder, or
``--keep DIR``): its trees re-scattered over the forest's ground, about 2.2 times as many
instances, each a mesh of its own (its own texture coordinates; no instancing), so every
triangle is unique in the scene, as in the paper's forest. Their texture coordinates are the
prototype cards' (``--uv shared``, the default): the paper's forest has the same kind of
repetition, since its uncompressed level-10 micromaps take 175 MiB, about 700 distinct maps of
256 KiB for its 1.2 M triangles. ``--uv phase`` is a far harder scene than the paper's: each
connected card's coordinates are shifted by a random fraction of a texel (the sampler repeats:
the same leaves, sampled at their own phase), so no two triangles share a map.

Each level runs in a process of its own (its peak memory is that process's); a level given in
``--sample-levels`` bakes a random fraction ``--sample`` of the distinct triangles and states
the time the whole scene would take at that rate (the bytes of a sample are not scaled: sharing
grows with the triangles).

    python bench/bench_million_forest.py --trace 10             # levels 4 to 10, and omaps trace csm10
    python bench/bench_million_forest.py --uv phase             # levels 4, 6 whole; 8, 10 sampled
"""

from __future__ import annotations

import argparse
import copy
import io
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
FOREST = os.path.join(HERE, "..", "..", "shared", "data", "scenes", "forest.glb")
PAPER = "1.2 M unique triangles at level 10 in under 6 MiB (Chernaik, Modisett & Billeter 2026)"


def build_forest(src: str, out: str, target: int = 1_200_000, seed: int = 2026, phase: bool = False) -> int:
    """Write the re-scattered forest to ``out`` (.glb); returns its alpha-tested triangles.
    ``phase``: each card's texture coordinates shifted by its own sub-texel phase."""
    from PIL import Image
    from pygltflib import GLTF2, Accessor, BufferView, Mesh, Node

    g = GLTF2().load(src)
    blob = bytearray(g.binary_blob())
    mask = {i for i, m in enumerate(g.materials) if m.alphaMode == "MASK"}

    def view(acc_index, dtype, width):
        acc = g.accessors[acc_index]
        bv = g.bufferViews[acc.bufferView]
        item = np.dtype(dtype).itemsize * width
        stride = bv.byteStride or item
        start = (bv.byteOffset or 0) + (acc.byteOffset or 0)
        raw = np.frombuffer(bytes(blob[start:start + stride * acc.count]), np.uint8).reshape(acc.count, stride)
        return raw[:, :item].copy().view(dtype).reshape(acc.count, width)

    def texture_size(material):
        tex = g.textures[g.materials[material].pbrMetallicRoughness.baseColorTexture.index]
        bv = g.bufferViews[g.images[tex.source].bufferView]
        start = bv.byteOffset or 0
        return Image.open(io.BytesIO(bytes(blob[start:start + bv.byteLength]))).size

    sizes = {m: texture_size(m) for m in mask}
    roots = g.scenes[g.scene or 0].nodes
    trees = [i for i in roots if g.nodes[i].mesh is not None
             and any(p.material in mask for p in g.meshes[g.nodes[i].mesh].primitives)]
    keep = [i for i in roots if i not in set(trees)]  # the ground
    where = np.array([g.nodes[i].translation for i in trees], np.float64)
    lo, hi = where.min(axis=0), where.max(axis=0)
    rng = np.random.default_rng(seed)
    meshes, nodes = [], []
    for i in keep:
        n = copy.deepcopy(g.nodes[i])
        if n.mesh is not None:
            meshes.append(g.meshes[n.mesh])
            n.mesh = len(meshes) - 1
        n.children = []
        nodes.append(n)
    count = 0
    k = 0
    while count < target:
        src_node = g.nodes[trees[rng.integers(len(trees))]]
        mesh = g.meshes[src_node.mesh]
        prims = []
        for p in mesh.primitives:
            q = copy.deepcopy(p)
            if p.material in mask:
                uv = view(p.attributes.TEXCOORD_0, np.float32, 2)
                w, h = sizes[p.material]
                part = _components(view(p.indices, _INDEX[g.accessors[p.indices].componentType], 1).reshape(-1, 3),
                                   len(uv))
                shift = rng.random((int(part.max()) + 1, 2)) / np.array([w, h])  # a sub-texel phase per card
                shifted = (uv + shift[part]).astype(np.float32) if phase else uv.copy()
                while len(blob) % 4:
                    blob.append(0)
                g.bufferViews.append(BufferView(buffer=0, byteOffset=len(blob), byteLength=shifted.nbytes))
                blob += shifted.tobytes()
                g.accessors.append(Accessor(bufferView=len(g.bufferViews) - 1, componentType=5126,
                                            count=len(shifted), type="VEC2"))
                q.attributes.TEXCOORD_0 = len(g.accessors) - 1
                count += g.accessors[p.indices].count // 3
            prims.append(q)
        meshes.append(Mesh(name=f"{mesh.name}_{k}", primitives=prims))
        yaw = rng.uniform(0, 2 * np.pi)
        s = float((src_node.scale or [1.0])[0]) * rng.uniform(0.85, 1.15)
        t = lo + rng.random(3) * (hi - lo)
        nodes.append(Node(name=f"tree_{k}", mesh=len(meshes) - 1, translation=[float(t[0]), float(lo[1]), float(t[2])],
                          rotation=[0.0, float(np.sin(yaw / 2)), 0.0, float(np.cos(yaw / 2))], scale=[s, s, s]))
        k += 1
    g.meshes, g.nodes = meshes, nodes
    g.scenes[g.scene or 0].nodes = list(range(len(nodes)))
    g.buffers[0].byteLength = len(blob)
    g.set_binary_blob(bytes(blob))
    g.save_binary(out)
    return count


_INDEX = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32}


def _components(tris: np.ndarray, n_vertices: int) -> np.ndarray:
    """The connected part (a card, a leaf cluster) of each vertex, by the triangles' shared
    vertices: a repeated card is a part of its own, so each copy gets its own phase."""
    label = np.arange(n_vertices)
    while True:
        low = label[tris].min(axis=1)
        new = label.copy()
        np.minimum.at(new, tris.ravel(), np.repeat(low, 3))
        new = new[new]
        if (new == label).all():
            return np.unique(label, return_inverse=True)[1]
        label = new


CHILD = r"""
import json, sys, time
import numpy as np
from types import SimpleNamespace
from omaps.scene import load_scene, alpha_triangles
from omaps.alpha_test import MaterialRules
from omaps.schemes import parse_schemes
from omaps.scene.alpha import distinct_rows
from omaps.trace.maps import merged_subtree_maps
scene = load_scene(sys.argv[1])
rules = MaterialRules()
at = alpha_triangles(scene, rules)
tests = {int(m): scene.alpha_test(int(m), rules) for m in np.unique(at.material)}
reps, _ = distinct_rows(at.uv, at.material, at.unknown)
fraction = float(sys.argv[3])
pick = reps
if fraction < 1:
    pick = np.sort(np.random.default_rng(1).choice(reps, max(1, int(round(fraction * len(reps)))), replace=False))
part = SimpleNamespace(uv=at.uv[pick], material=at.material[pick], unknown=at.unknown[pick])
s = parse_schemes([f"csm{sys.argv[2]}"])[0]
t = time.perf_counter()
m = merged_subtree_maps(part, tests, s)
print(json.dumps({"seconds": time.perf_counter() - t, "bytes": m.map_bytes, "nodes": m.info["csm_nodes"],
                  "baked": int(len(pick)), "distinct": int(len(reps)), "alpha": int(at.count)}))
"""


def _run_child(args):
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE, text=True)
    out = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    code = os.waitstatus_to_exitcode(status)
    return code, out, usage.ru_maxrss / 1024, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="4,6,8,10")
    ap.add_argument("--sample-levels", help="levels baked on a sample (comma list; '' for none; default: none, "
                    "with --uv phase 8,10)")
    ap.add_argument("--sample", type=float, default=0.02, help="fraction of the distinct triangles of a sampled level")
    ap.add_argument("--target", type=int, default=1_200_000, help="alpha-tested triangles at least")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--keep", help="folder to write million_forest.glb into (kept)")
    ap.add_argument("--uv", choices=("shared", "phase"), default="shared",
                    help="the cards' texture coordinates: the prototypes' (shared) or each at its own sub-texel phase")
    ap.add_argument("--trace", type=int, help="also run omaps trace --schemes none,csmL --size 128 --memory")
    a = ap.parse_args()
    if not os.path.isfile(FOREST):
        print(f"{FOREST} is absent: nothing to measure", file=sys.stderr)
        return 0
    folder = a.keep or tempfile.mkdtemp(prefix="omaps-million-")
    os.makedirs(folder, exist_ok=True)
    scene = os.path.join(folder, "million_forest.glb")
    t = time.perf_counter()
    n_alpha = build_forest(FOREST, scene, a.target, a.seed, a.uv == "phase")
    print(f"{scene}: {n_alpha:,} alpha-tested triangles ({os.path.getsize(scene) / 2**20:.0f} MiB, "
          f"built in {time.perf_counter() - t:.1f} s, seed {a.seed}, texture coordinates {a.uv})")
    subprocess.run([sys.executable, "-c", CHILD, FOREST, "2", "1"], check=True, capture_output=True)  # compile once
    if a.sample_levels is None:
        a.sample_levels = "8,10" if a.uv == "phase" else ""
    sampled = {int(v) for v in a.sample_levels.split(",") if v.strip()}
    rows = []
    for level in [int(v) for v in a.levels.split(",")]:
        frac = a.sample if level in sampled else 1.0
        code, out, peak, wall = _run_child(["-c", CHILD, scene, str(level), str(frac)])
        if code:
            print(f"level {level}: exit {code}", file=sys.stderr)
            return 1
        r = json.loads(out)
        r.update(level=level, peak_mb=peak, wall=wall, fraction=frac)
        rows.append(r)
    d = rows[0]["distinct"]
    print(f"{rows[0]['alpha']:,} alpha triangles, {d:,} distinct; csmL baked into its DAG ('bake s': the maps "
          "alone, load and pairing not counted; peak of the whole process)")
    print(f"{'level':>5} {'baked':>10} {'bake s':>9} {'whole s':>9} {'peak MB':>8} {'nodes':>12} {'MiB':>9}")
    for r in rows:
        whole = r["seconds"] * r["distinct"] / r["baked"]
        est = "" if r["fraction"] == 1 else " (est.)"
        mib = r["bytes"] / 2**20
        print(f"{r['level']:>5} {r['baked']:>10,} {r['seconds']:>9.1f} {whole:>9.0f}{est} {r['peak_mb']:>8.0f} "
              f"{r['nodes']:>12,} {mib:>9.2f}{' (sample)' if r['fraction'] < 1 else ''}")
    print(f"paper: {PAPER}")
    if a.trace is not None:
        report = os.path.join(folder, "trace.json")
        code, _, peak, wall = _run_child(["-m", "omaps", "trace", scene, "--schemes", f"none,csm{a.trace}", "--size",
                                          "128", "--memory", "--quiet", "--json", report])
        print(f"omaps trace --schemes none,csm{a.trace} --size 128 --memory: exit {code}, {wall:.0f} s, "
              f"peak {peak:.0f} MB")
        if os.path.isfile(report):
            with open(report) as f:
                schemes = json.load(f)["schemes"]
            for name, r in schemes.items():
                print(f"  {name}: {r['alpha_tests_per_primary_ray']:.3f} alpha tests per primary ray, "
                      f"{r['differing_pixels']} differing pixels, {r['map_bytes'] / 2**20:.2f} MiB of maps")
    return 0


if __name__ == "__main__":
    sys.exit(main())
