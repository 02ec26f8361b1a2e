"""The documentation site: ``mkdocs build --strict`` passes (no warning: broken links and anchors,
docstrings mkdocstrings cannot read, pages missing from the nav), and the built site browses from
disk. Headless Chromium opens ``index.html`` from a file:// URL and follows every link of its
navigation: each opens a page of the site (not a folder's listing, not an error page), nothing is
requested from outside the site, no script fails, and the API reference shows every function's and
class's signature as the code has it (names, kinds, annotations, defaults: compared with
``inspect.signature``), and each parameter table the signature's defaults.

The site is built here when the docs extra is installed (``pip install -e '.[docs]'``); CI builds it
once with ``mkdocs build --strict`` and points ``OMAPS_SITE`` at it."""

import ast
import dataclasses
import html
import importlib
import importlib.util
import inspect
import json
import os
import pkgutil
import re
import subprocess
import sys
import time
import urllib.parse
from pathlib import Path

import pytest

from conftest import ROOT
from omaps.report.browser import find_chromium, open_page

HAVE_MKDOCS = all(importlib.util.find_spec(m) for m in ("mkdocs", "material", "mkdocstrings", "mkdocs_gen_files"))
CHROMIUM = find_chromium()
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (apt-get install chromium; "
                                    "or set OMAPS_CHROMIUM): the site's browser checks are skipped")
# on top of omaps.report.browser's flags: a page of text needs no GPU, and nothing to contact
FLAGS = ("--disable-gpu", "--disable-quic")
pytestmark = pytest.mark.long  # (a build of the site, then a browser reading each page)
COMMANDS = ("eval", "bake", "encode", "decode", "trace", "omm", "batch", "report")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The built site: ``OMAPS_SITE`` if set, else built here into a temporary folder."""
    given = os.environ.get("OMAPS_SITE")
    if given:
        path = Path(given)
        assert (path / "index.html").is_file(), f"OMAPS_SITE={given}: no index.html there"
        return path
    if not HAVE_MKDOCS:
        pytest.skip("the docs extra is not installed (pip install -e '.[docs]'): the site is not built")
    path = tmp_path_factory.mktemp("site") / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1", DISABLE_MKDOCS_2_WARNING="true")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(path)],
                       cwd=ROOT, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-4000:]
    assert "WARNING" not in r.stderr, r.stderr[-4000:]
    return path


def nav_pages() -> list:
    """The pages of mkdocs.yml's nav (docs/ paths), in order."""
    import yaml  # (a dependency of mkdocs)

    out = []

    def walk(node):
        if isinstance(node, str):
            out.append(node)
        elif isinstance(node, list):
            for item in node:
                walk(item)
        elif isinstance(node, dict):
            for item in node.values():
                walk(item)

    walk(yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))["nav"])
    return out


def test_pages_are_files(site):
    """Every page of the nav is a file of its own (``install.html``, not ``install/index.html``): a
    link to a folder opens the folder's listing from disk."""
    for page in nav_pages():
        assert (site / (page[:-3] + ".html")).is_file(), page
    assert not (site / "install" / "index.html").exists()
    cli = (site / "reference" / "cli.html").read_text(encoding="utf-8")
    for command in COMMANDS:
        assert f"usage: omaps {command}" in cli, command
    api = (site / "reference" / "api" / "omaps.html").read_text(encoding="utf-8")
    assert 'id="omaps.texture.load_alpha"' in api and api.count('class="doc-signature') > 20


def test_every_link_is_a_file_of_the_site(site):
    """Each relative ``href`` / ``src`` of every page names a file of the site, and an anchor an
    element of that page (the 404 page is the exception: a web server serves it at any depth, so
    its links start at the site's root)."""
    ids = {}

    def has_id(page: Path, anchor: str) -> bool:
        if page not in ids:
            ids[page] = {html.unescape(i) for i in re.findall(r'\bid="([^"]*)"', page.read_text(encoding="utf-8"))}
        return anchor in ids[page]

    broken = []
    for page in sorted(site.rglob("*.html")):
        if page == site / "404.html":
            continue
        for ref in re.findall(r'(?:href|src)="([^"]*)"', page.read_text(encoding="utf-8")):
            parts = urllib.parse.urlsplit(html.unescape(ref))
            if parts.scheme or parts.netloc:
                continue  # another site
            target = (page.parent / urllib.parse.unquote(parts.path)).resolve() if parts.path else page
            if not target.is_file():
                broken.append((str(page.relative_to(site)), ref))
            elif target.suffix == ".html" and parts.fragment and not has_id(target, urllib.parse.unquote(parts.fragment)):
                broken.append((str(page.relative_to(site)), ref))
    assert broken == []


