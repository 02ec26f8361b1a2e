"""Numba kernels before their first use: which a command needs, whether numba's on-disk cache
holds them, and their compile before the command runs -- in parallel processes, one per core,
announced with an estimate and a line at least every ``PROGRESS_EVERY`` seconds.

Kernels are compiled with ``cache=True``: once per machine (and per change of their source or of
any module they import: ``omaps.kernel_cache``), then loaded in about a second. A *family* is the
set of modules one kind of work compiles; a module counts as cached when numba's index of at
least one of its kernels matches that key (what numba itself checks before loading).

The compile runs the library calls the commands make on tiny inputs written to a temporary
folder (``python -m omaps.cli.precompile FAMILY...``; with no family: every one), so it compiles
exactly the specialisations the commands use; the command then loads them from the cache, and so
do its worker processes (which would otherwise each compile the same kernels). Each family's
calls compile its own kernels and none of another family's (a codec's encoders encode a made-up
map, not a baked one; the tracer's filters compile without maps): the families' processes run at
the same time, and two that compiled the same kernels did that work twice. ``python
bench/bench_cold.py`` measures a first use.
"""

from __future__ import annotations

import importlib
import io
import os
import sys
import time

__all__ = ["FAMILIES", "uncached", "families_for", "compile_first", "finish_ahead", "stop_ahead", "warm"]

# family: (modules whose kernels it compiles (``module:function``: that kernel), seconds its
# compile process took with an empty cache on the 2-core reference machine, two such processes at
# a time: imports, the warm-up's tiny runs and the cache writes included)
# (the codecs' own families, vq2, vq4, synth, wavelet and any plug-in's, are declared by their
# entries in the codec registry (``CompileFamily``), their warm-up derived from them: encoding a
# made-up map with every encoder and effort of each codec that declares the family; ``FAMILIES`` is
# both, read on first use so that parsing a command line imports no codec)
COMMAND_FAMILIES = {
    "square": (("omaps.flag_table", "omaps.raster", "omaps.bake.square"), 49),
    "micromap": (("omaps.flag_table", "omaps.bake.micromap"), 39),
    "trace": (("omaps.trace.rays", "omaps.scene.pairing", "omaps.rows"), 51),
    "omm": (("omaps.omm.resolve", "omaps.omm_format", "omaps.coverage", "omaps.rows"), 58),
    "budget": (("omaps.omm.budget",), 13),  # omm --budget's pricing
    # the tracer's budget:BYTES scheme: its allocation, and its mixed maps' reader (other families
    # compile other kernels of both modules)
    "budget-maps": (("omaps.allocate:allocate_arrays", "omaps.trace.lookups:mixed_map_state"), 98),
    # the micromaps' lossless tree representations (``succinctL``, ``csmL``; the registry's
    # ``succinctL`` budget options name it)
    "hierarchical": (("omaps.codecs.succinct", "omaps.codecs.csm"), 70),
}


def _module_cached(name: str) -> bool:
    """Whether numba's cache holds a kernel of module ``name`` (``module:function``: that kernel)."""
    from numba.core.caching import NullCache
    from numba.core.dispatcher import Dispatcher

    name, _, only = name.partition(":")
    try:
        mod = importlib.import_module(name)
    except Exception:  # noqa: BLE001 - a module that cannot be imported compiles nothing here
        return True
    for attr, obj in vars(mod).items():
        if not isinstance(obj, Dispatcher) or getattr(obj.py_func, "__module__", None) != name:
            continue
        if only and attr != only:
            continue
        cache = getattr(obj, "_cache", None)
        if cache is None or isinstance(cache, NullCache):
            continue
        try:
            if cache._cache_file._load_index():  # empty when absent or stale (source changed)
                return True
        except Exception:  # noqa: BLE001 - an unreadable index: numba compiles
            pass
    return False


def uncached(families) -> list[str]:
    """The families (names in ``FAMILIES``) whose kernels numba's cache does not hold."""
    fam = _families()
    return [f for f in dict.fromkeys(families) if not all(_module_cached(m) for m in fam[f][0])]


def _families() -> dict:
    """Every family: the commands' own (``COMMAND_FAMILIES``) and the codecs' (the codec registry's
    ``COMPILE_FAMILIES``)."""
    from ..codecs.registry import COMPILE_FAMILIES

    return {**COMMAND_FAMILIES, **COMPILE_FAMILIES}


