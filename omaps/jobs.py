"""``omaps omm`` as one call: ``bake_omms`` bakes standard opacity micromaps of a scene or of a
texture and UV triangles, writes them as OMM files or into a glTF, and returns an ``OmmBake``;
``verify_omms`` and ``expand_omms`` beside it.

Each command is one library call returning a result object: ``omaps.evaluate_corpus`` (eval),
``omaps.trace_scene`` (trace), ``omaps.bake_omms`` (omm), ``omaps.run_batch`` (batch). The
commands parse their options, call, and print what they return. ``bake_omms`` lives here, above
both the ``omm`` and the ``trace`` packages, because its ``view`` weights come from a counting
trace of the scene (``omaps.trace.view``).

Example::

    >>> import numpy as np, omaps, tempfile, os
    >>> folder = tempfile.mkdtemp()
    >>> np.save(os.path.join(folder, "uvs.npy"), np.array([[[0, 0], [1, 0], [0, 1]]], np.float32))
    >>> alpha = np.zeros((8, 8), np.uint8); alpha[:, 4:] = 255
    >>> from PIL import Image; Image.fromarray(alpha).save(os.path.join(folder, "leaf.png"))
    >>> bake = omaps.bake_omms([os.path.join(folder, "leaf.png"), os.path.join(folder, "uvs.npy")],
    ...                        os.path.join(folder, "omm"), level=3)
    >>> bake.statistics["triangles"], bake.statistics["micro_triangles"], sorted(os.listdir(bake.output))[0]
    (1, 64, 'omm.json')
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass, field

from collections.abc import Callable, Sequence
from typing import Any

from . import checks
from .errors import InputError, InputTypeError, check_count
from .text import plural

__all__ = ["bake_omms", "OmmBake", "omm_settings", "omm_input_spec", "verify_omms", "OmmCheck", "expand_omms",
           "TqdmProgress"]


class TqdmProgress:
    """``omm.pipeline.Progress`` as a progress bar on stderr: one bar a stage (the budget's
    pricing and the baking, in micro-triangles), its total known when it starts."""

    FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} {unit} [{elapsed}<{remaining}]"

    def __init__(self):
        self.bar = None

    def stage(self, name: str, total: int, unit: str) -> None:
        from tqdm import tqdm  # only for the bar (its import costs 25 ms of the start)

        self.close()
        self.bar = tqdm(total=total, desc=f"omm {name}", unit=unit, unit_scale=unit == "micro-triangles",
                        bar_format=self.FORMAT, leave=False)

    def advance(self, n: int = 1) -> None:
        self.bar.update(n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


@dataclass
class OmmBake:
    """What ``bake_omms`` baked (and wrote).

    Attributes
    ----------
    result : omaps.omm.OmmResult
        The micromaps: data, triangle records, index, summary (settings, statistics, usage).
    settings : omaps.omm.OmmSettings
    spec : dict
        The input as ``omm.json`` records it.
    output : str or None
        Where it was written (a folder, or a .glb / .gltf file).
    skipped : list of dict
        Primitives of a scene left out (mesh, primitive, name, reason).
    warnings : list of str
        What writing a glTF output warned about.
    seconds : float
        Time of the bake (inputs read, weights, bake, pack), not of the writing.
    """

    result: Any
    settings: Any
    spec: dict
    output: str | None = None
    skipped: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    seconds: float = 0.0
    source_blocks: dict | None = None  # expand_omms: what was expanded (pair blocks: codec, blocks; merged: scheme, nodes, bytes)

    @property
    def statistics(self) -> dict:
        """Triangles, micro-triangles by state, micromaps (with and without reuse), bytes."""
        return self.result.summary["statistics"]

    def held_states(self) -> str:
        """The micro-triangle states the output holds. The statistics count the bake's T, O and
        unknown (C); 4-state output keeps every unknown one (as unknown-transparent or
        unknown-opaque), 2-state output has none: each became T or O by the promotion rule."""
        st = self.statistics
        known_area = f"known area {st['known_area_fraction']:.1%}"
        if self.settings.format != "2state":
            return f"{st['transparent']} T, {st['opaque']} O, {st['unknown']} unknown; {known_area}"
        to_t, to_o = st["unknown_resolved"]["transparent"], st["unknown_resolved"]["opaque"]
        return (f"{st['transparent'] + to_t} T, {st['opaque'] + to_o} O, 0 unknown: {st['unknown']} unknown "
                f"resolved to 2 states by {self.settings.promotion}, {to_t} to T and {to_o} to O; {known_area} "
                "before resolving")

    def messages(self) -> list[str]:
        """What ``omaps omm`` prints on stderr: the glTF writer's warnings, the ``--from`` scheme's
        notes (``Scheme.notes``), the primitives left out."""
        notes = (self.result.summary.get("pair_blocks") or {}).get("notes", [])
        return [f"omaps: warning: {w}" for w in self.warnings] + [f"omaps: note: {n}" for n in notes] + [
            f"omaps: skipped mesh {s['mesh']} primitive {s['primitive']} ({s['name']}): {s['reason']}"
            for s in self.skipped]

    def line(self) -> str:
        """One line as ``omaps omm`` prints it."""
        st = self.statistics
        return (f"{self.output}: {plural(st['triangles'], 'triangle')}, "
                f"{plural(st['micro_triangles'], 'micro-triangle')} ({self.held_states()}); "
                f"{plural(st['micromaps'], 'micromap')} after reuse (of {st['micromaps_without_reuse']}), "
                f"{plural(st['data_bytes'], 'data byte')}; {self.seconds:.2f} s")


@contextlib.contextmanager
def _numba_threads(threads: int | None):
    """numba's thread count set to ``threads`` for the block (None: left as it is)."""
    if threads is None:
        yield
        return
    import numba

    check_count(threads, "threads")
    before = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
    try:
        yield
    finally:
        numba.set_num_threads(before)


