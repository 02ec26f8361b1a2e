"""The examples of README.md and of every page under docs/ work exactly as written.

* ``sh`` blocks: every line (but the set-up block under "Two commands" in README.md, which CI
  runs itself, and blocks that install packages), page by page in the page's order, as bash
  scripts run from a folder beside ``../shared``, as from the repository root; outputs go to its
  ``out/``. Lines of a page that share no file under ``out/`` run as separate tests (page_parts),
  so that the test workers share them; a part that another page repeats word for word runs once.
* ``python`` blocks: each page's blocks in order, as one script, in a folder beside ``../shared``.
* ``console`` blocks are shown, not run: the virtual-environment and docs-build lines, commands
  that need other machines (a Dask cluster), and the results page's commands, which
  ``docs/scripts/results.py`` runs (test_results_page_is_rendered checks that page).

Examples that read ``../shared/data`` skip, naming it, when it is absent."""

import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, SCENES, SHARED, TEXTURES
from omaps.cli.main import parser
from omaps.cli.trace import bind_camera_value

README = ROOT / "README.md"
DOCS = ROOT / "docs"
PAGES = [README] + sorted(DOCS.rglob("*.md"))
HAVE_SHARED = TEXTURES.is_dir() and (SCENES / "palm.glb").is_file() and (SCENES / "forest.glb").is_file()
SETUP = ["pip install -e '.[test]' && omaps eval", "python -m pytest"]


