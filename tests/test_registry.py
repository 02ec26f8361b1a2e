"""The codec registry as the plug-in point: format codes it assigns, the checks it applies to an
entry, budget membership by opt-in, an encoder a codec lacks falling back (and said so), what
``Codec.compressed`` means, and plug-ins found through the entry point group ``omaps.codecs``
(their code in the key of every kernel that inlines the registry)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from omaps.codecs import ENTRIES, CodecEntry, CompileFamily, codec_names, entry, get_codec, square_codec
from omaps.codecs import registry
from omaps.errors import InputError
from omaps.schemes import get_scheme

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_codes_follow_declaration_order():
    """Codes 1, 2, ... in the order of ``ENTRIES``, omaps' own entries first; every name once."""
    assert [e.code for e in ENTRIES] == list(range(1, len(ENTRIES) + 1))
    origins = [e.origin == "omaps" for e in ENTRIES]
    assert origins == sorted(origins, reverse=True)
    assert len({e.name for e in ENTRIES}) == len(ENTRIES)
    assert all(get_codec(n).code == entry(n).code for n in ["sq1", "sq128", *codec_names()])


def _entry(**kw):
    base = dict(name="mine", map_size=16, block_bytes=64, lookup=lambda: None, make=lambda: None,
                families=("square",), description="a codec")
    return CodecEntry(**{**base, **kw})


@pytest.mark.parametrize("change, problem", [
    (dict(name="vq4"), "already declared by omaps"),
    (dict(name="Mine"), "lower-case"),
    (dict(name="mine-fast"), "ends in a variant"),
    (dict(name="sq12"), "scheme name"),
    (dict(name="budget"), "scheme name"),
    (dict(map_size=24), "power of two"),
    (dict(map_size=256), "map_size"),
    (dict(block_bytes=0), "block_bytes"),
    (dict(lookup=3), "callables"),
    (dict(budget_default=True), "budget_default needs budget"),
    (dict(description=""), "one line"),
    (dict(description="two\nlines"), "one line"),
    (dict(families=("nonesuch",)), "unknown compile family 'nonesuch'"),
    (dict(families=(CompileFamily("vq4", ("x",)),)), "declared otherwise"),
    (dict(families=(CompileFamily("mine", ()),)), "names no modules"),
])
def test_an_entry_is_checked(change, problem):
    seen = {e.name: "omaps" for e in ENTRIES}
    families = dict(registry._FAMILIES)
    with pytest.raises(InputError) as exc:
        registry._check(_entry(**change), "codec plug-in 'x' (x:entries, from x)", seen, families)
    assert problem in str(exc.value) and str(exc.value).startswith("codec plug-in 'x'")
    registry._check(_entry(), "codec plug-in 'x'", seen, families)  # the same entry, unchanged, passes


def test_not_an_entry():
    with pytest.raises(InputError, match="must be a CodecEntry, got dict"):
        registry._check({"name": "x"}, "codec plug-in 'x'", {}, {})


def test_budget_membership_is_opt_in():
    """The default options are the entries that opt in; the others may still be named."""
    from omaps.budget import PAIR_OPTIONS

    assert PAIR_OPTIONS[1:] == tuple(e.name for e in ENTRIES if e.budget_default)
    assert set(PAIR_OPTIONS[1:]) < set(registry.budget_options(variable=True))
    assert "succinct6" not in PAIR_OPTIONS and "succinct6" in get_scheme("budget:1KiB:default+succinct6").options
    assert not any(entry(n).budget_default and not entry(n).budget for n in codec_names())


def test_a_command_wide_encoder_falls_back_and_says_so():
    """``--encoder paper`` for a codec without the deck's encoder: its default, with a note; a
    variant named on the codec itself stays an error."""
    s = get_scheme("wavelet3", encoder="paper")
    assert (s.encoder, s.effort) == ("best", "medium")
    assert s.notes == ("wavelet3 has no encoder 'paper': its default encoder 'best' was used",)
    assert s.settings()["notes"] == list(s.notes)
    assert get_scheme("vq4", encoder="paper").notes == ()
    with pytest.raises(InputError, match="unknown variant 'paper' of wavelet3"):
        get_scheme("wavelet3-paper")
    with pytest.raises(InputError, match="wavelet3 has no encoder 'paper'"):
        get_codec("wavelet3").options("paper")


def test_notes_are_printed_under_the_results():
    from omaps.schemes import notes_lines

    settings = {"schemes": {s.name: s.settings() for s in (get_scheme("vq4"), get_scheme("wavelet3", encoder="paper"))}}
    assert notes_lines(settings) == ["note: wavelet3: wavelet3 has no encoder 'paper': its default encoder 'best' "
                                     "was used"]


def _all_c_codec(encoders=()):
    """A lossy 16x16 codec with nothing to choose: every block decodes to all C."""
    def enc(maps, e, f):
        return np.zeros((len(maps), 4), np.uint8)

    def dec(data):
        return np.full((16, 16), 2, np.uint8)

    return square_codec("allc", 16, 4, enc, dec, lambda b, x, y: 2, encoders=encoders,
                        default_encoder=encoders[0] if encoders else None)


