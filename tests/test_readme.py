"""The README's commands work exactly as written: every line of its ``sh`` blocks (but the set-up
block under "Two commands", which CI runs itself), in the README's order, as bash scripts run
from a folder beside ``../shared``, as from the repository root; outputs go to its ``out/``.
Lines that share no file under ``out/`` run as separate tests, so that the test workers share
them (readme_parts)."""

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


def readme_blocks() -> list[str]:
    text = README.read_text(encoding="utf-8")
    blocks = re.findall(r"^```sh\n(.*?)^```", text, re.M | re.S)
    return [b for b in blocks if "pip install" not in b]  # the set-up block: CI runs it


def omaps_lines() -> list[str]:
    return [ln for b in readme_blocks() for ln in b.splitlines() if ln.startswith("omaps ")]


def test_readme_commands_parse():
    """Every omaps command of the README parses (runs without ../shared too), and none uses a
    made-up file: inputs are in ../shared/data or made by an earlier line under out/."""
    lines = omaps_lines()
    assert len(lines) >= 12
    leaf = None
    for b in readme_blocks():
        m = re.search(r"^leaf=(\S+)$", b, re.M)
        leaf = m.group(1) if m else leaf
    assert leaf and leaf.startswith("../shared/data/textures/")
    for ln in lines:
        words = shlex.split(ln, comments=True)
        words = [leaf if w == "$leaf" else w for w in words]
        args = parser().parse_args(bind_camera_value(words[1:]))  # as omaps.cli.main does
        assert args.func is not None
        for w in words[2:]:
            if re.search(r"\.(png|glb|gltf|npy|vq2|vq4|json|csv)/?$", w) or w.endswith("/"):
                assert w.startswith(("../shared/data/", "out/")), (ln, w)


def readme_lines() -> list[str]:
    """Every non-blank line of the README's ``sh`` blocks (but the set-up block), in order."""
    return [ln for b in readme_blocks() for ln in b.splitlines() if ln.strip()]


def _out_paths(line: str) -> set[str]:
    return {p.rstrip("/") for p in re.findall(r"\bout/[\w./-]+", line)}


def _related(a: str, b: str) -> bool:
    """One path is the other or lies under it (``out/omm`` and ``out/omm/omm.json``)."""
    return a == b or a.startswith(b + "/") or b.startswith(a + "/")


def readme_parts() -> list[list[str]]:
    """The README's lines as independent scripts, each in the README's order: lines that name a
    common path under ``out/`` (one makes what another reads, verifies, replaces or traces) are
    one part, which starts with the README's ``leaf=`` line (the latest before a command using
    ``$leaf``) if its commands use ``$leaf``.
    Every line but the ``leaf=`` ones is in exactly one part (test_readme_parts_cover_every_line);
    the parts share nothing, so the test workers can run them side by side."""
    lines = readme_lines()
    cmds = [i for i, ln in enumerate(lines) if not re.match(r"^\w+=", ln)]
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
    first = next(ln for ln in script if not re.match(r"^\w+=", ln))
    words = shlex.split(first, comments=True)
    outs = sorted(_out_paths(first), key=first.index)
    name = outs[0] if outs else next((w for w in words[2:] if not w.startswith("-")), "")
    if words[0] != "omaps":
        return f"{words[0]}-{Path(name).name}"
    return "-".join(words[1:3] if words[1] == "batch" else words[1:2]) + "-" + Path(name).name


def test_readme_parts_cover_every_line():
    """The parts run each command line of the README exactly once, in the README's order, and
    only its lines."""
    lines = readme_lines()
    parts = readme_parts()
    assert len(parts) >= 8  # the README's independent examples, spread over the test workers
    cmds = [ln for ln in lines if not re.match(r"^\w+=", ln)]
    ran = [ln for s in parts for ln in s if not re.match(r"^\w+=", ln)]
    assert sorted(ran) == sorted(cmds)
    for s in parts:
        assert all(ln in lines for ln in s)
        pos = [lines.index(ln) for ln in s if not re.match(r"^\w+=", ln)]
        assert pos == sorted(pos), s
        for ln in s:  # a variable is set, as the README sets it, before the part's commands use it
            if m := re.match(r"^(\w+)=", ln):
                assert any(f"${m.group(1)}" in c for c in s), (ln, s)
                assert s.index(ln) < min(s.index(c) for c in s if f"${m.group(1)}" in c), s
    # out/ is made by an omaps command (which makes a missing output folder) before any other
    # line writes there, so a part starting with another command runs with out/ made
    first = next(ln for ln in cmds if _out_paths(ln))
    assert first.startswith("omaps "), first
    # a line that reads or replaces what an earlier one made runs after it in the same part
    uvs = next(s for s in parts if any("np.save('out/uvs.npy'" in ln for ln in s))
    assert any(ln.startswith("omaps omm $leaf out/uvs.npy") for ln in uvs)
    assert any(ln.startswith("omaps bake $leaf") for ln in uvs)


PARTS = readme_parts()


@pytest.mark.skipif(not (TEXTURES.is_dir() and (SCENES / "palm.glb").is_file() and (SCENES / "forest.glb").is_file()),
                    reason=f"the README's commands use ../shared/data, not found at {SHARED / 'data'}")
@pytest.mark.parametrize("script", PARTS, ids=[f"{k:02d}-{_part_id(s)}" for k, s in enumerate(PARTS)])
@pytest.mark.long
def test_readme_commands_run(tmp_path, script):
    """One part of the README's commands (readme_parts), as one bash script run from a folder
    beside ``../shared``, as from the repository root."""
    repo = tmp_path / "repo"
    repo.mkdir()
    (tmp_path / "shared").symlink_to(SHARED.resolve(), target_is_directory=True)
    text = "\n".join(script)
    if not next(ln for ln in script if not re.match(r"^\w+=", ln)).startswith("omaps "):
        (repo / "out").mkdir()  # made by the README's first command (test_readme_parts_cover_every_line)
    env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    env.pop("OMAPS_PROGRESS", None)
    r = subprocess.run(["bash", "-c", "set -euo pipefail -x\n" + text], cwd=repo, env=env, capture_output=True,
                       text=True)
    assert r.returncode == 0, f"a README command failed:\n{r.stderr[-4000:]}"
    named = set(re.findall(r"\bout/[\w./-]+", text))
    assert sorted(os.listdir(repo)) == (["out"] if named else [])  # everything went to out/
    missing = [p for p in named if not (repo / p).exists()]
    assert not missing, missing
    assert not list(repo.rglob(".omaps-*"))
    if "out/r.json" in named:
        # the corpus table of the README is what its first command computes
        table = README.read_text(encoding="utf-8").split("## Results on the shared corpus", 1)[1]
        head = next(ln for ln in table.splitlines() if ln.startswith("| scheme |"))
        row = next(ln for ln in table.splitlines() if ln.startswith("| mean savings |"))
        schemes = [c.strip() for c in head.strip("|").split("|")[1:]]
        values = [float(c) for c in row.strip("|").split("|")[1:]]
        mean = json.loads((repo / "out" / "r.json").read_text())["mean"]
        assert {s: round(mean[s]["savings"], 3) for s in schemes} == dict(zip(schemes, values))