def _rel(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


def blocks(page: Path, lang: str) -> list[str]:
    text = page.read_text(encoding="utf-8")
    found = re.findall(rf"^```{lang}\n(.*?)^```", text, re.M | re.S)
    return [b for b in found if "pip install" not in b]  # the set-up block: CI runs it


def page_lines(page: Path) -> list[str]:
    """Every non-blank line of the page's ``sh`` blocks (but the set-up block), in order."""
    return [ln for b in blocks(page, "sh") for ln in b.splitlines() if ln.strip()]


def _out_paths(line: str) -> set[str]:
    return {p.rstrip("/") for p in re.findall(r"\bout/[\w./-]+", line)}


def _related(a: str, b: str) -> bool:
    """One path is the other or lies under it (``out/omm`` and ``out/omm/omm.json``)."""
    return a == b or a.startswith(b + "/") or b.startswith(a + "/")


def _is_assign(line: str) -> bool:
    return bool(re.match(r"^\w+=", line))


def page_parts(page: Path) -> list[list[str]]:
    """The page's lines as independent scripts, each in the page's order: lines that name a
    common path under ``out/`` (one makes what another reads, verifies, replaces or traces) are
    one part, which starts with the page's variable assignments (``leaf=...``, the latest before
    each use) that its commands use. Every line but the assignments is in exactly one part
    (test_parts_cover_every_line); the parts share nothing, so the test workers can run them side
    by side."""
    lines = page_lines(page)
    cmds = [i for i, ln in enumerate(lines) if not _is_assign(ln)]
    group = {i: i for i in cmds}

    def root(i):
        while group[i] != i:
            i = group[i]
        return i

    for k, i in enumerate(cmds):
        for j in cmds[:k]:
            if any(_related(a, b) for a in _out_paths(lines[i]) for b in _out_paths(lines[j])):
                group[root(i)] = root(j)
    parts = {}
    for i in cmds:
        parts.setdefault(root(i), []).append(i)
    out = []
    for idx in parts.values():
        assigns, var = [], {}
        for i in range(idx[-1] + 1):
            m = re.match(r"^(\w+)=", lines[i])
            if m:
                var[m.group(1)] = lines[i]
            elif i in idx:
                for name, assign in var.items():  # the variables this line uses, set as written
                    if f"${name}" in lines[i] and assign not in assigns:
                        assigns.append(assign)
        out.append(assigns + [lines[i] for i in idx])
    return out


def _part_id(script: list[str]) -> str:
    """The part's first command and what it writes (or reads), e.g. ``eval-savings.png``."""
    first = next(ln for ln in script if not _is_assign(ln))
    words = shlex.split(first, comments=True)
    outs = sorted(_out_paths(first), key=first.index)
    name = outs[0] if outs else next((w for w in words[2:] if not w.startswith("-")), "")
    if words[0] != "omaps":
        return f"{words[0]}-{Path(name).name}"
    return "-".join(words[1:3] if words[1] == "batch" else words[1:2]) + "-" + Path(name).name


def all_parts() -> list[tuple[Path, list[str]]]:
    """(page, part) for every page, a part already run for an earlier page left out."""
    seen, out = set(), []
    for page in PAGES:
        for part in page_parts(page):
            if tuple(part) not in seen:
                seen.add(tuple(part))
                out.append((page, part))
    return out


def test_commands_parse():
    """Every omaps command of the README and the docs parses (runs without ../shared too), and
    none uses a made-up file: inputs are in ../shared/data or made by an earlier line under out/."""
    count = 0
    for page in PAGES:
        var = {}
        for ln in page_lines(page):
            if m := re.match(r"^(\w+)=(\S+)$", ln):
                var[m.group(1)] = m.group(2)
                assert m.group(2).startswith("../shared/data/"), (_rel(page), ln)
                continue
            if not ln.startswith("omaps "):
                continue
            count += 1
            words = [var.get(w[1:], w) if w.startswith("$") else w for w in shlex.split(ln, comments=True)]
            args = parser().parse_args(bind_camera_value(words[1:]))  # as omaps.cli.main does
            assert args.func is not None
            for w in words[2:]:
                if re.search(r"\.(png|glb|gltf|npy|vq2|vq4|vq4x64|json|csv)/?$", w) or w.endswith("/"):
                    assert w.startswith(("../shared/data/", "out/")), (_rel(page), ln, w)
    assert count >= 25


def test_parts_cover_every_line():
    """On every page the parts run each command line exactly once, in the page's order, and only
    its lines; a line that reads what an earlier one made runs after it in the same part."""
    for page in PAGES:
        lines, parts = page_lines(page), page_parts(page)
        cmds = [ln for ln in lines if not _is_assign(ln)]
        ran = [ln for s in parts for ln in s if not _is_assign(ln)]
        assert sorted(ran) == sorted(cmds), _rel(page)
        for s in parts:
            assert all(ln in lines for ln in s)
            pos = [lines.index(ln) for ln in s if not _is_assign(ln)]
            assert pos == sorted(pos), s
            for ln in s:  # a variable is set, as the page sets it, before the part's commands use it
                if m := re.match(r"^(\w+)=", ln):
                    assert any(f"${m.group(1)}" in c for c in s), (ln, s)
                    assert s.index(ln) < min(s.index(c) for c in s if f"${m.group(1)}" in c), s
    uvs = next(s for s in page_parts(DOCS / "guide" / "bake.md") if any("np.save('out/uvs.npy'" in ln for ln in s))
    assert any(ln.startswith("omaps bake $leaf --scheme tri4 --uvs out/uvs.npy") for ln in uvs)
    assert len(all_parts()) >= 20  # the independent examples, spread over the test workers


PARTS = all_parts()


@pytest.mark.skipif(not HAVE_SHARED, reason=f"the examples use ../shared/data, not found at {SHARED / 'data'}")
@pytest.mark.parametrize("page,script", PARTS,
                         ids=[f"{_rel(p).removeprefix('docs/').removesuffix('.md').replace('/', '_')}-{k:02d}-{_part_id(s)}"
                              for k, (p, s) in enumerate(PARTS)])
@pytest.mark.long
def test_commands_run(tmp_path, page, script):
    """One part of a page's commands (page_parts), as one bash script run from a folder beside
    ``../shared``, as from the repository root."""
    repo = tmp_path / "repo"
    repo.mkdir()
    (tmp_path / "shared").symlink_to(SHARED.resolve(), target_is_directory=True)
    text = "\n".join(script)
    if not next(ln for ln in script if not _is_assign(ln)).startswith("omaps "):
        (repo / "out").mkdir()  # a python line writing under out/ comes after an omaps command made it
    env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    env.pop("OMAPS_PROGRESS", None)
    r = subprocess.run(["bash", "-c", "set -euo pipefail -x\n" + text], cwd=repo, env=env, capture_output=True,
                       text=True)
    assert r.returncode == 0, f"a command of {_rel(page)} failed:\n{r.stderr[-4000:]}"
    named = set(re.findall(r"\bout/[\w./-]+", text))
    assert sorted(os.listdir(repo)) == (["out"] if named else [])  # everything went to out/
    missing = [p for p in named if not (repo / p).exists()]
    assert not missing, missing
    assert not list(repo.rglob(".omaps-*"))
    if "out/r.json" in named:
        # the README's corpus table and the results page's are what this command computes
        mean = json.loads((repo / "out" / "r.json").read_text())["mean"]
        for doc in (README, DOCS / "results.md"):
            schemes, values = corpus_table(doc)
            assert {s: round(mean[s]["savings"], 3) for s in schemes} == dict(zip(schemes, values)), _rel(doc)


def corpus_table(doc: Path) -> tuple[list[str], list[float]]:
    """The schemes and mean savings of a page's corpus table."""
    lines = doc.read_text(encoding="utf-8").splitlines()
    head = next(ln for ln in lines if ln.startswith("| scheme | sq4 |"))
    row = next(ln for ln in lines[lines.index(head):] if ln.startswith("| mean savings |"))
    schemes = [c.strip() for c in head.strip("|").split("|")[1:]]
    return schemes, [float(c) for c in row.strip("|").split("|")[1:]]


PY_PAGES = [p for p in PAGES if blocks(p, "python")]


@pytest.mark.parametrize("page", PY_PAGES, ids=[_rel(p) for p in PY_PAGES])
def test_python_examples_run(tmp_path, page):
    """A page's ``python`` blocks, in order, as one script run from a folder beside ``../shared``."""
    code = "\n\n".join(blocks(page, "python"))
    if "../shared/" in code and not HAVE_SHARED:
        pytest.skip(f"the examples of {_rel(page)} use ../shared/data, not found at {SHARED / 'data'}")
    repo = tmp_path / "repo"
    repo.mkdir()
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED.resolve(), target_is_directory=True)
    script = tmp_path / "example.py"
    script.write_text(code, encoding="utf-8")
    env = dict(os.environ)
    env.pop("OMAPS_PROGRESS", None)
    r = subprocess.run([sys.executable, str(script)], cwd=repo, env=env, capture_output=True, text=True)
    assert r.returncode == 0, f"a python example of {_rel(page)} failed:\n{r.stderr[-4000:]}"
    # run from the repository root, an example writes only under out/ (git-ignored)
    assert sorted(os.listdir(repo)) in ([], ["out"]), f"{_rel(page)} wrote {sorted(os.listdir(repo))} beside out/"


