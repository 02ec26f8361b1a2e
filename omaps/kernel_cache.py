"""numba's on-disk cache, keyed on everything a kernel can inline, not on its own file alone.

numba keys a cached kernel on its own source file (modification time and size): a kernel that
inlines a function of another module (the tracer's filters inline every codec's lookup, the codec
registry's format codes are compile-time constants) is loaded from the cache unchanged after that
other module changed, and computes with the old code -- wrong figures without an error, or, with
swapped format codes, maps read through the wrong codec.

Here a kernel of a file under a watched package (omaps itself; ``watch`` adds another) is keyed on the *content* of its file and of every module it imports,
transitively: module-level and function-level imports (a package's ``__init__``: module-level ones,
those its import runs); for a name a package exports lazily (``omaps.lazy``: its ``__getattr__``
imports the module on first use), every module of the package that mentions the name; and, in a
module that calls ``importlib.import_module``, a module named by a string (``"vq2_block"``,
``"omaps.codecs.vq2_block"``). The key over-covers: an edit may recompile a kernel that did not
need it, never the reverse. Changing, adding or removing a codec then recompiles, in a fresh
process, the kernels whose imports reach it and no other; the compile-ahead check
(``omaps.cli.precompile``) reads the same key through numba's own index.

Codec plug-ins (``omaps.plugins``) are code the registry runs at start-up: a kernel whose imports
reach the registry (the tracer's dispatch inlines every codec's lookup, the format codes are the
registry's) is also keyed on every installed plug-in: its entry point and the content of its
package and of what that imports (each plug-in package is watched). Such a kernel is cached under
a name of its own while plug-ins are installed, so the kernels of omaps with and without them do
not evict each other.

``install()`` puts the key in place; ``omaps/__init__`` calls it when numba's caching module is
imported (or at once, when it already is), before any omaps kernel is declared.

Example::

    >>> from omaps import kernel_cache
    >>> key = kernel_cache.source_key(kernel_cache.__file__)
    >>> len(key), key == kernel_cache.source_key(kernel_cache.__file__)
    (64, True)
"""

from __future__ import annotations

import os
import re
import sys
from functools import lru_cache

__all__ = ["install", "watch", "source_key", "dependencies"]

_ROOTS: dict[str, str] = {}  # top-level package name -> its folder (absolute, real path)
_SELF = os.path.realpath(__file__)  # imported by omaps/__init__, compiled into no kernel: in no key
_IMPORT = (r"^[ \t]*(?:from[ \t]+(\.*[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#;]*)"
                     r"|import[ \t]+([\w.]+(?:[ \t]+as[ \t]+\w+)?(?:[ \t]*,[ \t]*[\w.]+(?:[ \t]+as[ \t]+\w+)?)*))")


def watch(package_dir: str, name: str | None = None) -> None:
    """Key the kernels of the package in ``package_dir`` (a folder with ``__init__.py``) on their
    imports' content too. ``name``: the package's import name (default: the folder's name)."""
    path = os.path.realpath(package_dir)
    name = name or os.path.basename(path)
    if _ROOTS.get(name) == path:
        return
    _ROOTS[name] = path
    for cached in (source_key, _direct, _file_of, _package_words, plugins_key):
        cached.cache_clear()


def _module_file(top: str, parts: list[str]) -> str | None:
    """The file of module ``top.parts...`` under a watched package, or None."""
    return _file_of(top, tuple(parts))


@lru_cache(maxsize=None)
def _file_of(top: str, parts: tuple[str, ...]) -> str | None:
    base = os.path.join(_ROOTS[top], *parts)
    for cand in (os.path.join(base, "__init__.py"), base + ".py"):
        if os.path.isfile(cand):
            return cand
    return None


def _canonical(path: str) -> str:
    """``path`` as the modules found from a watched package's folder name it."""
    real = os.path.realpath(path)
    where = _package_of(real)
    return real if where is None else (_module_file(where[0], where[1]) or real)


def _package_of(path: str) -> tuple[str, list[str]] | None:
    """(top-level package, module parts) of a file under a watched package (a real path)."""
    for top, root in _ROOTS.items():
        if path.startswith(root + os.sep):
            rel = os.path.relpath(path, root)[:-3].split(os.sep)
            return top, rel[:-1] if rel[-1] == "__init__" else rel
    return None