def __getattr__(name):
    if name == "FAMILIES":
        return _families()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _scheme_families(text) -> list[str]:
    """The families that baking and encoding these comma-separated schemes compiles: a micromap
    level's, each codec's own (its registry entry), a budget's options' and its allocator's. A name
    that is no scheme compiles nothing here (the command reports it)."""
    from ..codecs.registry import entry
    from ..errors import InputError
    from ..schemes import get_scheme

    out = []
    for name in str(text or "").lower().split(","):
        try:
            s = get_scheme(name.strip())
        except InputError:
            continue
        if s.kind == "micromap":
            out += ["micromap"] + (["hierarchical"] if s.representation != "raw" else [])
        elif s.kind == "square":
            out += list(entry(s.codec.name).family_names)
        elif s.kind == "budget":
            from ..budget import PAIR_OPTIONS

            out += [f for o in (s.options or PAIR_OPTIONS)[1:] for f in entry(o).family_names] + ["budget-maps"]
    return out


def families_for(args) -> list[str]:
    """The families a parsed ``omaps`` command line compiles, in order, without repeats."""
    cmd = getattr(args, "command", None)
    out = []
    if cmd == "eval":
        out = _scheme_families(args.schemes)
    elif cmd == "trace":
        out = ["trace"] + _scheme_families(args.schemes)
    elif cmd == "omm" and getattr(args, "verify", None):
        out = ["omm"]
    elif cmd == "omm" and getattr(args, "inputs", None) and not getattr(args, "expand", False):
        source = getattr(args, "source", None) or "texture"
        out = ["micromap", "omm"] + (_scheme_families(source) if source != "texture" else [])
        if getattr(args, "budget", None) is not None:
            out.append("budget")
            if getattr(args, "weights", None) == "view":  # the view's hits are traced
                out.append("trace")
    elif cmd == "report":  # a scene is traced, a folder of textures evaluated
        from ..scene.files import is_scene_file

        scene = is_scene_file(str(getattr(args, "input", "")))
        if scene:
            from ..trace.experiment import DEFAULT_SCHEMES as TRACE_DEFAULT

            out = ["trace"] + _scheme_families(args.schemes or TRACE_DEFAULT)
        else:
            from ..schemes import DEFAULT_SCHEMES

            out = _scheme_families(args.schemes or ",".join(DEFAULT_SCHEMES))
    elif cmd == "encode":
        out = _scheme_families(args.codec)
    elif cmd == "bake":
        out = _scheme_families(args.scheme)
    return list(dict.fromkeys(out))


def _wanted() -> bool:
    forced = os.environ.get("OMAPS_PROGRESS", "").strip()
    if forced in ("0", "1"):
        return forced == "1"
    return sys.stderr.isatty()


def _seconds(families) -> int:
    fam = _families()
    return sum(fam[f][1] for f in families)


# seconds between the lines while a command waits for the compile ahead (at most 5 promised: room
# for a slow poll)
PROGRESS_EVERY = 4.0


def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


# The range a compile is announced with, against FAMILIES' figures: the same processes took from
# about 0.75 to 1.5 times as long on the reference machine, from run to run and with the load of
# other work.
AHEAD_RANGE = (0.75, 1.5)


def _load() -> float:
    """The load of other work on the machine (the 1-minute load average, less this process)."""
    try:
        return max(0.0, os.getloadavg()[0] - 1.0)
    except (AttributeError, OSError):
        return 0.0


def _ahead_seconds(groups, load: float = 0.0) -> tuple[int, int]:
    """About how long the compile takes, as a range: its slowest process's families, slowed down
    while more processes (its own, other work) than cores share the machine; the measured runs
    spread over a factor of 2."""
    t = max(_seconds(g) for g in groups) * max(1.0, (len(groups) + load) / _cores())
    low, high = (t * f for f in AHEAD_RANGE)
    return max(5, int(round(low / 5) * 5)), max(10, int(round(high / 5) * 5))


def _groups(families, cores: int) -> list[list[str]]:
    """The families spread over at most ``cores`` processes, the longest first onto the process
    with the least to do (each process then compiles for about as long)."""
    fam = _families()
    bins = [[] for _ in range(max(1, min(cores, len(families))))]
    for f in sorted(families, key=lambda f: -fam[f][1]):
        min(bins, key=lambda b: sum(fam[x][1] for x in b)).append(f)
    return [b for b in bins if b]


