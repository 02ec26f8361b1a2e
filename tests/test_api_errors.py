"""The Python API fails only from the outside: every public callable of omaps' public namespaces
(their ``__all__``), given arguments of the wrong type or value, raises an omaps error
(``InputError``, or ``InputTypeError`` for a wrong type) -- never an AttributeError, KeyError,
IndexError or a bare ValueError / TypeError from a conversion inside. Then the calls a new user
made, one by one: each works, or its error names the parameter in Python terms (and the command
line names its option instead)."""

import importlib
import inspect
import os
import pickle
import re
import warnings

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

import omaps
from conftest import SCENES, needs_scenes
from omaps.cli import main
from omaps.cli.main import error_text
from omaps.errors import InputError, InputTypeError

NAMESPACES = ("omaps", "omaps.bake", "omaps.codecs", "omaps.corpus", "omaps.omm", "omaps.scene", "omaps.trace")


def public_callables() -> list:
    """(qualified name, object) of every callable in the namespaces' ``__all__``, each once; the
    error classes themselves aside."""
    seen, out = set(), []
    for ns in NAMESPACES:
        module = importlib.import_module(ns)
        for name in module.__all__:
            obj = getattr(module, name)
            if id(obj) in seen or not callable(obj) or (inspect.isclass(obj) and issubclass(obj, BaseException)):
                continue
            seen.add(id(obj))
            out.append((f"{ns}.{name}", obj))
    return out


CALLABLES = public_callables()
# numba kernels (``@njit``): they are called from compiled code (the tracer's any-hit filter), where
# no Python check can run; numba types their arguments itself
KERNELS = [(n, f) for n, f in CALLABLES if isinstance(f, numba.core.dispatcher.Dispatcher)]
CHECKED = [(n, f) for n, f in CALLABLES if not isinstance(f, numba.core.dispatcher.Dispatcher)]

# arguments that keep a call cheap when the value under test is accepted: one worker process, and
# inputs that do not exist (the call then stops at them, an InputError)
CHEAP = {"jobs": 1, "threads": 1, "scene": "missing.glb", "paths": ["missing.png"], "inputs": ["missing.png"],
         "progress": False}

WRONG = st.one_of(
    st.sampled_from([None, "", "abc", "missing.png", "missing.glb", "sq3", b"\x00\x01", [None], [1, "a"], {"a": 1},
                     (), object(), 1j]),
    st.integers(min_value=-(2 ** 70), max_value=2 ** 70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.sampled_from([np.zeros((2, 3, 4)), np.array(["x"]), np.zeros(0), np.full((3, 3), np.nan),
                     np.zeros(5, np.complex64), np.array([None, 1], dtype=object), np.zeros((1, 1), np.int8) - 1,
                     np.zeros((70000, 2), np.uint8)]),
    st.lists(st.integers(-3, 3), max_size=4),
    st.lists(st.text(max_size=3), max_size=3),
)


@pytest.fixture(scope="module", autouse=True)
def in_a_scratch_folder(tmp_path_factory):
    """Calls that accept an output path write under a scratch folder, not the checkout."""
    before = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("api"))
    yield
    os.chdir(before)


def test_the_namespaces_export_callables():
    names = {n for n, _ in CHECKED}
    for call in ("omaps.evaluate_corpus", "omaps.trace_scene", "omaps.bake_omms", "omaps.load_alpha",
                 "omaps.bake_square", "omaps.get_codec", "omaps.scene.load_scene", "omaps.omm.build"):
        assert call in names or call.replace("omaps.", "omaps.bake.", 1) in names
    assert len(CHECKED) > 80
    # the kernels left out are numba dispatchers, each a block or bit reader of the codecs
    assert all(n.startswith("omaps.codecs.") for n, _ in KERNELS)


