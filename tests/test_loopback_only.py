"""Tests and code contact loopback only: no address or host name outside loopback in the code of
omaps/, tests/, bench/ and docs/ (``.py``), in .ci/run, or in the examples of README.md and docs/
that tests/test_readme.py runs (``sh`` and ``python`` blocks).

What is flagged (``findings``), in Python string literals (docstrings and comments are text, not
code), in the lines of shell code and in Python examples:

* a URL's host (``tcp://``, ``http://``, ``https://``, any ``scheme://``) that is not loopback;
* a literal that is an IP address and nothing else (``"192.0.2.1"``, ``"192.0.2.1:8786"``,
  ``"2001:db8::1"``), not loopback;
* the host given to a socket call that contacts it (``connect``, ``create_connection``,
  ``getaddrinfo``…: ``("example.com", 80)``), not loopback.

Loopback: ``localhost`` (and ``*.localhost``), 127.0.0.0/8, ``::1``; the bind-all addresses
``0.0.0.0`` and ``::`` also pass, and so does an upper-case placeholder (``tcp://HOST:PORT``).
Version numbers are not addresses: a number with four parts inside a longer string (``numpy==
1.2.3.4``) is not flagged, nor a whole literal assigned to a name or keyword that says
``version``."""

from __future__ import annotations

import ast
import ipaddress
import re
import shlex
from pathlib import Path

import pytest

from conftest import ROOT

SCHEME_URL = re.compile(r"(?i)\b([a-z][a-z0-9+.-]*)://(?:[^/\s@'\"]*@)?(\[[^\]\s]*\]|[^/\s:'\"?#{}\\]*)")
CONTACT_CALLS = {"connect", "connect_ex", "create_connection", "sendto", "getaddrinfo", "gethostbyname",
                 "gethostbyname_ex", "gethostbyaddr", "urlopen", "open_connection", "HTTPConnection",
                 "HTTPSConnection"}


def _address(text: str):
    """``text`` as an IP address (with a port or not, IPv6 possibly in brackets), else None."""
    t = text.strip()
    m = re.fullmatch(r"\[([0-9a-fA-F:.]+)\](?::\d+)?", t) or re.fullmatch(r"(\d{1,3}(?:\.\d{1,3}){3})(?::\d+)?", t)
    candidates = [m.group(1)] if m else ([t] if ":" in t else [])
    for c in candidates:
        try:
            return ipaddress.ip_address(c)
        except ValueError:
            pass
    return None


def loopback(host: str) -> bool:
    """Whether contacting ``host`` stays on this machine (or it is a placeholder, not a host)."""
    h = host.strip("[]")
    if not h or re.fullmatch(r"[A-Z][A-Z0-9_]*", h):  # nothing (filled in at run time), or HOST, SCHEDULER
        return True
    if h.lower() == "localhost" or h.lower().endswith(".localhost"):
        return True
    try:
        a = ipaddress.ip_address(h)
    except ValueError:
        return False  # a host name: resolved, and contacted, elsewhere
    return a.is_loopback or a.is_unspecified  # (0.0.0.0 and ::, bind-all)


def text_findings(text: str) -> list[str]:
    """What a piece of text (a string literal's value, a line of shell code) names outside
    loopback: URLs' hosts, and the whole text as an address."""
    found = []
    for m in SCHEME_URL.finditer(text):
        if not loopback(m.group(2)):
            found.append(f"{m.group(1)}://{m.group(2)}")
    a = _address(text)
    if a is not None and not (a.is_loopback or a.is_unspecified):
        found.append(text.strip())
    return found


def _version_context(parents: dict, node) -> bool:
    """A literal assigned to a name, attribute or keyword that says ``version``."""
    p = parents.get(node)
    if isinstance(p, ast.keyword):
        return "version" in (p.arg or "").lower()
    if isinstance(p, (ast.Assign, ast.AnnAssign)):
        targets = p.targets if isinstance(p, ast.Assign) else [p.target]
        return any("version" in ast.unparse(t).lower() for t in targets)
    return False


def python_findings(source: str, first_line: int = 1) -> list[tuple[int, str]]:
    """(line, what) for each address or host outside loopback in Python code: its string
    literals (docstrings aside) and the hosts its socket calls contact."""
    tree = ast.parse(source)
    parents = {c: p for p in ast.walk(tree) for c in ast.iter_child_nodes(p)}
    docstrings = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)
                  and isinstance(n.value.value, str)}
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            what = text_findings(node.value)
            if what and _address(node.value) is not None and _version_context(parents, node):
                what = [w for w in what if w != node.value.strip()]
            found += [(node.lineno + first_line - 1, w) for w in what]
        elif isinstance(node, ast.Call) and node.args:
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name not in CONTACT_CALLS:
                continue
            arg = node.args[0]
            host = arg.elts[0] if isinstance(arg, ast.Tuple) and arg.elts else arg
            if isinstance(host, ast.Constant) and isinstance(host.value, str) and "://" not in host.value \
                    and not loopback(host.value):
                found.append((node.lineno + first_line - 1, f"{name}({host.value!r}, …)"))
    return sorted(set(found))


def shell_findings(line: str) -> list[str]:
    """What a line of shell code names outside loopback: URLs' hosts, words that are addresses."""
    try:
        words = shlex.split(line, comments=False)
    except ValueError:
        words = line.split()
    return sorted(set(text_findings(line) + [w for word in words for w in text_findings(word) if "://" not in w]))