def _command(group, evaluation: bool = False) -> list[str]:
    """The command line of one compile process (it prints each family's name when done);
    ``evaluation``: only the kernels ``omaps eval`` runs (``warm``'s ``evaluation_only``)."""
    return [sys.executable, "-m", "omaps.cli.precompile", *(["--eval"] if evaluation else []), *group]


class _Ahead:
    """The compile processes of ``compile_first``: per process its families, the process, and
    the files its stdout (the families done, one a line) and stderr go to."""

    def __init__(self, groups, estimate: tuple[int, int], show: bool = True, evaluation: bool = False):
        import subprocess  # here, not at the top: a command that starts nothing ahead skips its import
        import tempfile

        self.t0 = time.perf_counter()
        self.estimate = estimate
        self.show = show
        self.procs = []
        for g in groups:
            out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
            self.procs.append((g, subprocess.Popen(_command(g, evaluation), stdin=subprocess.DEVNULL, stdout=out, stderr=err),
                               out, err))

    def done(self) -> list[str]:
        """The families compiled so far. Each process's stdout is read in place (``os.pread``): the
        file's offset is shared with the process, which writes at it, so a seek here could make
        it write over a family it had reported."""
        names = []
        for g, _, out, _ in self.procs:
            fd = out.fileno()
            text = os.pread(fd, os.fstat(fd).st_size, 0).decode(errors="replace")
            names += [f for f in text.split() if f in g]
        return names

    def status(self) -> str:
        done = set(self.done())
        compiling, waiting = [], []
        for g, p, _, _ in self.procs:
            left = [f for f in g if f not in done]
            if p.poll() is None and left:
                compiling.append(left[0])
                waiting += left[1:]
        parts = [f"done {', '.join(f for g, *_ in self.procs for f in g if f in done)}"] if done else []
        if compiling:
            parts.append(f"compiling {', '.join(compiling)}")
        elif not waiting:
            parts.append("writing the cache")  # every family reported, the processes not yet ended
        if waiting:
            parts.append(f"then {', '.join(waiting)}")
        elapsed = time.perf_counter() - self.t0
        low, high = self.estimate
        when = (f"about {low}-{high} s in all" if elapsed <= high
                else f"longer than the estimate of {low}-{high} s")
        return f"omaps: compiling numba kernels: {'; '.join(parts)} ({elapsed:.0f} s so far, {when})"

    def stop(self) -> None:
        for _, p, out, err in self.procs:
            if p.poll() is None:
                p.kill()
                p.wait()
            out.close()
            err.close()


def compile_first(args):
    """Before a command runs: compile its kernels that numba's cache does not hold yet, in
    background processes (its families spread over the cores; for ``omaps eval`` only what an
    evaluation runs), and say so on stderr (a terminal, or OMAPS_PROGRESS=1) with an estimate; the
    command and its worker processes then load them instead of each compiling them. Returns what
    ``finish_ahead`` waits for (None when everything is cached). With OMAPS_PRECOMPILE=0 nothing
    starts: the command compiles on first use in its own process, announced by one line."""
    missing = uncached(families_for(args))
    if not missing:
        return None
    show = _wanted()
    if os.environ.get("OMAPS_PRECOMPILE") == "0":
        if show:
            print(f"omaps: compiling numba kernels for first use: {', '.join(missing)} (once; about "
                  f"{_seconds(missing)} s of compiling on one core)", file=sys.stderr, flush=True)
        return None
    groups = _groups(missing, _cores())
    load = _load()
    low, high = _ahead_seconds(groups, load)
    busy = f", the machine busy with other work (load {load + 1:.1f})" if load >= 0.5 else ""
    if show:
        print(f"omaps: compiling numba kernels for first use: {', '.join(missing)} (once, then cached; about "
              f"{low}-{high} s on {_cores()} cores{busy}; a line every {PROGRESS_EVERY:.0f} s)",
              file=sys.stderr, flush=True)
    return _Ahead(groups, (low, high), show, evaluation=getattr(args, "command", None) == "eval")


def finish_ahead(started) -> None:
    """Wait for ``compile_first``'s processes, with a line on stderr at least every
    ``PROGRESS_EVERY`` seconds (the families done and still compiling, the time so far); a
    failure is reported (those kernels compile on first use instead) and changes no exit code."""
    if not started:
        return
    try:
        last = None
        while any(p.poll() is None for _, p, _, _ in started.procs):
            now = time.perf_counter()
            if last is None or now - last >= PROGRESS_EVERY:
                if started.show:
                    print(started.status(), file=sys.stderr, flush=True)
                last = now
            time.sleep(min(0.1, max(0.0, PROGRESS_EVERY - (time.perf_counter() - last))))
        for g, p, _, err in started.procs:
            if p.returncode and started.show:
                err.seek(0)
                text = err.read().decode(errors="replace").strip().splitlines()
                print(f"omaps: compiling {', '.join(g)} failed ({(text or ['?'])[-1]}); the command compiles "
                      "what it needs itself", file=sys.stderr)
    finally:
        started.stop()
    if started.show:
        print(f"omaps: kernels compiled in {time.perf_counter() - started.t0:.0f} s", file=sys.stderr, flush=True)