def omm_settings(*, level: int | None = None, dynamic: float | None = None, max_level: int = 8,
                 budget: int | str | None = None, format: str = "4state", promote: str = "nearest", seed: int = 0,
                 special: bool = True, dedup: bool = True, source: str = "texture", encoder: str | None = None,
                 effort: str | None = None, jobs: int = 1) -> Any:
    """The ``OmmSettings`` of ``bake_omms``' options, checked (an ``InputError`` naming the
    parameter, or the conflict)."""
    from . import omm_format
    from .names import EFFORTS, PROMOTIONS
    from .omm.pipeline import OmmSettings
    from .omm_format import MAX_LEVEL

    if level is not None:
        level = checks.integer(level, "level", 0, MAX_LEVEL)
    if dynamic is not None:
        dynamic = checks.number(dynamic, "dynamic", 0, open_lo=True)
    max_level = checks.integer(max_level, "max_level", 0, MAX_LEVEL)
    checks.choice(format, "format", tuple(omm_format.FORMAT_NAMES))
    checks.choice(promote, "promote", PROMOTIONS)
    seed = checks.integer(seed, "seed", 0, 2 ** 63 - 1)
    special, dedup = checks.boolean(special, "special"), checks.boolean(dedup, "dedup")
    source = checks.text(source, "source")
    checks.choice(encoder, "encoder", ("paper", "best"), optional=True)
    checks.choice(effort, "effort", tuple(EFFORTS), optional=True)
    jobs = checks.integer(jobs, "jobs", 1)
    if sum(x is not None for x in (level, dynamic, budget)) > 1:
        raise InputError("level, dynamic and budget exclude each other", param=("level", "dynamic", "budget"))
    if budget is not None:
        if isinstance(budget, str):
            from .budget import parse_bytes

            budget = parse_bytes(budget)
        elif isinstance(budget, bool) or not isinstance(budget, int):
            raise InputTypeError(f"budget must be bytes as an int or text such as '1.2MiB', got {budget!r}",
                                 param="budget")
        budget = checks.integer(budget, "budget", 1)
    if level is not None and source != "texture":
        fixed = ("the L of csmL" if isinstance(source, str) and source.strip().lower().startswith("csm")
                 else "log2 N of the square map")
        raise InputError(f"source fixes the level to {fixed}; drop level", param=("source", "level"))
    return OmmSettings(format=format, level=4 if level is None else level, dynamic_scale=dynamic,
                       max_level=max_level, promotion=promote, special=special, dedup=dedup, source=source,
                       encoder=encoder, effort=effort, seed=seed, jobs=jobs, budget=budget)