SETTLE = """(() => document.readyState === 'complete' && location.href === %s
          && !!(document.querySelector('article') || document.getElementById('parentDirLinkBox')
                || !document.querySelector('.md-header')))()"""

PAGE = """(() => {
  const h1 = document.querySelector('article.md-content__inner h1');
  const id = decodeURIComponent(location.hash.slice(1));
  return {href: location.href, title: document.title, listing: !!document.getElementById('parentDirLinkBox'),
          h1: h1 ? h1.textContent.trim() : null, anchor: id ? !!document.getElementById(id) : null,
          objects: [...document.querySelectorAll('.doc-object.doc-function, .doc-object.doc-class')].map(o => {
            const h = o.querySelector(':scope > .doc-heading');
            const s = o.querySelector(':scope > .doc-signature');
            const table = [...o.querySelectorAll(':scope > .doc-contents table')].find(t => {
              let e = t;  // (the theme wraps a table in scrolling boxes)
              while (e.parentElement && !e.parentElement.classList.contains('doc-contents')) e = e.parentElement;
              return t.closest('.doc-object') === o && e.previousElementSibling
                && e.previousElementSibling.textContent.trim() === 'Parameters:';
            });
            const heads = table ? [...table.querySelectorAll('thead th')].map(th => th.textContent.trim()) : [];
            const [n, d] = [heads.indexOf('Name'), heads.indexOf('Default')];
            return {kind: o.classList.contains('doc-class') ? 'class' : 'function', id: h ? h.id : null,
                    heading: h ? h.firstChild.textContent.trim() : null,
                    signature: s ? s.textContent.trim() : null,
                    defaults: n < 0 || d < 0 ? [] : [...table.querySelectorAll('tbody tr')].map(r =>
                      [r.cells[n].textContent.trim(), r.cells[d].textContent.trim()])};
          }),
          built: [...document.querySelectorAll('article h2[id]:not(.doc-heading)')].map(h => {
            const n = h.nextElementSibling;
            return {id: h.id, heading: h.firstChild.textContent.trim(),
                    signature: n && n.classList.contains('highlight') ? n.textContent.trim() : null};
          })};
})()"""


def settle(page, url: str, timeout: float = 60.0) -> None:
    """Wait until ``url`` is the loaded document (the evaluation may meet the old one going away)."""
    end = time.monotonic() + timeout
    while True:
        try:
            if page.evaluate(SETTLE % json.dumps(url)):
                return
        except RuntimeError:
            pass  # the context being replaced
        if time.monotonic() > end:
            raise TimeoutError(f"{url} did not load in {timeout:g} s")
        time.sleep(0.1)


@pytest.fixture(scope="module")
def browsed(site):
    """Chromium opens index.html from disk and follows each link of its navigation: per link what it
    opened; the links; the console errors, the browser's error log and every request."""
    if CHROMIUM is None:
        pytest.skip("no chromium on PATH (apt-get install chromium; or set OMAPS_CHROMIUM): the site's "
                    "browser checks are skipped")
    index = (site / "index.html").resolve().as_uri()
    with open_page(CHROMIUM, site / "index.html", flags=FLAGS) as p:
        settle(p, index)
        links = p.evaluate("[...document.querySelectorAll('.md-nav--primary a.md-nav__link[href]')]"
                           ".map(a => a.href)")
        opened = {}
        for url in dict.fromkeys(links):
            result = p.call("Page.navigate", {"url": url})
            if result.get("errorText"):
                opened[url] = {"error": result["errorText"]}
                continue
            settle(p, url)
            opened[url] = p.evaluate(PAGE)
        errors = p.console_errors() + [e for e in p.log if e[0] == "error"]
        requests = list(p.requests)
    return {"index": index, "links": links, "opened": opened, "errors": errors, "requests": requests}


@needs_chromium
def test_the_navigation_is_mkdocs_yml_nav(browsed, site):
    """index.html links every page of the nav (and nothing else of the site)."""
    files = {urllib.parse.urlsplit(u)._replace(fragment="").geturl() for u in browsed["links"]}
    assert files == {(site / (p[:-3] + ".html")).resolve().as_uri() for p in nav_pages()}


@needs_chromium
def test_every_navigation_link_opens_its_page(browsed, site):
    root = site.resolve().as_uri() + "/"
    for url, got in browsed["opened"].items():
        assert "error" not in got, (url, got)
        assert got["href"] == url and url.startswith(root), (url, got["href"])
        assert not got["listing"] and not got["title"].startswith("Index of"), (url, got["title"])
        assert got["h1"], (url, "no page heading")
        assert got["anchor"] in (None, True), (url, "no element with the link's anchor")
    assert len(browsed["opened"]) >= len(nav_pages())