def stop_ahead(started) -> None:
    """Stop ``compile_first``'s processes (the command failed or was interrupted)."""
    if started:
        started.stop()


def _quad_scene(folder: str) -> str:
    """A unit quad (two triangles) with a 16 x 16 alpha-tested texture, as a .gltf file."""
    import base64
    import json

    import numpy as np
    from PIL import Image

    yy, xx = np.mgrid[0:16, 0:16]
    rgba = np.zeros((16, 16, 4), np.uint8)
    rgba[..., 1] = 160
    rgba[..., 3] = np.where((xx - 7.5) ** 2 + (yy - 7.5) ** 2 < 40, 255, 0) + np.where(xx == 3, 100, 0)
    png = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(png, format="PNG")
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blob = pos.tobytes() + uv.tobytes() + idx.tobytes() + b"\0\0\0\0"
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"alphaMode": "MASK", "alphaCutoff": 0.5, "doubleSided": True,
                       "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}],
        "images": [{"uri": "data:image/png;base64," + base64.b64encode(png.getvalue()).decode()}],
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                        {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
    }
    path = os.path.join(folder, "quad.gltf")
    with open(path, "w") as f:
        json.dump(doc, f)
    Image.fromarray(rgba, "RGBA").save(os.path.join(folder, "leaf.png"))
    return path


def _states_map(n: int):
    """An n x n map of every state, as a baker gives one: an O disc, a ring of C, T around it."""
    import numpy as np

    from .. import states

    yy, xx = np.mgrid[0:n, 0:n]
    r = np.hypot(xx - (n - 1) / 2, yy - (n - 1) / 2) / n
    return np.where(r < 0.25, states.O, np.where(r < 0.35, states.C, states.T)).astype(np.uint8)