@pytest.mark.fuzz
@pytest.mark.parametrize("name,func", CHECKED, ids=[n for n, _ in CHECKED])
@settings(max_examples=30, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_wrong_arguments_raise_only_omaps_errors(name, func, data):
    params = [p for p in inspect.signature(func).parameters.values() if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if not params:
        return
    target = data.draw(st.sampled_from(params), label="parameter")
    args, kwargs = [], {}
    for p in params:
        if p is target:
            value = data.draw(WRONG.filter(lambda v: v is not None or p.default is not None), label=p.name)
        elif p.name in CHEAP:
            value = CHEAP[p.name]
        elif p.default is not p.empty:
            continue
        else:
            value = data.draw(WRONG, label=p.name)
        if p.kind == p.KEYWORD_ONLY:
            kwargs[p.name] = value
        elif p.kind == p.POSITIONAL_ONLY or not kwargs:
            args.append(value)
        else:
            kwargs[p.name] = value
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            func(*args, **kwargs)
        except InputError as exc:  # the documented error: it says what is wrong
            assert str(exc)
        except Exception as exc:  # noqa: BLE001 - anything else is a failure, shown with its call
            pytest.fail(f"{name}(*{args!r:.200}, **{kwargs!r:.200}) raised {type(exc).__name__}: {exc}")


# ---- the errors themselves ------------------------------------------------------------------------

def test_error_classes():
    exc = InputTypeError("level must be an integer, got 'x'", param="level")
    assert isinstance(exc, InputError) and isinstance(exc, TypeError) and isinstance(exc, ValueError)
    assert omaps.InputTypeError is InputTypeError and "InputTypeError" in omaps.__all__
    back = pickle.loads(pickle.dumps(InputError("no such {channel}", "a.png", param="channel")))
    assert (type(back), back.path, back.param, str(back)) == (InputError, "a.png", "channel", "a.png: no such channel")


def test_the_command_line_names_its_option_for_the_parameter():
    exc = InputError("level must be an integer from 0 to 12, got 13", param="level")
    assert error_text(exc, {"level": "--level"}) == "--level must be an integer from 0 to 12, got 13"
    assert error_text(exc, {}) == "level must be an integer from 0 to 12, got 13"
    exc = InputError("image has no alpha channel (mode RGB); give {channel} to pick one", "x.jpg", param="channel")
    assert str(exc) == "x.jpg: image has no alpha channel (mode RGB); give channel to pick one"
    assert error_text(exc, {"channel": "--channel"}) == "x.jpg: image has no alpha channel (mode RGB); give --channel to pick one"


def test_the_command_line_prints_no_class_name_and_no_repeated_path():
    exc = InputError("cannot read glTF (InputError: a.glb: the GLB header is truncated)", "a.glb")
    assert error_text(exc, {}) == "a.glb: cannot read glTF (the GLB header is truncated)"


# ---- the calls, one by one ------------------------------------------------------------------------

def texture(tmp_path, name="leaf.png", mode="L"):
    a = np.zeros((8, 8), np.uint8)
    a[:, 4:] = 255
    path = tmp_path / name
    Image.fromarray(a).convert(mode).save(path)
    return path


def test_schemes_as_a_list_of_names_or_schemes():
    by_text = [s.name for s in omaps.parse_schemes("none,vq4")]
    assert [s.name for s in omaps.parse_schemes(["none", "vq4"])] == by_text
    assert [s.name for s in omaps.parse_schemes(("none", omaps.get_scheme("vq4")))] == by_text
    with pytest.raises(InputTypeError, match="schemes must hold scheme names or Schemes, got int") as e:
        omaps.parse_schemes(["none", 4])
    assert e.value.param == "schemes"


def test_trace_scene_takes_a_list_of_schemes(tmp_path):
    # the list passes the scheme check: the call stops at the missing scene, naming it
    with pytest.raises(InputError, match="no such file") as e:
        omaps.trace_scene(str(tmp_path / "missing.glb"), ["none", "vq4"])
    assert e.value.path == str(tmp_path / "missing.glb")
    with pytest.raises(InputTypeError) as e:
        omaps.trace_scene(str(tmp_path / "missing.glb"), ["none", 4])
    assert e.value.param == "schemes"


@needs_scenes
def test_trace_scene_traces_a_list_of_schemes():
    by_list = omaps.trace_scene(str(SCENES / "palm.glb"), ["none", omaps.get_scheme("tri3")], size="16x8", jobs=1)
    assert by_list.passed and list(by_list.report["schemes"]) == ["none", "tri3"]
    assert (by_list.report["camera"]["width"], by_list.report["camera"]["height"]) == (16, 8)
    by_text = omaps.trace_scene(str(SCENES / "palm.glb"), "none,tri3", size=(16, 8), jobs=1)
    key = "alpha_tests_per_primary_ray"
    assert by_text.report["schemes"]["tri3"][key] == by_list.report["schemes"]["tri3"][key]


@pytest.mark.parametrize("size", ["abc", "0", -3, 1.5, (4, "x"), None])
def test_trace_scene_size_is_checked(size, tmp_path):
    with pytest.raises(InputError, match=r"^size must") as e:
        omaps.trace_scene(str(tmp_path / "missing.glb"), size=size)
    assert e.value.param == "size"


def test_bake_square_takes_an_alpha_test_or_its_grid():
    test = omaps.StateRule("levels").alpha_test(np.array([[0, 40, 250, 255]], np.uint8))
    assert np.array_equal(omaps.bake_square(test, 16), omaps.bake_square(test.grid(), 16))
    with pytest.raises(InputTypeError, match="grid must be a FootprintGrid") as e:
        omaps.bake_square(np.zeros((4, 4)), 16)
    assert e.value.param == "grid"
    with pytest.raises(InputError, match="n must be a square map size") as e:
        omaps.bake_square(test, 12)
    assert e.value.param == "n"


def test_evaluate_corpus_takes_arrays_named_by_their_place(tmp_path):
    y, x = np.mgrid[:32, :32]
    disc = np.where((x - 15.5) ** 2 + (y - 15.5) ** 2 < 12 ** 2, 255, 0).astype(np.uint8)
    res = omaps.evaluate_corpus([disc, texture(tmp_path)], ["sq4", "tri2"], jobs=1)
    assert [r.name for r in res.results] == ["array 0", "leaf.png"]
    alone = omaps.evaluate_texture(disc, "sq4,tri2")
    assert res.results[0].savings == alone.savings
    with pytest.raises(InputError, match="array 1") as e:  # a bad array is bad input, named
        omaps.evaluate_corpus([disc, np.zeros((4, 4), np.int16) - 1], "sq4", jobs=1)
    assert e.value.path == "array 1"
    with pytest.raises(InputTypeError) as e:
        omaps.evaluate_corpus([disc, 3], "sq4", jobs=1)
    assert e.value.param == "paths[1]"


def test_bake_omms_takes_one_path_and_speaks_python(tmp_path):
    missing = tmp_path / "plants.glb"
    with pytest.raises(InputError, match="no such file") as e:
        omaps.bake_omms(str(missing), tmp_path / "out")
    assert e.value.path == str(missing)
    with pytest.raises(InputError) as e:
        omaps.bake_omms([texture(tmp_path), tmp_path / "a.npy", tmp_path / "b.npy"], tmp_path / "out")
    assert e.value.param == "inputs" and "--" not in str(e.value) and "-o" not in str(e.value)
    with pytest.raises(InputError, match="^level, dynamic and budget exclude each other$"):
        omaps.bake_omms(str(missing), level=3, dynamic=2.0)
    with pytest.raises(InputError, match="^level must be an integer from 0 to 12, got 13$"):
        omaps.bake_omms(str(missing), level=13)
    with pytest.raises(InputTypeError, match="^jobs must be an integer"):
        omaps.bake_omms(str(missing), jobs="2")


def test_load_alpha_without_alpha_names_the_parameter(tmp_path, capsys):
    rgb = texture(tmp_path, "x.jpg", "RGB")
    with pytest.raises(InputError, match=r"x\.jpg: image has no alpha channel .*give channel to pick one") as e:
        omaps.load_alpha(rgb)
    assert "--" not in str(e.value) and e.value.param == "channel"
    assert omaps.load_alpha(rgb, channel="R").values.max() == 255
    assert main(["eval", str(rgb), "--schemes", "sq4"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"omaps: error: {rgb}: image has no alpha channel (mode RGB); give --channel to pick one"


def test_codec_encode_reports_the_shape_given():
    with pytest.raises(InputError, match=r"vq4 stores a 32x32 map of states 0..2, got shape \(16, 16\)") as e:
        omaps.get_codec("vq4").encode(np.zeros((16, 16)))
    assert e.value.param == "m"
    codec = omaps.get_codec("sq4")
    ones = np.ones((4, 4))  # integral floats are states too
    assert np.array_equal(codec.decode(codec.encode(ones)), ones)
    with pytest.raises(InputTypeError, match="name must be a string"):
        omaps.get_codec(4)


def test_omm_level_names_the_option(tmp_path, capsys):
    tex = texture(tmp_path)
    uvs = tmp_path / "uvs.npy"
    np.save(uvs, np.array([[[0, 0], [1, 0], [0, 1]]], np.float32))
    assert main(["omm", str(tex), str(uvs), "-o", str(tmp_path / "out"), "--level", "13"]) == 2
    assert capsys.readouterr().err.strip() == "omaps: error: --level must be an integer from 0 to 12, got 13"
    assert not (tmp_path / "out").exists()
    assert main(["omm", str(tex), str(uvs), "-o", str(tmp_path / "out"), "--level", "3", "--dynamic", "2"]) == 2
    assert capsys.readouterr().err.strip() == "omaps: error: --level, --dynamic and --budget exclude each other"


MODULES_IN_PYTHON_TERMS = ("errors.py", "checks.py", "jobs.py", "texture.py", "schemes.py", "alpha_test.py",
                           "corpus/experiment.py", "corpus/evaluate.py", "trace/experiment.py", "trace/camera.py",
                           "trace/two_state.py", "omm/pipeline.py", "bake/micromap.py", "bake/square.py",
                           "bake/pair_maps.py", "codecs/registry.py")


@pytest.mark.parametrize("module", MODULES_IN_PYTHON_TERMS)
def test_library_messages_name_no_command_line_option(module):
    source = open(os.path.join(os.path.dirname(omaps.__file__), module), encoding="utf-8").read()
    raised = re.findall(r"raise Input(?:Type)?Error\(f?\"([^\"]*)", source)
    assert raised or module in ("errors.py",)
    assert [m for m in raised if re.search(r"(^|[\s(])--?[a-z]", m)] == []
