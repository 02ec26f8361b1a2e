"""The Embree tracer: any-hit filter against an independent alpha test, every scheme's visible
result identical to 'none', deferred shadow tests, and the CLI."""

import json

import numpy as np
import pytest
from PIL import Image

from conftest import SCENES, needs_scenes
from gltf_files import write_quad_gltf
from omaps import trace
from omaps.cli import main
from omaps.codecs.registry import codec_names
from omaps.scene import load_scene
from omaps.schemes import parse_schemes
from omaps.trace import embree


def test_device_checks_version_and_features():
    d = embree.Device()
    assert 40300 <= d.version < 50000
    assert d.version_text.startswith("4.")


def test_quad_hits_match_an_independent_alpha_test(tmp_path):
    """A textured unit quad seen head-on: 'none' hits exactly where the texel under the ray is
    opaque (computed here from the plane intersection), and every scheme agrees."""
    rng = np.random.default_rng(5)
    alpha = (rng.random((8, 8)) < 0.5).astype(np.uint8) * 255
    f = write_quad_gltf(tmp_path / "q.gltf", alpha, sampler={"magFilter": 9728, "wrapS": 33071, "wrapT": 33071})
    scene = load_scene(f)
    names = ["none", "sq4", "sq16", "tri3", "vq2"]
    prep = trace.prepare(scene, parse_schemes(names))
    w = h = 61
    cam = trace.Camera(np.array([0.5, 0.5, 2.0]), np.array([0.5, 0.5, 0.0]), 40.0).basis(w, h)
    runs = {n: trace.trace_scheme(prep, n, cam, w, h) for n in names}
    none = runs["none"].primary
    # independent: ray / plane z = 0, texel of (x, 1 - y)
    ys, xs = np.mgrid[0:h, 0:w]
    d = cam[3:6] + (2 * (xs[..., None] + 0.5) / w - 1) * cam[6:9] + (1 - 2 * (ys[..., None] + 0.5) / h) * cam[9:12]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    t = -cam[2] / d[..., 2]
    p = cam[:3] + t[..., None] * d
    inside = (p[..., 0] > 0) & (p[..., 0] < 1) & (p[..., 1] > 0) & (p[..., 1] < 1)
    tx, ty = p[..., 0] * 8, (1 - p[..., 1]) * 8
    opaque = np.zeros((h, w), bool)
    xi, yi = np.clip(tx.astype(int), 0, 7), np.clip(ty.astype(int), 0, 7)
    opaque[inside] = alpha[yi[inside], xi[inside]] >= 128
    near_edge = (np.minimum(tx % 1, 1 - tx % 1) < 1e-4) | (np.minimum(ty % 1, 1 - ty % 1) < 1e-4)
    hit = none.inst >= 0
    assert opaque.sum() > 100 and (inside & ~opaque).sum() > 100
    assert np.all((hit == opaque) | near_edge)
    np.testing.assert_allclose(none.dist[hit], t[hit], rtol=1e-5)
    on_border = np.any(np.minimum(np.abs(p[..., :2]), np.abs(1 - p[..., :2])) < 1e-6, axis=-1)
    assert np.all(((none.candidates > 0) == inside) | on_border)
    for n in names[1:]:
        r = runs[n].primary
        assert trace.differing_pixels(r, none) == 0
        np.testing.assert_array_equal(r.candidates, none.candidates)
        assert np.all(r.tests <= none.tests)
    assert runs["sq16"].primary.tests.sum() < none.tests.sum()  # a 0/255 checkerboard: mostly known cells


@pytest.fixture(scope="module")
def palm_runs():
    scene = load_scene(SCENES / "palm.glb")
    # every codec (wavelet3 at its fast effort: the transform search changes which blocks are
    # stored, not how the tracer reads them, and medium's costs a minute here)
    names = ["none", "sq16", "tri3"] + [c + "-fast" if c == "wavelet3" else c for c in codec_names()]
    prep = trace.prepare(scene, parse_schemes(names))
    w, h = 64, 48
    # under the crown, looking up into it: many candidates per ray, shadow rays through leaves
    cam = trace.Camera(np.array([-70.0, 130.0, -70.0]), np.array([0.0, 175.0, 0.0]), 70.0).basis(w, h)
    light = np.array([0.3, 0.9, 0.3]) / np.linalg.norm([0.3, 0.9, 0.3])
    runs = {n: trace.trace_scheme(prep, n, cam, w, h, light, 1e-3, deferred=True) for n in names}
    return prep, runs, trace.trace_scheme(prep, None, cam, w, h, light, 1e-3)


