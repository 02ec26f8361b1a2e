"""The package's layout, read from its source: every import counted, function-level ones too.

* the import graph of ``omaps`` has no cycle;
* nothing outside ``omaps/cli`` imports ``omaps.cli`` (besides ``python -m omaps``'s entry);
* nothing outside ``omaps/codecs`` imports one codec's own module: only the package API
  (``omaps.codecs``) or the registry;
* every command module is at most ``COMMAND_LINES`` lines: the commands parse, call one library
  function and print.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "omaps"
COMMAND_LINES = 220
ENTRY_POINTS = {"omaps.__main__"}  # ``python -m omaps``: runs the command line


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts}


def imported_modules(path: Path) -> set[str]:
    """The omaps modules a source file imports, anywhere in it (``from .x import name`` counts as
    the module ``x``, or ``x.name`` where that is a module)."""
    name = module_name(path)
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")
                mod = ".".join(base[:len(base) - node.level + 1] + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            found |= {f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod for a in node.names}
    out = set()
    for m in found:
        while m and m not in MODULES:
            m = m.rpartition(".")[0]
        if m and m != name:
            out.add(m)
    return out


GRAPH = {m: imported_modules(p) for m, p in MODULES.items()}


def cycles(graph: dict) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_cycle_finder_finds_cycles_and_only_cycles():
    graph = {"a": {"b"}, "b": {"a"}, "c": {"a", "d"}, "d": {"e"}, "e": {"f"}, "f": {"d"}}
    assert sorted(cycles(graph)) == [["a", "b"], ["d", "e", "f"]]
    assert cycles({"x": {"y"}, "y": set(), "z": {"x", "y"}}) == []


def test_function_level_imports_are_counted():
    src = PACKAGE / "trace" / "experiment.py"
    assert "omaps.trace.prepare" in imported_modules(src)  # imported inside trace_scene only


def test_the_import_graph_has_no_cycle():
    assert cycles(GRAPH) == []


def test_nothing_outside_cli_imports_the_cli():
    bad = sorted((m, d) for m, deps in GRAPH.items() if not m.startswith("omaps.cli") and m not in ENTRY_POINTS
                 for d in deps if d == "omaps.cli" or d.startswith("omaps.cli."))
    assert not bad


def test_nothing_outside_codecs_imports_a_codecs_own_module():
    allowed = {"omaps.codecs", "omaps.codecs.registry"}
    bad = sorted((m, d) for m, deps in GRAPH.items() if not m.startswith("omaps.codecs")
                 for d in deps if d.startswith("omaps.codecs.") and d not in allowed)
    assert not bad


@pytest.mark.parametrize("path", sorted(p.name for p in (PACKAGE / "cli").glob("*.py")
                                        if p.name not in ("main.py", "precompile.py", "__init__.py",
                                                          "__main__.py")))
def test_command_modules_are_thin(path):
    lines = len((PACKAGE / "cli" / path).read_text().splitlines())
    assert lines <= COMMAND_LINES, f"omaps/cli/{path} has {lines} lines"
