"""Output files and folders, the same way in every command: each path checked before the work,
each output written whole or not at all, with the permissions the umask gives (0644 files and
0755 folders under umask 022).

The overwrite rule (README, "Outputs"):

* an existing output **file** is replaced, atomically: the new one is written beside it under a
  hidden temporary name (``.omaps-…``) and renamed over it. It must be a regular file (a link is
  followed), writable, and not one of the command's inputs;
* an existing output **folder** is replaced whole (the old one removed, nothing merged) only when
  it is empty or holds the manifest that the same kind of output writes (``omm.json`` for
  ``omaps omm``, ``show.json`` for ``omaps eval --show``): a folder omaps did not write is never
  deleted.

Names: an output file ends in the suffix of its format where it has one (``-o`` of ``omaps bake``
``.npy``, ``--json`` ``.json``, ``--csv`` ``.csv``, pictures ``.png``), a file of raw bytes
(``omaps encode -o``) in none of a file format, and an output folder's name in no file format's
suffix (``FILE_SUFFIXES``: ``x.txt`` or ``x.png`` is a file's name, never a folder's).

``Outputs`` gathers a command's outputs: ``file`` / ``folder`` check a path when the option is
read (before any work: an error is ``InputError`` naming the path, exit 2, nothing written);
``writing()`` stages every output under a temporary name and renames them all into place when
the whole command has succeeded, or removes them all (an error, Ctrl-C).
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import signal
import threading

from . import interrupt
from .errors import InputError

TEMP_PREFIX = ".omaps-"

# suffixes of file formats: an output folder's name never ends in one (``x.txt`` is no folder
# name), and an output of raw bytes (``omaps encode -o``) is not named as another format
FILE_SUFFIXES = frozenset({
    ".txt", ".log", ".md", ".json", ".csv", ".tsv", ".xml", ".html", ".yaml", ".yml", ".toml",
    ".npy", ".npz", ".png", ".jpg", ".jpeg", ".gif", ".bmp", ".tga", ".tif", ".tiff", ".webp", ".exr",
    ".hdr", ".dds", ".ktx", ".ktx2", ".svg", ".pdf", ".ps", ".eps", ".glb", ".gltf", ".obj", ".zip",
    ".gz", ".tar", ".xz", ".bz2", ".7z", ".py"})
# the suffix of a file option that writes one format in every command
OPTION_SUFFIXES = {"--json": (".json",), "--csv": (".csv",)}


def _temp_name(folder: str, suffix: str = "") -> str:
    return os.path.join(folder, f"{TEMP_PREFIX}{os.urandom(6).hex()}{suffix}")


def make_temp_file(folder, suffix: str = "") -> str:
    """Create an empty hidden file in ``folder`` (mode 0666 less the umask) and return its path."""
    folder = os.fspath(folder)
    for _ in range(100):
        path = _temp_name(folder, suffix)
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return path
    raise FileExistsError(errno.EEXIST, "no free temporary name", folder)


def make_temp_folder(folder) -> str:
    """Create an empty hidden folder in ``folder`` (mode 0777 less the umask) and return its path."""
    folder = os.fspath(folder)
    for _ in range(100):
        path = _temp_name(folder)
        try:
            os.mkdir(path, 0o777)
        except FileExistsError:
            continue
        return path
    raise FileExistsError(errno.EEXIST, "no free temporary name", folder)


def _remove(path) -> None:
    with contextlib.suppress(OSError):
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            os.unlink(path)


def _named(exc: OSError, tmp: str, path: str) -> OSError:
    """An OSError about a temporary name, re-addressed to the output it stands for."""
    if exc.filename is not None and os.fspath(exc.filename).startswith(tmp):
        return OSError(exc.errno, exc.strerror, path)
    return exc


# ---------------------------------------------------------------------------------------------
# checks (before any work)

def _check_parent(path: str, shown) -> None:
    """The nearest existing ancestor of ``path`` is a folder we can create files in (tried: a
    hidden file is made and removed, so read-only mounts and permissions are both caught)."""
    folder = os.path.dirname(path)
    while not os.path.lexists(folder):
        up = os.path.dirname(folder)
        if up == folder:
            break
        folder = up
    if not os.path.isdir(folder):
        raise InputError(f"{folder} is not a folder", shown)
    try:
        _remove(make_temp_file(folder))
    except OSError as exc:
        raise InputError(f"cannot create files in {folder} ({exc.strerror or exc})", shown) from None


def _target(path) -> str:
    """The absolute path an output is written to: a link to a file is followed."""
    if path is None or os.fspath(path) == "":
        raise InputError("an output path is empty")
    p = os.path.abspath(os.fspath(path))
    if os.path.islink(p) and os.path.isfile(p):
        p = os.path.realpath(p)
    return p


def _suffix(p: str) -> str:
    return os.path.splitext(os.path.basename(os.path.normpath(p)))[1].lower()


def check_file(path, option: str | None = None, suffixes=None, inputs=(), raw: bool = False) -> str:
    """The absolute path of an output file, when it may be written (see the module's rule).
    ``suffixes``: the name must end in one of them (by default the option's own format:
    ``OPTION_SUFFIXES``); ``raw``: a file of raw bytes, whose name must not end in the suffix
    of a file format (``FILE_SUFFIXES``)."""
    p = _target(path)
    shown = os.fspath(path)
    what = option or "this output"
    if os.path.isdir(p):
        raise InputError(f"is a folder; {what} is a file", shown)
    if os.path.lexists(p):
        if not os.path.isfile(p):
            raise InputError(f"exists and is not a regular file; {what} is a file", shown)
        if not os.access(p, os.W_OK):
            raise InputError("exists and is read-only: not replacing it", shown)
        for i in inputs:
            with contextlib.suppress(OSError):
                if os.path.samefile(p, i):
                    raise InputError(f"is also an input of this command; {option or 'the output'} would replace it",
                                     shown)
    if suffixes is None:
        suffixes = OPTION_SUFFIXES.get(option)
    ext = _suffix(shown)
    if suffixes and ext not in suffixes:
        raise InputError(f"{what} must end in {', '.join(suffixes)}" + (f", not {ext}" if ext else ""), shown)
    if raw and ext in FILE_SUFFIXES:
        raise InputError(f"{what} writes raw bytes, not a {ext} file: use another suffix (such as .bin)", shown)
    _check_parent(p, shown)
    return p


def check_folder(path, manifest: str, option: str | None = None, inputs=(), files=()) -> str:
    """The absolute path of an output folder, when it may be written: absent, empty, or holding
    ``manifest`` (an earlier output of the same kind); see the module's rule. Its name does not
    end in the suffix of a file format (``files``: the suffixes for which the option writes a
    file instead, named in the error)."""
    shown = os.fspath(path)
    p = os.path.abspath(shown)
    ext = _suffix(shown)
    if ext in FILE_SUFFIXES:
        what = option or "this output"
        if files:
            raise InputError(f"{what} must end in {', '.join(files)} (a file) or in no file suffix (a folder), "
                             f"not {ext}", shown)
        raise InputError(f"{what} is a folder, and a folder's name does not end in a file suffix such as {ext}", shown)
    if os.path.islink(p) and os.path.isdir(p):
        p = os.path.realpath(p)
    if os.path.lexists(p):
        if not os.path.isdir(p):
            raise InputError(f"exists and is not a folder; {option or 'this output'} is a folder", shown)
        try:
            entries = os.listdir(p)
        except OSError as exc:
            raise InputError(f"cannot read the folder ({exc.strerror or exc})", shown) from None
        if entries and manifest not in entries:
            raise InputError(f"folder is not empty and holds no {manifest} (not written by omaps): "
                             "not replacing it", shown)
        for i in inputs:
            ai = os.path.abspath(os.fspath(i))
            if ai == p or ai.startswith(p + os.sep):
                raise InputError(f"holds an input of this command; {option or 'the output'} would replace it", shown)
    _check_parent(p, shown)
    return p


# ---------------------------------------------------------------------------------------------
# writing

def replace_folder(tmp: str, folder: str) -> None:
    """Move a finished temporary folder to ``folder``; an existing one is swapped out first and
    removed only after that."""
    if os.path.lexists(folder):
        old = make_temp_folder(os.path.dirname(folder))
        os.rmdir(old)
        os.replace(folder, old)
        try:
            os.replace(tmp, folder)
        except BaseException:
            os.replace(old, folder)
            raise
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, folder)


@contextlib.contextmanager
def atomic_path(path, suffix=None):
    """Yield a temporary path in the target's folder; on success it replaces ``path``."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    suffix = suffix if suffix is not None else os.path.splitext(path)[1]
    tmp = make_temp_file(folder, suffix)
    try:
        yield tmp
        interrupt.check()
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise _named(exc, tmp, path) from None
    except BaseException:
        _remove(tmp)
        raise


@contextlib.contextmanager
def atomic_folder(folder, manifest: str):
    """Yield an empty temporary folder beside ``folder``; on success it replaces ``folder``
    (checked first by ``check_folder``)."""
    folder = check_folder(folder, manifest)
    os.makedirs(os.path.dirname(folder), exist_ok=True)
    tmp = make_temp_folder(os.path.dirname(folder))
    try:
        yield tmp
        interrupt.check()
        replace_folder(tmp, folder)
    except OSError as exc:
        _remove(tmp)
        raise _named(exc, tmp, folder) from None
    except BaseException:
        _remove(tmp)
        raise


def write_text(path, text: str) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)