@lru_cache(maxsize=None)
def _read(path: str) -> bytes:
    with open(path, "rb") as f:
        return f.read()


@lru_cache(maxsize=None)
def _direct(path: str) -> tuple[str, ...]:
    """The files of watched packages that ``path`` imports directly (any import statement)."""
    where = _package_of(path)
    if where is None:
        return ()
    top, parts = where
    is_pkg = path.endswith("__init__.py")
    here = parts if is_pkg else parts[:-1]  # the package a relative import starts from
    text = _read(path).decode("utf-8", "replace")
    found: list[str] = []

    def add(mod_parts: list[str], names: list[str], root: str = top) -> None:
        for i in range(len(mod_parts) + 1):  # each package on the way runs its __init__
            f = _module_file(root, mod_parts[:i])
            if f:
                found.append(f)
        init = _module_file(root, mod_parts)
        for n in names:
            f = _module_file(root, mod_parts + [n])  # `from pkg import submodule`
            if f:
                found.append(f)
            elif init and init.endswith("__init__.py") and _lazy(init):
                found.extend(_mentioning(os.path.dirname(init), n))

    for m in re.finditer(_IMPORT, text, re.M):
        if is_pkg and text[m.start()] in " \t":
            continue  # a package's __init__ runs its module-level imports only on import
        frm, names, plain = m.group(1), m.group(2), m.group(3)
        if plain is not None:
            for item in plain.split(","):
                dotted = item.split()[0].split(".")
                if dotted[0] in _ROOTS:  # this package or another watched one (a plug-in's omaps imports)
                    add(dotted[1:], [], dotted[0])
            continue
        listed = [n.split()[0] for n in names.strip().strip("()").split(",") if n.split()]
        root = top
        if frm.startswith("."):
            level = len(frm) - len(frm.lstrip("."))
            mod = here[:len(here) - level + 1] + [p for p in frm.lstrip(".").split(".") if p]
        else:
            dotted = frm.split(".")
            if dotted[0] not in _ROOTS:
                continue
            root, mod = dotted[0], dotted[1:]
        add(mod, listed, root)
    # modules imported by name at run time, in a module that calls ``importlib.import_module``: a
    # string naming a module of this package (``"vq2_block"``) or a dotted path
    # (``"omaps.codecs.vq2_block"``); not in a lazily exporting package's ``__init__``, whose
    # names' modules its importers resolve
    strings = (set(re.findall(r"[\"']([A-Za-z_][\w.]*)[\"']", text))
               if "import_module" in text and not (is_pkg and _lazy(path)) else ())
    for word in sorted(strings):
        dotted = word.split(".")
        f = _module_file(top, dotted[1:]) if dotted[0] == top and len(dotted) > 1 else (
            _module_file(top, here + dotted) if len(dotted) == 1 else None)
        if f:
            found.append(f)
    return tuple(f for f in dict.fromkeys(found) if f != path and f != _SELF)


@lru_cache(maxsize=None)
def _lazy(init: str) -> bool:
    """Whether a package's ``__init__`` exports names on first use (a module ``__getattr__``)."""
    return re.search(rb"^def __getattr__|^__getattr__\s*[,=]", _read(init), re.M) is not None


def _mentioning(folder: str, name: str) -> list[str]:
    """The modules of a lazily exporting package that mention ``name``: one of them defines it
    or imports it (a superset of the module the package's ``__getattr__`` takes it from)."""
    return [f for f, words in _package_words(folder) if name in words]


@lru_cache(maxsize=None)
def _package_words(folder: str) -> list[tuple[str, frozenset[str]]]:
    """Each module of a package folder (its own modules and subpackages) with the words it holds."""
    out = []
    for entry in sorted(os.listdir(folder)):
        cand = os.path.join(folder, entry)
        if not (entry.endswith(".py") and entry != "__init__.py"):
            cand = os.path.join(cand, "__init__.py")
            if not os.path.isfile(cand):
                continue
        out.append((cand, frozenset(re.findall(r"\w+", _read(cand).decode("utf-8", "replace")))))
    return out


def dependencies(path: str) -> list[str]:
    """Every file of a watched package that ``path`` reaches through imports, itself first."""
    path = _canonical(path)
    seen = {path: None}
    todo = [path]
    while todo:
        for dep in _direct(todo.pop()):
            if dep not in seen:
                seen[dep] = None
                todo.append(dep)
    return list(seen)


