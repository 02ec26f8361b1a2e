"""The tracer's 2-state mode: C cells resolved to O or T, no alpha tests, error as measured."""

import numpy as np
import pytest

from conftest import SCENES, needs_scenes
from omaps import states, trace
from omaps.cli import main
from omaps.schemes import parse_schemes
from omaps.trace import two_state


@pytest.fixture(scope="module")
def palm():
    from omaps.scene import load_scene

    scene = load_scene(SCENES / "palm.glb")
    prep = trace.prepare(scene, parse_schemes("none,sq16,vq4"))
    w, h = 64, 48
    cam = trace.Camera(np.array([-70.0, 130.0, -70.0]), np.array([0.0, 175.0, 0.0]), 70.0).basis(w, h)
    return prep, cam, w, h, trace.trace_scheme(prep, "none", cam, w, h)


@needs_scenes
@pytest.mark.parametrize("name", ["sq16", "vq4"])
def test_two_state_rules(palm, name):
    prep, cam, w, h, ref = palm
    sm = prep.maps[name]
    three = two_state.decoded_pair_maps(sm, prep.alpha)
    cache = {}
    err = {}
    for mode in two_state.MODES:
        sm2 = two_state.two_state_maps(prep, sm, mode, cache=cache)
        two = two_state.decoded_pair_maps(sm2, prep.alpha)
        assert set(np.unique(two)) <= {states.T, states.O}
        known = three != states.C
        np.testing.assert_array_equal(two[known], three[known])  # T and O cells keep their state
        if mode in ("opaque", "transparent"):
            assert np.all(two[~known] == (states.O if mode == "opaque" else states.T))
        prep.maps[sm2.name] = sm2
        run = trace.trace_scheme(prep, sm2.name, cam, w, h)
        del prep.maps[sm2.name]
        assert run.primary.tests.sum() == 0  # no ray runs the any-hit shader
        err[mode] = trace.coverage_error(run, ref)
        if mode == "opaque":  # C taken as opaque can only stop a ray earlier
            assert np.all(run.primary.dist <= ref.primary.dist)
        if mode == "transparent":
            assert np.all(run.primary.dist >= ref.primary.dist)
    assert err["opaque"]["passed_through_fraction"] == 0 and err["transparent"]["stopped_early_fraction"] == 0
    # the majority and the hashed rule beat always-opaque and always-transparent here
    for good in ("nearest", "hashed"):
        assert err[good]["differing_fraction"] < min(err["opaque"]["differing_fraction"],
                                                     err["transparent"]["differing_fraction"])


@needs_scenes
def test_cell_fractions_match_the_alpha_test(palm):
    """Cells whose map state is known have fractions 0 (T) or 1 (O): every sample agrees."""
    prep = palm[0]
    from omaps.coverage import cell_fractions
    from omaps.scene.alpha import distinct_rows, pair_corner_uvs

    uv, has_b, mat = pair_corner_uvs(prep.alpha)
    reps, _ = distinct_rows(uv, has_b, mat)
    frac = np.zeros((len(reps), 16, 16))
    for m in np.unique(mat[reps]):
        sel = np.flatnonzero(mat[reps] == m)
        frac[sel], _ = cell_fractions(prep.tests[int(m)], uv[reps[sel]], has_b[reps[sel]], 16)
    three = two_state.decoded_pair_maps(prep.maps["sq16"], prep.alpha)[reps]
    assert np.all((frac >= 0) & (frac <= 1))
    assert np.all(frac[three == states.T] == 0) and np.all(frac[three == states.O] == 1)
    assert 0 < frac[three == states.C].mean() < 1


@needs_scenes
def test_cli_two_state(tmp_path, capsys):
    import json
    j = tmp_path / "r.json"
    assert main(["trace", str(SCENES / "palm.glb"), "--size", "32", "--schemes", "none,tri2,vq2",
                 "--two-state", "hashed,opaque", "--json", str(j), "--quiet", "--jobs", "1"]) == 0
    r = json.loads(j.read_text())
    assert set(r["two_state"]) == {"vq2"} and set(r["two_state"]["vq2"]) == {"hashed", "opaque"}
    assert "2-state" in capsys.readouterr().out
    assert main(["trace", str(SCENES / "palm.glb"), "--two-state", "dither"]) == 2