def omm_input_spec(inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], rules: Any = None,
                   channel: str | int | None = None) -> dict:
    """The input of ``bake_omms`` as omm.json records it (a scene, or a texture and UVs), checked."""
    from .alpha_test import MaterialRules
    from .omm import inputs as omm_inputs
    from .scene.files import SCENE_RULE, is_scene_file  # the scene loader's rule (omaps trace's too)

    inputs = checks.paths(inputs, "inputs")
    if rules is not None and not isinstance(rules, MaterialRules):
        raise InputTypeError(f"rules must be an omaps.MaterialRules, got {type(rules).__name__}", param="rules")
    if channel is not None and (isinstance(channel, bool) or not isinstance(channel, (str, int))):
        raise InputTypeError(f"channel must be a band name or index, got {type(channel).__name__}", param="channel")
    rules = MaterialRules() if rules is None else rules
    if len(inputs) == 1 and is_scene_file(inputs[0]):
        if channel is not None:
            raise InputError("channel applies to a texture input, not to a scene", param="channel")
        return omm_inputs.scene_spec(inputs[0], rules)
    if len(inputs) == 2:
        return omm_inputs.texture_spec(inputs[0], inputs[1], rules.cutoff, rules.filter, rules.wrap, channel)
    if len(inputs) == 1:
        raise InputError(f"a texture needs a .npy array of UV triangles (T, 3, 2) after it; {SCENE_RULE}", inputs[0])
    raise InputError(f"inputs must be [scene (.gltf, .glb, .usd, .usda, .usdc, .usdz)] or [texture, uvs.npy], got "
                     f"{len(inputs)} paths",
                     param="inputs")


