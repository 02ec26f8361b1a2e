"""One call evaluates a corpus: ``evaluate_corpus`` returns a ``CorpusResult`` with each
texture's savings per scheme, the means ``omaps eval`` prints, and methods that write its JSON,
CSV, chart and per-texture panels."""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Union

from .. import checks
from ..errors import InputError, InputTypeError, check_count
from ..schemes import DEFAULT_SCHEMES, EVAL_KINDS, parse_schemes
from ..text import format_table, plural
from .evaluate import EvalConfig, evaluate_many, mean_results

if TYPE_CHECKING:
    import numpy as np

    from ..schemes import Scheme
    from ..texture import AlphaTexture

    PathOrArray = Union[str, os.PathLike[str], np.ndarray, AlphaTexture]
    PathsOrArrays = Union[PathOrArray, Sequence[PathOrArray]]

__all__ = ["evaluate_corpus", "CorpusResult", "PER_TEXTURE_ROWS"]

PER_TEXTURE_ROWS = 20  # per-texture rows printed by default when there are at most this many textures


def _inputs(paths: object) -> list[Any]:
    """``evaluate_corpus``' inputs as a list: paths (str), and arrays as ``AlphaTexture`` objects
    named ``array N`` by their place in the list (the texture's channel is read later)."""
    import numpy as np

    from ..texture import AlphaTexture

    single = isinstance(paths, (str, os.PathLike, np.ndarray, AlphaTexture))
    if not single and not isinstance(paths, (list, tuple)):
        raise InputTypeError(f"paths must be a path, an array or an AlphaTexture, or a list of them, got "
                             f"{type(paths).__name__}", param="paths")
    out: list[Any] = []
    for i, p in enumerate([paths] if single else list(paths)):  # type: ignore[call-overload]
        name = "paths" if single else f"paths[{i}]"
        if isinstance(p, AlphaTexture):
            out.append(p)
        elif isinstance(p, np.ndarray):
            out.append(("array" if single else f"array {i}", p))
        else:
            out.append(checks.path(p, name))
    return out


@dataclass
class CorpusResult:
    """What ``evaluate_corpus`` measured.

    Attributes
    ----------
    results : list of TextureResult
        Per texture (in input order): its name, size, savings and bits per scheme.
    names : list of str
        The schemes, in order.
    settings : dict
        The source, the texel-state rules, filter, wrap, channel, codec choices and schemes.
    source : str
        "N files" or "the embedded procedural corpus".
    unreadable : list of (str, str)
        Files found in folders that could not be read, with the problem (left out).
    small : list of str
        Textures left out for being smaller than ``min_size``.
    skipped_other : list of str
        Files in the folders given without an image extension.
    seconds : float
    no_alpha : list of (str, str)
        Images found in the folders given that are not alpha masks (no alpha channel: photographs,
        screenshots, normal maps), with the reason; left out unless ``config.channel`` picks a band.
        An image named itself is read, and is an error when it has no alpha.
    """

    results: list
    names: list
    settings: dict
    source: str
    unreadable: list = field(default_factory=list)
    small: list = field(default_factory=list)
    skipped_other: list = field(default_factory=list)
    seconds: float = 0.0
    no_alpha: list = field(default_factory=list)

    @property
    def means(self) -> dict:
        """Per scheme the mean savings and the mean bits per pair over the textures."""
        return mean_results(self.results, self.names)

    def table(self, per_texture: bool = False) -> str:
        """The savings table as ``omaps eval`` prints it (each texture's row when ``per_texture``)."""
        means = self.means
        rows = []
        if per_texture:
            rows += [[r.name if len(r.name) <= 40 else "..." + r.name[-37:]] + [f"{r.savings[n]:.3f}" for n in self.names]
                     for r in self.results]
        rows.append([f"MEAN savings ({len(self.results)})"] + [f"{means[n]['savings']:.3f}" for n in self.names])
        rows.append(["mean bits/pair"] + [f"{means[n]['bits']:.0f}" for n in self.names])
        from ..schemes import notes_lines

        return "\n".join([format_table(["texture"] + self.names, rows), *notes_lines(self.settings)])

    def heading(self) -> str:
        """The line ``omaps eval`` prints above the table."""
        s = self.settings
        return (f"omaps eval: {plural(len(self.results), 'texture')} from {self.source}, mode {s['mode']}, "
                f"filter {s['filter']}, wrap {s['wrap']}, {self.seconds:.2f} s")

    def write_json(self, path) -> None:
        """Settings, per-texture and mean results, and unreadable files as JSON."""
        from .report import write_json

        write_json(path, self.results, self.names, self.settings, self.unreadable)

    def write_csv(self, path) -> None:
        """One row per texture and scheme."""
        from .report import write_csv

        write_csv(path, self.results, self.names)

    def plot(self, path) -> None:
        """Mean savings against bits per pair (the suffix picks the format)."""
        from .report import plot_savings

        plot_savings(path, self.results, self.names)

    def write_show(self, folder, progress: bool = False) -> None:
        """One PNG per texture with its maps, and show.json (needs ``keep_maps=True``)."""
        from .report import write_show

        write_show(folder, self.results, self.settings, progress)