@lru_cache(maxsize=None)
def source_key(path: str) -> str:
    """SHA-256 over the content of ``path`` and of every watched module it reaches (sorted by
    their path relative to their package, so a moved checkout keeps its cache)."""
    import hashlib  # (here: OpenSSL's load is not part of ``import omaps``)

    path = _canonical(path)
    h = hashlib.sha256()
    deps = dependencies(path)
    named = []
    for f in deps:
        where = _package_of(f)
        named.append(("/".join([where[0], *where[1]]) if where else f, f))
    for name, f in sorted(named):
        h.update(name.encode() + b"\0" + hashlib.sha256(_read(f)).digest())
    if _reaches_registry(deps):
        h.update(b"plugins\0" + plugins_key().encode())
    return h.hexdigest()


def _reaches_registry(deps) -> bool:
    """Whether a kernel's files include the codec registry (it then depends on the plug-ins)."""
    registry = _module_file("omaps", ["codecs", "registry"]) if "omaps" in _ROOTS else None
    return registry is not None and registry in deps


@lru_cache(maxsize=None)
def plugins_key() -> str:
    """SHA-256 over the installed codec plug-ins: each entry point (in the registry's order) and
    the content of every file of its package and of the watched modules those import; "" when
    none is installed (or plug-ins are off)."""
    import hashlib

    from .plugins import codec_entry_points, describe, package_folder

    eps = codec_entry_points()
    if not eps:
        return ""
    h = hashlib.sha256()
    for ep in eps:
        h.update(describe(ep).encode() + b"\0")
        pkg = package_folder(ep)
        if pkg is None:
            continue  # (the registry refuses it)
        watch(pkg[1], pkg[0])
        files = []
        for folder, dirs, names in os.walk(pkg[1]):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            files += [os.path.join(folder, n) for n in sorted(names) if n.endswith(".py")]
        for f in sorted({d for f in files for d in dependencies(f)}):
            where = _package_of(f)
            name = "/".join([where[0], *where[1]]) if where else f
            h.update(name.encode() + b"\0" + hashlib.sha256(_read(f)).digest())
    return h.hexdigest()


def _keyed(cls):
    """``cls`` (one of numba's locators) keyed on ``source_key`` for the files of watched packages."""

    class Keyed(cls):
        @classmethod
        def from_function(klass, py_func, py_file):
            if _package_of(os.path.realpath(py_file)) is None:
                return None  # numba's own locator, as usual
            return super().from_function(py_func, py_file)

        def get_source_stamp(self):
            return ("omaps-imports", source_key(self._py_file))

        def get_disambiguator(self):
            # with plug-ins installed, a kernel that depends on them is cached under a name of its own
            base = super().get_disambiguator()
            if not _reaches_registry(dependencies(self._py_file)):
                return base
            plugins = plugins_key()
            return f"{base}-plugins-{plugins[:12]}" if plugins else base

    Keyed.__name__ = Keyed.__qualname__ = "Imports" + cls.__name__
    return Keyed


def install() -> None:
    """Put the import-keyed locators first in numba's list (once; idempotent)."""
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")
    if any(getattr(c, "_omaps_keyed", False) for c in impl._locator_classes):
        return
    keyed = []
    for cls in impl._locator_classes:
        if issubclass(cls, caching._SourceFileBackedLocatorMixin):
            k = _keyed(cls)
            k._omaps_keyed = True
            keyed.append(k)
    impl._locator_classes = keyed + list(impl._locator_classes)


class _Watcher:
    """A meta path finder that runs ``install`` right after numba's caching module is first
    imported (a plain class: ``importlib.abc`` would cost ``import omaps`` 17 ms)."""

    def find_spec(self, name, path=None, target=None):
        if name != "numba.core.caching":
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                break
        else:
            return None
        sys.meta_path[:] = [f for f in sys.meta_path if f is not self]
        loader = spec.loader
        run = loader.exec_module

        def exec_module(module):
            run(module)
            install()

        loader.exec_module = exec_module  # this loader instance serves this one module
        return spec


def watch_numba() -> None:
    """``install`` now if numba's caching module is loaded, else as soon as it is."""
    if "numba.core.caching" in sys.modules:
        install()
    elif not any(isinstance(f, _Watcher) for f in sys.meta_path):
        sys.meta_path.insert(0, _Watcher())