def bake_omms(inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
              output: str | os.PathLike[str] | None = None, *, level: int | None = None,
              dynamic: float | None = None, max_level: int = 8, budget: int | str | None = None,
              weights: str = "area", size: int | tuple[int, int] | str = (512, 512), format: str = "4state",
              promote: str = "nearest", seed: int = 0, special: bool = True, dedup: bool = True,
              source: str = "texture", encoder: str | None = None, effort: str | None = None, jobs: int = 1,
              threads: int | None = None, rules: Any = None, channel: str | int | None = None,
              progress: Any = None, root: str | os.PathLike[str] | None = None, allow_outside: bool = False,
              build_stage: Callable[..., Any] | None = None) -> OmmBake:
    """Bake standard opacity micromaps (VK_EXT_opacity_micromap / DXR 1.2) and write them.

    Parameters
    ----------
    inputs : str or os.PathLike, or a list of them
        ``SCENE.gltf|.glb|.usd|.usda|.usdc|.usdz`` (every alpha-tested primitive), or ``[TEXTURE, UVS.npy]`` (UV
        triangles, shape (T, 3, 2)).
    output : str or os.PathLike, optional
        A folder (omm_data.bin, omm_triangles.bin, omm_index.bin, omm_usage.json, omm.json;
        replaced whole if empty or an earlier omm folder), or for a glTF scene a .glb / .gltf file with
        the EXT_mesh_opacity_micromap extension. Checked before any work, written all or nothing.
        None: nothing is written.
    level, dynamic, budget : optional
        One subdivision level (0..12, default 4); or per triangle the smallest level whose
        micro-triangles cover at most ``dynamic``\\ :sup:`2` texels; or per triangle the level and
        format that save the most expected any-hit calls per byte within ``budget`` bytes (an int
        or text such as "1.2MiB"). At most one of them.
    max_level : int
        Cap of ``dynamic`` and ``budget``.
    weights : {"area", "view"}
        The budget's weights: world area times instances, or where the candidate hits of a trace
        of the scene's default camera (for an image of ``size``) fall.
    size : int, (int, int) or str
        ``weights="view"``: the image size W, (W, H) or "WxH", sides 1..8192.
    format : {"4state", "2state"}
    promote : {"nearest", "opaque", "transparent", "hashed"}
        What unknown regions become (in 4state: unknown-opaque or unknown-transparent).
    seed : int
        Seed of the hashed promotion.
    special, dedup : bool
        Special indices for uniform triangles; sharing of identical micromaps.
    source : str
        ``texture``, or a square scheme (``sqN``, a codec) whose pair maps are stored, decoded and
        expanded.
    encoder, effort : str, optional
        The source codec's choices.
    jobs : int
        Worker processes encoding the source codec's maps.
    threads : int, optional
        Baking threads (default: numba's, all cores); the output does not depend on it.
    rules : omaps.MaterialRules, optional
        Alpha-test rules (a texture input uses its cutoff, filter and wrap).
    channel : str, optional
        A texture input's coverage channel.
    progress : bool or Progress, optional
        True: progress bars on stderr; or an object with ``stage`` and ``advance``.
    root : str, optional
        A scene's URI policy (``omaps.load_scene``): the folder the files it names must lie under
        (default: its own folder).
    allow_outside : bool
        Read the files a scene names wherever they are (a scene you trust).

    Returns
    -------
    OmmBake

    build_stage : callable, optional
        What bakes and packs the loaded geometries: ``(geometries, settings[, progress]) ->
        OmmResult``, by default ``omaps.omm.build``; ``omaps batch omm --split`` passes
        ``omaps.omm.split.build_split`` with its worker pool.

    Raises
    ------
    InputTypeError
        An argument of the wrong type (its message names the parameter).
    InputError
        For bad inputs or values (naming the file or the parameter); nothing is written then.
    """
    from .atomic import Outputs
    from .omm import files, gltf_io
    from . import omm_format
    from .omm import inputs as omm_inputs
    from .omm.pipeline import build

    inputs = checks.paths(inputs, "inputs")
    if output is not None:
        output = checks.path(output, "output")
    checks.choice(weights, "weights", ("area", "view"))
    w, h = checks.size(size, "size")
    check_count(threads, "threads")
    if root is not None:
        root = checks.path(root, "root")
    allow_outside = checks.boolean(allow_outside, "allow_outside")
    if not (progress is None or isinstance(progress, bool) or hasattr(progress, "stage")):
        raise InputTypeError(f"progress must be True, False or an object with stage and advance, got "
                             f"{type(progress).__name__}", param="progress")
    if build_stage is not None and not callable(build_stage):
        raise InputTypeError(f"build_stage must be callable, got {type(build_stage).__name__}", param="build_stage")
    settings = omm_settings(level=level, dynamic=dynamic, max_level=max_level, budget=budget, format=format,
                            promote=promote, seed=seed, special=special, dedup=dedup, source=source,
                            encoder=encoder, effort=effort, jobs=jobs)
    spec = omm_input_spec(inputs, rules, channel)
    outputs = Outputs(inputs=inputs)
    to_gltf = output is not None and gltf_io.is_gltf(output)
    if to_gltf:
        if spec["kind"] != "scene":
            raise InputError("a .glb / .gltf output needs a glTF input (a texture and UVs have no scene)", output)
        from .scene.files import is_usd_file

        if is_usd_file(spec["path"]):
            raise InputError("a .glb / .gltf output needs a glTF input: the micromaps of a USD stage are written as "
                             "an OMM folder (give output a folder)", param="output")
        outputs.file(output, "-o")
    else:
        outputs.folder(output, "-o", omm_format.SUMMARY_FILE, (".glb", ".gltf"))  # before the work, not after
    t0 = time.perf_counter()
    view, view_info = None, None
    if weights == "view":  # where the view's hits fall: the same counting trace as trace's budget
        if settings.budget is None or spec["kind"] != "scene":
            raise InputError("weights 'view' needs a budget and a glTF scene", param=("weights", "budget"))
        from .alpha_test import MaterialRules
        from .scene import load_scene
        from .trace.view import scene_view_samples

        vw, hits, cam = scene_view_samples(load_scene(spec["path"], root=root, allow_outside=allow_outside), rules or MaterialRules(), w, h)
        view, view_info = (vw, hits), {"weights": "view", "size": [w, h], "camera": cam, "hits": int(len(hits))}
    geoms, skipped, warned = omm_inputs.load_geometries(spec, view, root=root, allow_outside=allow_outside)
    bar = TqdmProgress() if progress is True else (progress or None)
    with _numba_threads(threads):
        try:
            stage = build if build_stage is None else build_stage
            result = stage(geoms, settings, bar) if bar is not None else stage(geoms, settings)
        finally:
            if isinstance(bar, TqdmProgress):
                bar.close()
    bake = OmmBake(result, settings, spec, None if output is None else os.fspath(output), skipped, [],
                   time.perf_counter() - t0)
    if "budget" in result.summary:
        result.summary["budget"].update(view_info or {"weights": "area"})
    extra = {"input": spec, "skipped_primitives": skipped, "warnings": warned}
    if output is not None:
        with outputs.writing():
            if to_gltf:
                bake.warnings = list(gltf_io.write_gltf_result(spec["path"], outputs.path(output), output, result,
                                                               extra, root=root, allow_outside=allow_outside))
            else:
                files.write_into(outputs.path(output), result, extra)
    return bake


