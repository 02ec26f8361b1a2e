"""The README's commands work exactly as written: every line of its ``sh`` blocks (but the set-up
block under "Two commands", which CI runs itself), in order, as one bash script run from a
folder beside ``../shared``, as from the repository root; outputs go to its ``out/``."""

import json
import os
import re
import shlex
import subprocess
import sys

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


@pytest.mark.skipif(not (TEXTURES.is_dir() and (SCENES / "palm.glb").is_file() and (SCENES / "forest.glb").is_file()),
                    reason=f"the README's commands use ../shared/data, not found at {SHARED / 'data'}")
def test_readme_commands_run(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    (tmp_path / "shared").symlink_to(SHARED.resolve(), target_is_directory=True)
    script = "set -euo pipefail -x\n" + "\n".join(readme_blocks())
    env = dict(os.environ, PATH=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    env.pop("OMAPS_PROGRESS", None)
    r = subprocess.run(["bash", "-c", script], cwd=repo, env=env, capture_output=True, text=True)
    assert r.returncode == 0, f"a README command failed:\n{r.stderr[-4000:]}"
    assert sorted(os.listdir(repo)) == ["out"]  # everything went to out/
    named = set(re.findall(r"\bout/[\w./-]+", "\n".join(readme_blocks())))
    missing = [p for p in named if not (repo / p).exists()]
    assert not missing, missing
    assert not list(repo.rglob(".omaps-*"))
    # the corpus table of the README is what its first command computes
    table = README.read_text(encoding="utf-8").split("## Results on the shared corpus", 1)[1]
    head = next(ln for ln in table.splitlines() if ln.startswith("| scheme |"))
    row = next(ln for ln in table.splitlines() if ln.startswith("| mean savings |"))
    schemes = [c.strip() for c in head.strip("|").split("|")[1:]]
    values = [float(c) for c in row.strip("|").split("|")[1:]]
    mean = json.loads((repo / "out" / "r.json").read_text())["mean"]
    assert {s: round(mean[s]["savings"], 3) for s in schemes} == dict(zip(schemes, values))