def test_compressed_means_encoded_not_has_encoders():
    """A lossy codec declared with no encoder choices is still encoded and its loss counted."""
    c = _all_c_codec()
    assert c.compressed and not c.raw and c.options() == (None, None)
    blocks, decoded = c.encode_many(np.ones((3, 16, 16), np.uint8))
    assert blocks.shape == (3, 4) and (decoded == 2).all()
    assert get_codec("sq16").raw and not get_codec("sq16").compressed
    assert all(get_codec(n).compressed for n in codec_names())
    with pytest.raises(InputError, match="allc has no encoder 'paper' \\(it has no encoders to choose\\)"):
        c.options("paper")
    assert c.fallback("paper", "fast")[:2] == (None, None)


def test_square_codec_checks_its_defaults():
    with pytest.raises(InputError, match="default_encoder"):
        square_codec("x", 16, 4, print, print, print, encoders=("a",), default_encoder="b")
    with pytest.raises(InputError, match="encode_many must be"):
        square_codec("x", 16, 4, None, print, print)


def test_make_must_give_the_codec_its_entry_states(monkeypatch):
    bad = _entry(name="liar", make=lambda: _all_c_codec())
    monkeypatch.setitem(registry._BY_NAME, "liar", bad)
    with pytest.raises(InputError, match="make\\(\\) gave allc .*not the Codec its entry states"):
        get_codec("liar")


# --- plug-ins ---------------------------------------------------------------------------------

PLUGIN = '''
from omaps.codecs import CodecEntry, CompileFamily, square_codec


def _lookup():
    from .block import lookup
    return lookup


def _make():
    from omaps.codecs.raw import pack_states, unpack_states
    from .block import lookup

    def enc(maps, e, f):
        return pack_states(maps.reshape(len(maps), -1))

    def dec(data):
        import numpy as np
        m = unpack_states(np.frombuffer(data, np.uint8)[None], 256)[0]
        return np.minimum(m, 2).reshape(16, 16)

    return square_codec("copy16", 16, 64, enc, dec, lookup)


def entries():
    return [CodecEntry("copy16", 16, 64, _lookup, _make,
                       ("square", CompileFamily("copy16", ("copyplug.block",), 5)), budget=True,
                       description="a raw 16x16 map again (a test plug-in)")]
'''

BLOCK = '''
from numba import njit

from omaps.codecs.bits import get_bits


@njit(cache=True)
def lookup(block, x, y):
    v = get_bits(block, 2 * (16 * y + x), 2)
    return 2 if v > 2 else v
'''


def _install(site, name="copyplug", module=PLUGIN, value="copyplug:entries"):
    """A package ``name`` with an entry point of the group omaps.codecs, as pip installs one."""
    pkg = site / name
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / "__init__.py").write_text(module)
    (pkg / "block.py").write_text(BLOCK)
    info = site / f"{name}-1.0.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[omaps.codecs]\n{name} = {value}\n")


PROBE = """
import json, sys
import omaps
from omaps import kernel_cache
import numba.core.caching
from omaps.codecs import ENTRIES
import omaps.codecs.dispatch as dispatch, omaps.raster as raster
from omaps.plugins import codec_entry_points
print(json.dumps({"dispatch": kernel_cache.source_key(dispatch.__file__),
                  "raster": kernel_cache.source_key(raster.__file__),
                  "codes": {e.name: e.code for e in ENTRIES}, "plugins": [ep.name for ep in codec_entry_points()]}))
"""


def _probe(site, **env):
    r = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=300,
                       env=dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), ROOT]), **env))
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_a_plugin_joins_the_registry_and_every_dependent_key(tmp_path):
    """Installed, a plug-in's codec gets the code after omaps' own; the key of a kernel that
    reaches the registry changes with the plug-in's presence and with its content (its block
    module's import of omaps' bit reader included); a kernel that does not reach the registry
    keeps its key."""
    site = tmp_path / "site"
    site.mkdir()
    without = _probe(site)
    _install(site)
    with_it = _probe(site)
    assert with_it["plugins"] == ["copyplug"] and without["plugins"] == []
    assert with_it["codes"]["copy16"] == max(without["codes"].values()) + 1
    assert {k: v for k, v in with_it["codes"].items() if k != "copy16"} == without["codes"]
    assert with_it["dispatch"] != without["dispatch"] and with_it["raster"] == without["raster"]
    (site / "copyplug" / "block.py").write_text(BLOCK.replace("v > 2", "v >= 3"))
    changed = _probe(site)
    assert changed["dispatch"] not in (with_it["dispatch"], without["dispatch"])
    assert _probe(site, OMAPS_CODEC_PLUGINS="0")["dispatch"] == without["dispatch"]


