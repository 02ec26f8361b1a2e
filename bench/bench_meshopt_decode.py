"""EXT_meshopt_compression decoding speed: omaps' decoders (``omaps.scene.meshopt``, numba) against
meshoptimizer's C decoders (the ``meshoptimizer`` package, a test dependency), side by side in one
run, on the vertex and index data of the shared forest's meshes (or a generated grid when
../shared is absent), encoded here by meshoptimizer's encoder. Rates are MB of decoded data per
second, best of ``REPEATS``; the ratio is what to read (the machine is shared).

    python bench/bench_meshopt_decode.py
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from omaps.scene.meshopt import decode_attributes, decode_triangles

REPEATS = 5


def _data():
    """(positions and UVs interleaved as 20-byte float vertices, uint32 triangle list) of the forest's
    prototypes merged, or of a 600 x 600 grid."""
    path = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "scenes", "forest.glb")
    if os.path.isfile(path):
        from omaps.scene import load_scene

        scene = load_scene(path)
        pos, uv, tri, base = [], [], [], 0
        for m in scene.meshes:
            g = m.merged
            pos.append(g["positions"])
            uv.append(g["uvs"].astype(np.float32))
            tri.append(g["triangles"] + base)
            base += len(g["positions"])
        what = f"forest.glb's {len(scene.meshes)} prototypes"
        pos, uv, tri = np.concatenate(pos), np.concatenate(uv), np.concatenate(tri)
    else:
        k = 600
        x, y = np.meshgrid(np.arange(k, dtype=np.float32), np.arange(k, dtype=np.float32))
        pos = np.stack([x.ravel(), y.ravel(), np.zeros(k * k, np.float32)], 1)
        uv = pos[:, :2] / k
        v = np.arange(k * k).reshape(k, k)
        a, b, c, d = v[:-1, :-1].ravel(), v[:-1, 1:].ravel(), v[1:, :-1].ravel(), v[1:, 1:].ravel()
        tri = np.stack([np.stack([a, b, c], 1), np.stack([b, d, c], 1)], 1).reshape(-1, 3)
        what = f"a {k} x {k} grid (../shared absent)"
    verts = np.concatenate([pos.astype(np.float32), uv.astype(np.float32)], axis=1)
    return what, np.ascontiguousarray(verts).view(np.uint8).reshape(len(verts), 20), tri.astype(np.uint32).ravel()


def _best(fn) -> float:
    fn()
    best = float("inf")
    for _ in range(REPEATS):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main() -> int:
    try:
        import meshoptimizer as mo
    except ImportError:
        print("meshoptimizer (the reference decoder) is not installed: pip install -e '.[test]'", file=sys.stderr)
        return 2
    mo.encode_vertex_version(0)
    mo.encode_index_version(1)
    what, verts, tri = _data()
    n, stride = verts.shape
    venc = mo.encode_vertex_buffer(verts, n, stride)
    ienc = mo.encode_index_buffer(tri, len(tri), n)
    assert np.array_equal(decode_attributes(venc, n, stride), verts.ravel())
    assert np.array_equal(decode_triangles(ienc, len(tri), 4), np.asarray(mo.decode_index_buffer(len(tri), 4, ienc)))
    print(f"{what}: {n:,} vertices of {stride} bytes ({len(venc) / verts.size:.2f} of their size encoded), "
          f"{len(tri) // 3:,} triangles ({len(ienc) / (4 * len(tri)):.2f} encoded); best of {REPEATS}")
    rows = [("attributes", verts.size, lambda: decode_attributes(venc, n, stride),
             lambda: mo.decode_vertex_buffer(n, stride, venc)),
            ("triangles", 4 * len(tri), lambda: decode_triangles(ienc, len(tri), 4),
             lambda: mo.decode_index_buffer(len(tri), 4, ienc))]
    print(f"{'stream':<11} {'omaps MB/s':>11} {'C MB/s':>9} {'omaps / C':>10}")
    for name, size, ours, ref in rows:
        a, b = _best(ours), _best(ref)
        print(f"{name:<11} {size / a / 1e6:>11.0f} {size / b / 1e6:>9.0f} {b / a:>10.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
