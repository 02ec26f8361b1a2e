"""The documentation site builds: ``mkdocs build --strict`` (no warning: broken links and anchors,
API docstrings mkdocstrings cannot read, pages missing from the nav) into a temporary folder."""

import importlib.util
import os
import subprocess
import sys

import pytest

from conftest import ROOT

HAVE_MKDOCS = all(importlib.util.find_spec(m) for m in ("mkdocs", "material", "mkdocstrings", "mkdocs_gen_files"))


@pytest.mark.skipif(not HAVE_MKDOCS, reason="the docs extra is not installed (pip install -e '.[docs]')")
@pytest.mark.long
def test_mkdocs_build_strict(tmp_path):
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1", DISABLE_MKDOCS_2_WARNING="true")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                       cwd=ROOT, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-4000:]
    assert "WARNING" not in r.stderr, r.stderr[-4000:]
    site = tmp_path / "site"
    for page in ("index.html", "reference/cli/index.html", "reference/api/omaps/index.html", "results/index.html",
                 "FORMAT/index.html", "TERMINOLOGY/index.html"):
        assert (site / page).is_file(), page
    cli = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    for command in ("eval", "bake", "encode", "decode", "trace", "omm", "batch"):
        assert f"usage: omaps {command}" in cli, command
    assert "load_alpha" in (site / "reference" / "api" / "omaps" / "index.html").read_text(encoding="utf-8")