def test_the_plugin_reaches_omaps_modules_it_imports(tmp_path):
    """A plug-in module's key covers the omaps modules it imports (watched across packages)."""
    site = tmp_path / "site"
    _install(site)
    code = ("import json; from omaps import kernel_cache; import omaps; "
            "from omaps.plugins import codec_entry_points, package_folder; "
            "top, folder = package_folder(codec_entry_points()[0]); kernel_cache.watch(folder, top); "
            f"print(json.dumps(kernel_cache.dependencies({str(site / 'copyplug' / 'block.py')!r})))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), ROOT])))
    assert r.returncode == 0, r.stderr
    deps = [os.path.relpath(p, ROOT) if p.startswith(ROOT) else os.path.basename(p) for p in json.loads(r.stdout)]
    assert deps[0] == "block.py" and os.path.join("omaps", "codecs", "bits.py") in deps


@pytest.mark.parametrize("module, value, problem", [
    ("def entries():\n    raise RuntimeError('boom')\n", "copyplug:entries", "loading its codecs failed: boom"),
    ("entries = 3\n", "copyplug:entries", "not a callable"),
    ("def entries():\n    return [1]\n", "copyplug:entries", "must be a CodecEntry, got int"),
    (PLUGIN.replace('CodecEntry("copy16"', 'CodecEntry("vq4"'), "copyplug:entries", "'vq4' is already declared by omaps"),
    (PLUGIN, "copyplug:nonesuch", "has no attribute 'nonesuch'"),
])
def test_a_broken_plugin_is_an_error_naming_it(tmp_path, module, value, problem):
    """Exit 2 with one line naming the plug-in; with OMAPS_CODEC_PLUGINS=0 omaps starts."""
    site = tmp_path / "site"
    _install(site, module=module, value=value)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), ROOT]), OMAPS_PROGRESS="0")
    r = subprocess.run([sys.executable, "-m", "omaps", "eval", "--schemes", "sq4"], capture_output=True, text=True,
                       timeout=300, env=env, cwd=str(tmp_path))
    assert r.returncode == 2, (r.stdout, r.stderr)
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith(f"omaps: error: codec plug-in 'copyplug' ({value}, from copyplug): "), r.stderr
    assert problem in last and "OMAPS_CODEC_PLUGINS=0" in last and "Traceback" not in r.stderr


def test_without_plugins_omaps_starts_past_a_broken_one(tmp_path):
    site = tmp_path / "site"
    _install(site, module="def entries():\n    raise RuntimeError('boom')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), ROOT]), OMAPS_CODEC_PLUGINS="0")
    r = subprocess.run([sys.executable, "-c", "from omaps.codecs import ENTRIES; print(len(ENTRIES))"],
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0 and int(r.stdout) == sum(e.origin == "omaps" for e in ENTRIES), r.stderr


def test_the_kernels_of_omaps_with_and_without_plugins_are_cached_apart(tmp_path):
    """With a plug-in installed, a kernel that reaches the registry is cached under a name of its
    own (both cache entries live side by side); one that does not keeps numba's name."""
    site = tmp_path / "site"
    _install(site)
    code = textwrap.dedent("""
        import json
        import omaps
        import numba.core.caching as c
        import omaps.trace.lookups as lookups, omaps.raster as raster
        from numba.core.dispatcher import Dispatcher
        def disamb(mod):
            f = next(o for o in vars(mod).values() if isinstance(o, Dispatcher) and o.py_func.__module__ == mod.__name__)
            return f._cache._impl.locator.get_disambiguator()
        print(json.dumps([disamb(lookups), disamb(raster)]))
    """)
    out = []
    for env in ({}, {"OMAPS_CODEC_PLUGINS": "0"}):
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                           env=dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), ROOT]), **env))
        assert r.returncode == 0, r.stderr
        out.append(json.loads(r.stdout))
    (plug_lookups, plug_raster), (plain_lookups, plain_raster) = out
    assert "-plugins-" in plug_lookups and "-plugins-" not in plain_lookups
    assert plug_raster == plain_raster and "-plugins-" not in plain_raster


def test_a_plugins_compile_family_warms_up(tmp_path):
    """The compile-ahead knows a plug-in's family from its entry alone: its warm-up encodes with
    the plug-in's codec (no hand-kept table), and a scheme naming the codec asks for it."""
    site = tmp_path / "site"
    _install(site)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), ROOT]), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    r = subprocess.run([sys.executable, "-m", "omaps.cli.precompile", "copy16"], capture_output=True, text=True,
                       timeout=600, env=env)
    assert r.returncode == 0 and r.stdout.split() == ["copy16"], r.stderr
    code = ("from argparse import Namespace as ns; from omaps.cli.precompile import families_for, uncached; "
            "f = families_for(ns(command='eval', schemes='copy16,sq4')); print(f, uncached(['copy16']))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0 and r.stdout.strip() == "['square', 'copy16'] []", (r.stdout, r.stderr)