@dataclass
class OmmCheck:
    """What ``verify_omms`` checked: the micromaps read, the problems found (none: valid) and
    the checks done."""

    result: object
    problems: list
    done: list

    @property
    def ok(self) -> bool:
        return not self.problems


def verify_omms(path: str | os.PathLike[str], *, root: str | os.PathLike[str] | None = None,
                allow_outside: bool = False) -> OmmCheck:
    """Check an OMM folder or a baked glTF file: layout (the extension's rules), usage counts,
    pair blocks, and a re-bake from its recorded inputs (a glTF file: its own textures).
    ``root``, ``allow_outside``: the URI policy of the scenes read (``omaps.load_scene``).

    Raises
    ------
    InputTypeError, InputError
        A wrong argument (naming the parameter), or a file that cannot be read (naming it).
    """
    from .omm.verify import verify

    path = checks.path(path, "path")
    root = None if root is None else checks.path(root, "root")
    allow_outside = checks.boolean(allow_outside, "allow_outside")

    return OmmCheck(*verify(path, root=root, allow_outside=allow_outside))


def expand_omms(baked: str | os.PathLike[str], output: str | os.PathLike[str], *,
                root: str | os.PathLike[str] | None = None, allow_outside: bool = False) -> OmmBake:
    """A baked .glb / .gltf holding the deck's pair blocks (OMAPS_pair_opacity_maps) or merged
    micromaps (OMAPS_merged_micromaps, ``omm --from csmL``), decoded and expanded into standard
    micromaps (EXT_mesh_opacity_micromap only), written to
    ``output`` (.glb / .gltf). ``root``, ``allow_outside``: the URI policy (``omaps.load_scene``).

    Raises
    ------
    InputTypeError, InputError
        A wrong argument (naming the parameter), or a file that cannot be read (naming it).
    """
    from .atomic import Outputs
    from .omm import gltf_io
    from .omm.expand import expand_result

    baked, output = checks.path(baked, "baked"), checks.path(output, "output")
    root = None if root is None else checks.path(root, "root")
    allow_outside = checks.boolean(allow_outside, "allow_outside")
    for name, value in (("baked", baked), ("output", output)):
        if not gltf_io.is_gltf(value):
            raise InputError(f"{name} must be a .glb or .gltf file, got {value!r}", param=name)
    outputs = Outputs(inputs=[baked])
    outputs.file(output, "-o")
    t0 = time.perf_counter()
    res = gltf_io.read_gltf(baked, root=root, allow_outside=allow_outside)
    if res.pair_blocks is None and res.merged_micromaps is None:
        raise InputError("holds no OMAPS_pair_opacity_maps pair blocks or OMAPS_merged_micromaps to expand", baked)
    out = expand_result(res, root=root, allow_outside=allow_outside)
    bake = OmmBake(out, None, {"kind": "scene", "path": os.path.abspath(baked)}, os.fspath(output),
                   seconds=time.perf_counter() - t0)
    with outputs.writing():
        bake.warnings = list(gltf_io.write_gltf_result(baked, outputs.path(output), output, out, None, root=root, allow_outside=allow_outside))
    bake.source_blocks = dict(res.summary.get("pair_blocks") or res.summary["merged_micromaps"])
    return bake