def _results_module():
    spec = importlib.util.spec_from_file_location("docs_results", DOCS / "scripts" / "results.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_results_page_is_rendered():
    """docs/results.md is what docs/scripts/results.py renders from the run's figures
    (docs/results.json), and the README's corpus table shows the same figures."""
    mod = _results_module()
    figures = json.loads((DOCS / "results.json").read_text(encoding="utf-8"))
    assert (DOCS / "results.md").read_text(encoding="utf-8") == mod.render(figures), \
        "docs/results.md is stale: run python docs/scripts/results.py --render-only"
    schemes, values = corpus_table(README)
    assert schemes == mod.BASE
    assert values == [round(figures["corpus"]["mean"][s]["savings"], 3) for s in schemes]


def test_readme_is_for_users():
    """README.md: at most 200 lines, no development history, the virtual environment made before
    exactly the two set-up commands that CI runs (.ci/run reads the first sh block under
    "Two commands")."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    for word in ("issue", "issues", "session", "sessions"):
        assert not re.search(rf"\b{word}\b", text, re.I), word
    assert not re.search(r"\bthe deck\b", text, re.I)
    section = text.split("\n## Two commands\n", 1)[1].split("\n## ", 1)[0]
    setup = re.search(r"^```sh\n(.*?)^```", section, re.M | re.S).group(1).splitlines()
    assert setup == SETUP
    venv = "python3 -m venv .venv && source .venv/bin/activate"
    assert venv in section and section.index(venv) < section.index("```sh")
    assert "pip install -e '.[docs]' && mkdocs build --strict" in text