def evaluate_corpus(paths: PathsOrArrays | None = None, schemes: str | Sequence[str | Scheme] | None = None, *,
                    config: EvalConfig | None = None, jobs: int | None = None, min_size: int = 0,
                    keep_maps: bool = False, progress: bool = False) -> CorpusResult:
    """Savings (the fraction of hits needing no any-hit shader) of each scheme on each texture
    mapped to the corpus pair.

    Parameters
    ----------
    paths : str, os.PathLike, numpy array or AlphaTexture, or a list of them, optional
        Image files and folders (searched recursively), and textures as arrays (named ``array 0``,
        ``array 1``, ... by their place in the list) or ``AlphaTexture`` objects; None or empty:
        the embedded procedural corpus.
    schemes : str, or list of str or Scheme, optional
        Comma-separated names (``sqN``, ``triL``, ``texel``, a codec); default
        ``omaps.schemes.DEFAULT_SCHEMES``.
    config : EvalConfig, optional
        Texel-state rule, filter, wrap, channel and codec choices.
    jobs : int, optional
        Worker processes (default: all cores).
    min_size : int
        Leave out textures whose smaller side is below this.
    keep_maps : bool
        Keep each texture's maps (for ``CorpusResult.write_show``).
    progress : bool
        A progress bar on stderr.

    Returns
    -------
    CorpusResult

    Raises
    ------
    InputTypeError
        An argument of the wrong type (its message names the parameter).
    InputError
        For bad values (naming the parameter), a file named in ``paths`` that cannot be read, or no
        texture at all (its ``unreadable`` attribute then lists the files that could not be read).

    Examples
    --------
    >>> from omaps.corpus import evaluate_corpus
    >>> res = evaluate_corpus(schemes="sq16,tri3", jobs=1)
    >>> res.source, sorted(res.means), 0 < res.means["sq16"]["savings"] < 1
    ('the embedded procedural corpus', ['sq16', 'tri3'], True)
    """
    from ..texture import find_images, without_alpha
    from .procedural import default_corpus

    if config is not None and not isinstance(config, EvalConfig):
        raise InputTypeError(f"config must be an omaps.EvalConfig, got {type(config).__name__}", param="config")
    config = EvalConfig() if config is None else config
    schemes = parse_schemes(",".join(DEFAULT_SCHEMES) if schemes is None else schemes, EVAL_KINDS,
                            config.encoder, config.effort, "evaluate_corpus", param="schemes")
    names = [s.name for s in schemes]
    min_size = checks.integer(min_size, "min_size", 0)
    jobs = check_count(jobs, "jobs")
    keep_maps, progress = checks.boolean(keep_maps, "keep_maps"), checks.boolean(progress, "progress")
    given = [] if paths is None else _inputs(paths)
    files: list[str] = [p for p in given if isinstance(p, str)]
    skipped_other: list = []
    no_alpha: list = []
    named: set = set()
    if given:
        items: list = []
        for p in given:
            if isinstance(p, str):
                found, other = find_images([p])
                if os.path.isdir(p) and config.channel is None:  # a folder's images that are not alpha masks
                    why = [without_alpha(f) for f in found]
                    no_alpha += [(f, w) for f, w in zip(found, why) if w is not None]
                    found = [f for f, w in zip(found, why) if w is None]
                items += found
                skipped_other += other
            else:
                items.append(p)
        if not items:
            raise InputError("no image files found" if not no_alpha else
                             f"no image with an alpha channel found ({plural(len(no_alpha), 'image')} without "
                             f"one, e.g. {no_alpha[0][0]}: {no_alpha[0][1]})", ", ".join(files))
        named = {p for p in files if not os.path.isdir(p)} | {p[0] for p in given if isinstance(p, tuple)}
        source = plural(len(items), "file" if all(isinstance(it, str) for it in items) else "texture")
    else:
        items = default_corpus()
        source = "the embedded procedural corpus"
    t0 = time.perf_counter()
    unreadable: list = []
    errors: dict = {}
    results, small = evaluate_many(items, schemes, config, jobs, keep_maps=keep_maps, min_size=min_size,
                                   progress=progress, unreadable=unreadable, errors=errors)
    seconds = time.perf_counter() - t0
    for path, problem in unreadable:
        if path in named:  # a file named on the command line is bad input
            raise errors.get(path) or InputError(problem, path)
    if not results:
        exc = (InputError("no texture could be read", ", ".join(files)) if unreadable
               else InputError(f"no texture is at least {min_size} px"))
        exc.unreadable = unreadable  # type: ignore[attr-defined]
        raise exc
    settings = {"source": source, **config.settings(), "min_size": min_size,
                "schemes": {s.name: s.settings() for s in schemes}}
    return CorpusResult(results, names, settings, source, unreadable, small, list(skipped_other), seconds,
                        no_alpha)