def _fenced(path: Path, lang: str) -> list[tuple[int, str]]:
    """(first line, text) of the page's ``lang`` blocks, as tests/test_readme.py finds them."""
    text = path.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1))
            for m in re.finditer(rf"^```{lang}\n(.*?)^```", text, re.M | re.S)]


def scanned() -> list[Path]:
    py = [p for d in ("omaps", "tests", "bench", "docs") for p in sorted((ROOT / d).rglob("*.py"))]
    return py + [ROOT / ".ci" / "run", ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))


def findings(path: Path, root: Path = ROOT) -> list[str]:
    """``FILE:LINE: what`` for each address or host outside loopback in one scanned file."""
    rel = path.relative_to(root).as_posix()
    found: list[tuple[int, str]] = []
    if path.suffix == ".py":
        found = python_findings(path.read_text(encoding="utf-8"))
    elif path.suffix == ".md":
        for start, block in _fenced(path, "python"):
            found += python_findings(block, start)
        for start, block in _fenced(path, "sh"):
            found += [(start + i, w) for i, ln in enumerate(block.splitlines()) for w in shell_findings(ln)]
    else:  # a shell script
        for i, ln in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if not ln.lstrip().startswith("#"):
                found += [(i, w) for w in shell_findings(ln)]
    return [f"{rel}:{n}: {w}" for n, w in sorted(set(found))]


def test_code_and_examples_name_loopback_only():
    files = scanned()
    assert len(files) > 100 and ROOT / "omaps" / "batch" / "engine.py" in files and ROOT / ".ci" / "run" in files
    here = Path(__file__).resolve()
    assert here in files and len(findings(here)) >= 10  # its made-up samples below: found on disk too
    bad = [f for p in files if p != here for f in findings(p)]
    assert not bad, "outside loopback (tests and code contact loopback only):\n" + "\n".join(bad)


# --- the scanner itself, on made-up code (this file is the one the scan above leaves out) ---------

@pytest.mark.parametrize("code, want", [
    ("c = Client('tcp://198.51.100.1:8786')", ["tcp://198.51.100.1"]),
    ("requests.get('https://example.com/x.png')", ["https://example.com"]),
    ("u = f'http://user@files.example.org:8080/{name}'", ["http://files.example.org"]),
    ("u = 'ws://[2001:db8::1]:80/'", ["ws://[2001:db8::1]"]),
    ("s.connect(('192.0.2.7', 80))", ["192.0.2.7", "connect('192.0.2.7', …)"]),
    ("socket.create_connection(('scheduler.example.net', 8786))", ["create_connection('scheduler.example.net', …)"]),
    ("addr = '192.0.2.1:8786'", ["192.0.2.1:8786"]),
    ("hosts = ['2001:db8::5']", ["2001:db8::5"]),
    ("socket.getaddrinfo('pypi.org', 443)", ["getaddrinfo('pypi.org', …)"]),
])
def test_scanner_flags_outside_addresses(code, want):
    assert [w for _, w in python_findings(code)] == want


@pytest.mark.parametrize("code", [
    "c = Client('tcp://127.0.0.1:8786')",
    "c = Client(f'tcp://127.0.0.1:{port}')",
    "c = Client(f'tcp://{host}:{port}')",
    "c = Client('tcp://localhost:8786')",
    "u = 'http://[::1]:80/'",
    "help = 'tcp://HOST:PORT: an existing Dask scheduler'",
    "uri = 'file://' + path",
    "s.bind(('0.0.0.0', 0))",
    "s.bind(('', 8787))",
    "s.connect(('127.0.0.1', port))",
    "s.connect(('::1', port))",
    "deps = ['numpy>=1.2.3.4,<3']",
    "__version__ = '1.2.3.4'",
    "setup(version='203.0.113.2')",
    "ratio = '1.25.3.7 times'",
    'def f():\n    """See http://example.com/docs."""\n    return 1',  # a docstring: text, not contacted
    "x = 1  # http://example.com in a comment",
])
def test_scanner_passes_loopback_placeholders_and_versions(code):
    assert python_findings(code) == []


def test_scanner_reads_shell_lines_and_page_examples(tmp_path):
    assert shell_findings("pip install 'numpy==1.2.3.4'") == []
    assert shell_findings("omaps batch eval t -o out --scheduler tcp://127.0.0.1:8786") == []
    assert shell_findings("curl -O https://example.com/a.png") == ["https://example.com"]
    assert shell_findings("ping -c1 192.0.2.3") == ["192.0.2.3"]
    page = tmp_path / "docs" / "page.md"
    page.parent.mkdir()
    page.write_text("Text naming http://example.com is prose.\n\n```sh\nomaps eval t\ncurl http://198.51.100.7/x\n```\n\n"
                    "```console\nssh 198.51.100.7\n```\n\n```python\nimport socket\n"
                    "socket.create_connection(('198.51.100.6', 80))\n```\n")
    assert findings(page, tmp_path) == ["docs/page.md:5: http://198.51.100.7", "docs/page.md:14: 198.51.100.6",
                                        "docs/page.md:14: create_connection('198.51.100.6', …)"]
    script = tmp_path / "run"
    script.write_text("#!/bin/sh\n# http://example.com: a comment\npip install --index-url http://203.0.113.1/ x\n")
    assert findings(script, tmp_path) == ["run:3: http://203.0.113.1"]