def write_bytes(path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)


@contextlib.contextmanager
def _sigint_held():
    """Hold Ctrl-C while outputs are renamed into place (a handful of renames), so a command
    either leaves all its outputs or none; the interrupt then counts as coming after the end."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, lambda *_: None)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


class Outputs:
    """A command's output files and folders (see the module's docstring).

    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> out = Outputs()
    >>> out.file(os.path.join(d, "a.json"), "--json")
    >>> with out.writing():
    ...     with open(out.path(os.path.join(d, "a.json")), "w") as f:
    ...         _ = f.write("hi")
    >>> sorted(os.listdir(d))
    ['a.json']
    """

    def __init__(self, inputs=()):
        self.inputs = [os.fspath(i) for i in inputs if i]
        self._targets: dict[str, tuple[str, str, str | None]] = {}  # abs path -> (kind, option, manifest)
        self._given: dict[str, str] = {}  # as given -> abs path
        self._staged: dict[str, str] = {}  # abs path -> temporary path
        self._made: list[str] = []  # folders created for the outputs, removed again on failure

    def _add(self, given, p: str, kind: str, option: str, manifest=None) -> None:
        for q, (k, opt, _) in self._targets.items():
            if q == p:
                raise InputError(f"given to both {opt} and {option}", given)
            inner, outer = (q, p) if k == "folder" else (p, q)
            if (k == "folder" or kind == "folder") and outer.startswith(inner + os.sep):
                raise InputError(f"lies inside the output folder of {opt if k == 'folder' else option}", given)
        self._targets[p] = (kind, option, manifest)
        self._given[os.fspath(given)] = p

    def file(self, path, option: str, suffixes=None, raw: bool = False) -> None:
        """Declare an output file (nothing when ``path`` is None); check it now (``suffixes``,
        ``raw``: see ``check_file``)."""
        if path is None:
            return
        self._add(path, check_file(path, option, suffixes, self.inputs, raw), "file", option)

    def folder(self, path, option: str, manifest: str, files=()) -> None:
        """Declare an output folder replaced whole (nothing when ``path`` is None); check it now
        (``files``: see ``check_folder``)."""
        if path is None:
            return
        self._add(path, check_folder(path, manifest, option, self.inputs, files), "folder", option, manifest)

    def path(self, path) -> str:
        """Where to write the declared output ``path`` now: a temporary file or (empty) folder
        beside it, renamed into place by ``writing()``."""
        p = self._given.get(os.fspath(path), path)
        if p not in self._staged:
            kind, option, _ = self._targets[p]
            parent = os.path.dirname(p)
            missing = []
            d = parent
            while not os.path.lexists(d) and os.path.dirname(d) != d:
                missing.append(d)
                d = os.path.dirname(d)
            os.makedirs(parent, exist_ok=True)
            self._made += missing  # deepest first
            self._staged[p] = (make_temp_folder(parent) if kind == "folder"
                               else make_temp_file(parent, os.path.splitext(p)[1]))
        return self._staged[p]

    def _commit(self) -> None:
        interrupt.check()  # (a Ctrl-C that something swallowed on its way: nothing is written)
        with _sigint_held():
            for p, tmp in list(self._staged.items()):
                try:
                    if self._targets[p][0] == "folder":
                        replace_folder(tmp, p)
                    else:
                        os.replace(tmp, p)
                except OSError as exc:
                    raise _named(exc, tmp, p) from None
                del self._staged[p]

    def _discard(self) -> None:
        for tmp in self._staged.values():
            _remove(tmp)
        self._staged.clear()
        for d in self._made:
            with contextlib.suppress(OSError):
                os.rmdir(d)  # only if still empty
        self._made.clear()

    @contextlib.contextmanager
    def writing(self):
        """Write the outputs inside this block (to ``path(...)``); all are renamed into place at
        its end, or all removed if it fails or is interrupted."""
        try:
            yield self
            self._commit()
        except OSError as exc:
            failed = next(((p, t) for p, t in self._staged.items() if exc.filename is not None
                           and os.fspath(exc.filename).startswith(t)), None)
            self._discard()
            raise (_named(exc, failed[1], failed[0]) if failed else exc) from None
        except BaseException:
            self._discard()
            raise