@needs_chromium
def test_no_script_error_and_nothing_requested_from_outside(browsed, site):
    """Pages, styles, scripts and the search index all come from the site's folder: browsing from
    disk needs no network (no web fonts, no script from a CDN) and fails no script."""
    assert browsed["errors"] == []
    root = site.resolve().as_uri() + "/"
    outside = [u for u in browsed["requests"] if not u.startswith((root, "data:", "about:"))]
    assert outside == []
    for u in browsed["requests"]:
        if u.startswith(root):
            assert Path(urllib.parse.unquote(urllib.parse.urlsplit(u).path)).is_file(), u


def _object(dotted: str):
    obj = pkgutil.resolve_name(dotted)
    return getattr(obj, "py_func", obj)  # a numba kernel: its Python function


class _LastName(ast.NodeTransformer):
    def visit_Attribute(self, node):  # os.PathLike -> PathLike
        return ast.copy_location(ast.Name(node.attr, ast.Load()), node)


def _source(node) -> str:
    """An annotation as the reference shows it: dotted names by their last part (the full name is
    the tooltip), ``Optional[X]`` as written."""
    if isinstance(node, str):
        node = ast.parse(node, mode="eval").body
    return ast.unparse(_LastName().visit(node))


def _same_value(a, b) -> bool:
    if a is b:
        return True
    if type(a) is not type(b):
        return False
    try:
        return bool(a == b) or repr(a) == repr(b)
    except Exception:
        return repr(a) == repr(b)


def signature_mismatches(obj, rendered: str) -> list:
    """How a rendered signature (``name(params) -> ret``) differs from ``inspect.signature(obj)``."""
    fn = ast.parse(f"def {rendered}: pass").body[0]
    a = fn.args
    positional = a.posonlyargs + a.args
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    shown = [(x.arg, inspect.Parameter.POSITIONAL_ONLY, x.annotation, d)
             for x, d in zip(a.posonlyargs, defaults)]
    shown += [(x.arg, inspect.Parameter.POSITIONAL_OR_KEYWORD, x.annotation, d)
              for x, d in zip(a.args, defaults[len(a.posonlyargs):])]
    if a.vararg:
        shown.append((a.vararg.arg, inspect.Parameter.VAR_POSITIONAL, a.vararg.annotation, None))
    shown += [(x.arg, inspect.Parameter.KEYWORD_ONLY, x.annotation, d) for x, d in zip(a.kwonlyargs, a.kw_defaults)]
    if a.kwarg:
        shown.append((a.kwarg.arg, inspect.Parameter.VAR_KEYWORD, a.kwarg.annotation, None))

    sig = inspect.signature(obj)
    params = list(sig.parameters.values())
    if params and params[0].name in ("self", "cls") and (not shown or shown[0][0] != params[0].name):
        params = params[1:]  # a method's first parameter, which the reference leaves out
    scope = vars(sys.modules[obj.__module__])
    out = []
    if [(p.name, p.kind) for p in params] != [(s[0], s[1]) for s in shown]:
        return [f"parameters {[(p.name, p.kind.name) for p in params]} shown as {[(s[0], s[1].name) for s in shown]}"]
    for p, (name, _, ann, default) in zip(params, shown):
        out += _annotation_mismatch(name, p.annotation, ann)
        if (p.default is inspect.Parameter.empty) != (default is None):
            out.append(f"{name}: default {p.default!r} shown as {default and ast.unparse(default)}")
        elif default is not None:
            expected = p.default
            if expected is getattr(dataclasses, "_HAS_DEFAULT_FACTORY", object()):
                continue  # a dataclass field's default_factory: shown as written
            try:
                value = eval(compile(ast.Expression(default), "<signature>", "eval"), scope)  # noqa: S307
            except Exception as e:
                out.append(f"{name}: default {ast.unparse(default)} cannot be evaluated ({e})")
                continue
            if not _same_value(value, expected):
                out.append(f"{name}: default {expected!r} shown as {ast.unparse(default)}")
    if not inspect.isclass(obj):
        out += _annotation_mismatch("return", sig.return_annotation, fn.returns)
    return out


def _annotation_mismatch(name, expected, shown) -> list:
    if expected is inspect.Parameter.empty:
        return [] if shown is None else [f"{name}: no annotation, shown as {ast.unparse(shown)}"]
    if shown is None:
        return [f"{name}: annotation {expected!r} not shown"]
    text = expected if isinstance(expected, str) else inspect.formatannotation(expected)
    ok = _source(text) == _source(shown)
    return [] if ok else [f"{name}: annotation {expected!r} shown as {ast.unparse(shown)}"]