def warm(families, report=None, evaluation_only: bool = False) -> None:
    """Compile the families' kernels by running the library calls the commands make on tiny
    inputs; ``report``: a stream that gets each family's name when its kernels are compiled;
    ``evaluation_only``: only the calls of ``omaps eval`` (a family with none compiles nothing)."""
    import tempfile
    import warnings

    import numpy as np

    from .. import bake_omms, evaluate_corpus, trace_scene, verify_omms
    from ..codecs.registry import COMPILE_FAMILIES, family_codecs

    with tempfile.TemporaryDirectory(prefix="omaps-precompile-") as tmp:
        scene = _quad_scene(tmp)
        leaf = os.path.join(tmp, "leaf.png")

        def ev(schemes):
            def run():
                evaluate_corpus([leaf], schemes, jobs=1)

            run.evaluation = True  # what omaps eval compiles (warm's evaluation_only)
            return run

        def tr(schemes, path=scene, **kw):
            return lambda: trace_scene(path, schemes, size=16, camera="0.5,0.5,2:0.5,0.5,0:60", jobs=1, **kw)

        def omm(out, inputs=(scene,), **kw):
            return lambda: bake_omms(list(inputs), os.path.join(tmp, out), threads=1, **kw)

        def enc(*codecs):
            """The codecs' encoders (every encoder and effort: the deck's encoder and thorough are
            kernels of their own in vq2; a codec with none to choose, once) on a made-up map,
            through ``Codec.encode_many`` as trace, omm --from and eval call them, and each codec's
            random-access lookup on the block: no square baker (the square family's) and no
            tracer."""
            def run():
                from ..codecs import get_codec

                for name in codecs:
                    codec = get_codec(name)
                    for e in codec.encoders or (None,):
                        for f in codec.efforts or (None,):
                            blocks, _ = codec.encode_many(_states_map(codec.map_size)[None], e, f)
                    codec.lookup(blocks[0], 0, 0)

            run.evaluation = True
            return run

        def tracer():
            """What the tracer does with a scheme's maps, with no map baked: the maps' dedupe (on
            made-up maps), the filters of baked and stored maps (micromaps, a file's micromaps,
            square maps of any codec) and the 2-state maps' fractions and promotion."""
            from ..alpha_test import material_test
            from ..coverage import cell_fractions
            from ..promotion import resolve_regions
            from ..trace import lookups
            from ..trace.filter import make_filter
            from ..trace.maps import dedupe_maps

            dedupe_maps(np.stack([_states_map(16)] * 2))
            for fn in (lookups.micro_map_state, lookups.stored_micromap_state, lookups.pair_map_state):
                make_filter(fn)
            # --two-state: the cells' opaque fractions and the hashed promotion, on a made-up pair
            # and an 8-bit material's test (a scene's alpha as a PNG decodes it)
            test = material_test("t", "MASK", 0.5, 1.0, _states_map(8) * np.uint8(127), 255, "linear", "wrap",
                                 "wrap")
            frac, centre = cell_fractions(test, np.random.default_rng(0).random((1, 6, 2)), np.ones(1, bool), 16)
            resolve_regions(_states_map(16)[None], frac, centre, "hashed")

        def budget():
            """``omm --budget``'s own kernels on made-up items, with no bake and no trace (the
            micromap, omm and trace families' work): the pricing's texel areas, merge of contents,
            greedy over groups and row index, and the view hits' counting filter."""
            from ..bake.micromap import texel_areas
            from ..omm.budget import _adopt, _merged
            from ..rows import RowIndex
            from ..trace import lookups
            from ..trace.filter import make_filter

            rng = np.random.default_rng(0)
            texel_areas(rng.random((8, 3, 2)), 16, 16)
            rows3 = rng.integers(0, 3, (8, 16)).astype(np.uint8)
            none = np.zeros(1, np.int64)
            _merged(rows3, rows3, np.full(8, 12, np.int64), rng.random(8), none, none, 2)
            _adopt(rng.random((8, 4)), rng.integers(0, 4, (8, 4)), np.full(4, 10, np.int64), 30)
            RowIndex(8).add(rng.integers(0, 255, (40, 8)).astype(np.uint8))  # (grows its table)
            make_filter(lookups.counting_state)

        def budget_maps():
            """The tracer's ``budget:BYTES`` scheme's own kernels: the allocation over a pair's
            options (made-up ones) and the filter of its mixed maps (every codec's reader)."""
            from ..allocate import allocate
            from ..trace import lookups
            from ..trace.filter import make_filter

            rng = np.random.default_rng(0)
            allocate(rng.integers(1, 64, (8, 3)), rng.random((8, 3)), 200)
            make_filter(lookups.mixed_map_state)

        def or_downsample():
            """Square maps of several sizes baked once (the finest), the coarser OR-ed from it."""
            from ..bake.square import or_downsample

            or_downsample(np.zeros((1, 4, 4), np.uint8), 2)

        runs = {
            "square": [ev("sq4,sq16"), or_downsample],
            "micromap": [ev("tri2,tri3")],
            "trace": [tr("none", shadows=True), tracer],
            "omm": [omm("omm"), omm("omm_2", format="2state", promote="hashed"), omm("omm.glb"),
                    lambda: verify_omms(os.path.join(tmp, "omm")),
                    tr("none,omm", path=os.path.join(tmp, "omm.glb"))],
            "hierarchical": [ev("succinct3,csm3"), tr("none,succinct3,csm3")],
            "budget": [budget],
            "budget-maps": [budget_maps],
            # each codec family of the registry: its codecs' encoders
            **{f: [enc(*family_codecs(f))] for f in COMPILE_FAMILIES},
        }
        failed = []
        for f in families:  # one family failing (no Embree, say) leaves the others compiled
            for run in [r for r in runs[f] if not evaluation_only or getattr(r, "evaluation", False)]:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        run()
                except Exception as exc:  # noqa: BLE001 - reported below, the next family goes on
                    failed.append(f"{f}: {type(exc).__name__}: {str(exc)[-200:]}")
                    break
            else:
                if report is not None:
                    print(f, file=report, flush=True)
        if failed:
            raise RuntimeError("; ".join(failed))


if __name__ == "__main__":
    known = _families()
    only_eval = "--eval" in sys.argv[1:]
    names = [a for a in sys.argv[1:] if a != "--eval"]
    unknown = [f for f in names if f not in known]
    if unknown:
        sys.exit(f"unknown families: {', '.join(unknown)} (known: {', '.join(known)})")
    warm(names or list(known), report=sys.stdout, evaluation_only=only_eval)