@needs_scenes
def test_palm_every_scheme_sees_what_none_sees(palm_runs):
    prep, runs, opaque = palm_runs
    none = runs["none"]
    assert none.primary.candidates.mean() > 1 and none.shadow.tests.sum() > 500
    assert trace.differing_pixels(opaque.primary, none.primary) > 0  # the alpha test matters here
    for n, r in runs.items():
        assert trace.differing_pixels(r.primary, none.primary) == 0, n
        np.testing.assert_array_equal(r.primary.candidates, none.primary.candidates)
        np.testing.assert_array_equal(r.shadow.occluded, none.shadow.occluded)
        np.testing.assert_array_equal(r.deferred.occluded, none.shadow.occluded)
        assert np.all(r.primary.tests <= none.primary.tests)
        assert r.deferred.tests.sum() <= r.shadow.tests.sum()
        if n != "none":
            assert r.primary.tests.sum() < none.primary.tests.sum()
    assert np.array_equal(none.primary.tests, none.primary.candidates)  # none tests every candidate


@needs_scenes
def test_palm_summary(palm_runs):
    prep, runs, _ = palm_runs
    s = trace.summary(runs["vq2"], runs["none"], prep.maps["vq2"], 64, 48)
    assert s["differing_pixels"] == 0 and s["differing_shadow_rays"] == 0 and s["deferred_differing_shadow_rays"] == 0
    assert s["map_bytes"] == 32 * len(prep.alpha.pair_first)
    assert 0 < s["alpha_tests_per_primary_ray"] < s["candidates_per_primary_ray"]
    assert s["deferred_tests_saved"] >= 0


@needs_scenes
def test_cli_trace_palm(tmp_path, capsys):
    j, hm, rd = tmp_path / "r.json", tmp_path / "h.png", tmp_path / "r.png"
    assert main(["trace", str(SCENES / "palm.glb"), "--size", "40x32", "--schemes", "none,sq8,vq2", "--shadows",
                 "--json", str(j), "--heatmap", str(hm), "--render", str(rd), "--jobs", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "none" in out and "vq2" in out
    r = json.loads(j.read_text())
    assert set(r["schemes"]) == {"none", "sq8", "vq2"}
    for v in r["schemes"].values():
        for k in ("alpha_tests_per_primary_ray", "candidates_per_primary_ray", "alpha_tests_per_shadow_ray",
                  "rays_per_second", "differing_pixels", "map_bytes"):
            assert k in v
        assert v["differing_pixels"] == 0
    assert r["scene"]["triangles"] == 4152 and r["camera"]["width"] == 40
    assert Image.open(rd).size == (40, 32)
    assert Image.open(hm).size[0] > 200


@pytest.mark.parametrize("args, problem", [
    (["--size", "0"], "--size"), (["--size", "10x"], "--size"), (["--schemes", "sq3"], "power of two"),
    (["--schemes", "vq9"], "unknown scheme"), (["--camera", "1,2,3:1,2,3:40"], "differ"),
    (["--camera", "1,2:0,0,0:40"], "--camera"), (["--light", "0,0,0", "--shadows"], "--light"),
])
def test_cli_trace_bad_options(tmp_path, capsys, args, problem):
    f = write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8))
    assert main(["trace", f] + args) == 2
    assert problem in capsys.readouterr().err


def test_scene_without_alpha_tested_triangles(tmp_path, capsys):
    f = write_quad_gltf(tmp_path / "q.gltf", np.full((2, 2), 255, np.uint8), material={"alphaMode": "OPAQUE"})
    j = tmp_path / "r.json"
    assert main(["trace", f, "--size", "8", "--shadows", "--schemes", "none,sq8,tri2,vq2", "--json", str(j)]) == 0
    r = json.loads(j.read_text())
    assert r["scene"]["alpha_triangles"] == 0
    assert all(v["alpha_tests_per_primary_ray"] == 0 and v["differing_pixels"] == 0 for v in r["schemes"].values())
