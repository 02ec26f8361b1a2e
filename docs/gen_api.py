"""Generate the Python API reference pages (``reference/api/*.md``) for mkdocstrings: one page per
public namespace, one ``:::`` entry per name of its ``__all__``, pointing at the module that
defines it (the packages export their names lazily, which a static reader cannot follow). A
function made at import (a numba kernel assembled from a registry) gets a heading and its signature
from ``inspect``; constants are listed with their values. Run by the mkdocs-gen-files plugin during
``mkdocs build``."""

from __future__ import annotations

import importlib
import inspect

# page name, package, what it is ({codecs}: the registry's codecs)
PACKAGES = [
    ("omaps", "omaps", "The top-level namespace: textures, the alpha test, the bakers, codecs, schemes, "
     "the corpus evaluation and scenes. `import omaps` is cheap: each name is imported on first use."),
    ("bake", "omaps.bake", "The bakers: pair-square maps and per-triangle micromaps (bird-curve order)."),
    ("codecs", "omaps.codecs", "Stored square maps: raw `sqN` and the registry's codecs, {codecs}, through one "
     "interface."),
    ("batch", "omaps.batch", "One command's library call over many inputs on Dask, resumable and fault-tolerant, "
     "behind `omaps batch`."),
    ("corpus", "omaps.corpus", "The corpus evaluation behind `omaps eval`."),
    ("omm", "omaps.omm", "Standard opacity micromaps (VK_EXT_opacity_micromap, DXR 1.2) behind `omaps omm`."),
    ("scene", "omaps.scene", "glTF 2.0 scenes: the model, the reader, alpha-tested triangles and their pairs."),
    ("trace", "omaps.trace", "The Embree ray tracer behind `omaps trace`."),
]


def _target(pkg, name: str) -> str | None:
    """Dotted path of the object ``pkg.name`` where it is defined."""
    obj = getattr(pkg, name)
    obj = getattr(obj, "py_func", obj)  # a numba kernel: its Python function
    if inspect.ismodule(obj):
        return obj.__name__
    mod = getattr(obj, "__module__", None)
    if (inspect.isclass(obj) or inspect.isfunction(obj)) and mod and mod.startswith("omaps"):
        qual = getattr(obj, "__qualname__", name)
        if "<" not in qual:
            return f"{mod}.{qual}"
    return None  # a constant: listed by name only


def _built(pkg, name: str):
    """The Python function of ``pkg.name`` if it is made by a call at import (a numba kernel
    assembled from a registry), which a static reader cannot document; else None."""
    obj = getattr(pkg, name)
    obj = getattr(obj, "py_func", obj)
    if inspect.isfunction(obj) and "<locals>" in obj.__qualname__ and obj.__module__.startswith("omaps"):
        return obj
    return None


def _built_entry(package: str, name: str, func, kernel: bool, modules: set[str]) -> list[str]:
    """A heading and the signature of a function made at import; its module's docstring (shown
    once per page, above the first) describes it."""
    lines = []
    if func.__module__ not in modules:
        modules.add(func.__module__)
        lines += [f"::: {func.__module__}", "    options:", "      members: false",
                  f"      heading: \"{func.__module__}\"", ""]
    lines += [f"## {package}.{name} {{#{package}.{name}}}", "", "```python", f"{name}{inspect.signature(func)}",
              "```", "", f"{'A numba kernel' if kernel else 'A function'} made when the package is imported: "
              f"see [`{func.__module__}`][{func.__module__}] above.", ""]
    return lines


def _value(value) -> str:
    """A constant as the page shows it: its value when short, else what it holds (a long value or
    one holding functions is no reading, and its addresses change from build to build)."""
    text = repr(value)
    if len(text) <= 100 and " at 0x" not in text:
        return f" = `{text}`"
    kind = type(value).__name__
    if isinstance(value, (tuple, list, set, frozenset, dict)):
        items = list(value.values() if isinstance(value, dict) else value)
        kinds = {type(v).__name__ for v in items}
        what = f" `{kinds.pop()}`" if len(kinds) == 1 else ""
        return f": a `{kind}` of {len(items)}{what} {'entries' if isinstance(value, dict) else 'items'}"
    return f": a `{kind}`"


def render(page: str, package: str, intro: str, done: dict[str, str]) -> str:
    """The page of ``package``; ``done`` maps the targets documented on earlier pages to their
    public names there (an object is documented once, and linked from the other pages)."""
    pkg = importlib.import_module(package)
    lines = [f"# `{package}`", "", intro, "",
             "Generated from the docstrings (`docs/gen_api.py`, mkdocstrings).", ""]
    consts, elsewhere, modules = [], [], set()
    for name in pkg.__all__:
        target = _target(pkg, name)
        built = _built(pkg, name) if target is None else None
        if built is not None:
            lines += _built_entry(package, name, built, hasattr(getattr(pkg, name), "py_func"), modules)
            continue
        if target is None:
            consts.append(name)
            continue
        if target in done:
            elsewhere.append(f"- `{package}.{name}`: see [`{done[target]}`][{target}]")
            continue
        done[target] = f"{package}.{name}"
        lines += [f"::: {target}", "    options:", f"      heading: \"{package}.{name}\"", ""]
    if elsewhere:
        lines += ["## Also exported here", ""] + elsewhere + [""]
    if consts:
        lines += ["## Constants", ""]
        for name in consts:
            lines.append(f"- `{package}.{name}`{_value(getattr(pkg, name))}")
        lines.append("")
    return "\n".join(lines)


def pages():
    from omaps.codecs import codec_list, codec_names

    codecs = codec_list("and", [f"`{n}`" for n in codec_names()])  # (plug-ins' included)
    done: dict[str, str] = {}
    for page, package, intro in PACKAGES:
        yield f"reference/api/{page}.md", render(page, package, intro.replace("{codecs}", codecs), done)


try:
    import mkdocs_gen_files
except ImportError:
    mkdocs_gen_files = None

if mkdocs_gen_files is not None and __name__ != "__main__":
    for path, text in pages():
        with mkdocs_gen_files.open(path, "w") as f:
            f.write(text)
        mkdocs_gen_files.set_edit_path(path, "gen_api.py")

if __name__ == "__main__":
    for path, text in pages():
        print(f"--- {path}\n{text}")