@needs_chromium
def test_parameter_tables_give_the_signatures_defaults(browsed):
    """The Default column of each Parameters table is the signature's default of that parameter,
    ``required`` where there is none (one docstring entry may describe several parameters, each
    with its own default)."""
    problems, checked = [], set()
    alpha_test = importlib.import_module("omaps").StateRule.alpha_test
    for ident, (_, o) in api_objects(browsed).items():
        obj = _object(ident)
        if not o.get("defaults"):
            continue
        params = inspect.signature(obj).parameters
        scope = vars(sys.modules[obj.__module__])
        for name, shown in o.get("defaults", []):
            p = params.get(name)
            if p is None or p.default is getattr(dataclasses, "_HAS_DEFAULT_FACTORY", object()):
                continue
            checked.add((obj, name))
            if shown == "required":
                ok = p.default is inspect.Parameter.empty
            else:
                try:
                    ok = _same_value(eval(shown, scope), p.default)  # noqa: S307
                except Exception:
                    ok = False
            if not ok:
                problems.append(f"{ident}({name}): default {p.default!r} shown as {shown}")
    assert problems == [], "\n".join(problems)
    assert (alpha_test, "wrap") in checked and len(checked) > 20  # (the tables were read)


def own_constructor(cls) -> bool:
    """Whether a class has parameters of omaps' making (a dataclass, an ``__init__``), which its
    signature shows; one that only inherits Python's (a warning category) has none to show."""
    return dataclasses.is_dataclass(cls) or any(
        "__init__" in vars(k) or "__new__" in vars(k) for k in cls.__mro__ if k.__module__.startswith("omaps"))


def api_objects(browsed) -> dict:
    """The functions and classes of the API pages as Chromium shows them: dotted name (the
    heading's id) -> (page, what it shows)."""
    out = {}
    for url, got in browsed["opened"].items():
        if "/reference/api/" in url and "objects" in got:
            for o in got["objects"]:
                out[o["id"]] = (url, o)
            for o in got["built"]:  # made at import (docs/gen_api.py): a heading and the signature
                if o["id"].startswith("omaps."):
                    out[o["id"]] = (url, {**o, "kind": "function"})
    return out


@needs_chromium
def test_api_pages_show_the_signatures_of_the_code(browsed):
    objects = api_objects(browsed)
    assert len(objects) > 50
    problems = []
    for ident, (url, o) in objects.items():
        obj = _object(ident)
        if not o["signature"]:
            if not (inspect.isclass(obj) and not own_constructor(obj)):
                problems.append((ident, "no signature"))
            continue
        name = o["signature"].split("(", 1)[0]
        if name != ident.rsplit(".", 1)[1]:
            problems.append((ident, f"signature of {name}"))
            continue
        problems += [(ident, m) for m in signature_mismatches(obj, o["signature"])]
    assert problems == [], '\n'.join(map(str, problems))
    # (two the reference is read for: the main call of omaps trace, and the alpha test's sampling)
    headings = {o["heading"]: o for _, o in objects.values()}
    assert headings["omaps.trace_scene"]["signature"].startswith("trace_scene(")
    state_rule = importlib.import_module("omaps").StateRule
    wrap = inspect.signature(state_rule.alpha_test).parameters["wrap"].default
    shown = [o["signature"] for i, (_, o) in objects.items() if _object(i) is state_rule.alpha_test]
    assert len(shown) == 1, shown
    args = ast.parse(f"def {shown[0]}: pass").body[0].args
    assert ast.literal_eval(args.defaults[[a.arg for a in args.args][-len(args.defaults):].index("wrap")]) == wrap


@needs_chromium
def test_every_public_function_and_class_is_in_the_reference(browsed):
    """Each function and class of the ``__all__`` of each package that has an API page."""
    documented = {id(_object(i)) for i in api_objects(browsed)}
    packages = [got["h1"].strip("`¶ ") for url, got in browsed["opened"].items()
                if "/reference/api/" in url and got.get("h1")]
    assert "omaps" in packages and len(packages) >= 5, packages
    missing = []
    for package in packages:
        pkg = importlib.import_module(package)
        for name in pkg.__all__:
            obj = getattr(pkg, name)
            obj = getattr(obj, "py_func", obj)
            if (inspect.isclass(obj) or inspect.isfunction(obj)) and id(obj) not in documented:
                missing.append(f"{package}.{name}")
    assert missing == []
