"""First use of numba kernels: which a command compiles, the cache check behind the one-line
announcement, and the ahead-of-time compile (``omaps.cli.precompile``)."""

import os
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

from omaps.cli.precompile import FAMILIES, families_for


def test_families_of_commands():
    def ns(**kw):
        return SimpleNamespace(**kw)

    assert families_for(ns(command="eval", schemes="sq16,tri3,texel")) == ["square", "micromap"]
    assert families_for(ns(command="eval", schemes="vq2-paper,vq4x64-fast")) == ["square", "vq2", "vq4"]
    assert families_for(ns(command="eval", schemes="vq4-synth,wavelet3-fast")) == ["square", "vq4", "synth", "wavelet"]
    assert families_for(ns(command="trace", schemes="none,vq4")) == ["trace", "square", "vq4"]
    assert families_for(ns(command="trace", schemes="none,file:vq4,omm")) == ["trace"]
    assert families_for(ns(command="trace", schemes="budget:1MiB")) == ["trace", "square", "vq2", "vq4",
                                                                         "budget-maps"]
    assert families_for(ns(command="trace", schemes="budget:1MiB:vq4+succinct6")) == [
        "trace", "square", "vq4", "hierarchical", "budget-maps"]
    assert families_for(ns(command="report", input="palm.glb", schemes="none,tri3")) == ["trace", "micromap"]
    assert families_for(ns(command="report", input="textures", schemes=None)) == ["square", "micromap"]
    assert families_for(ns(command="omm", inputs=["a.glb"], expand=False, source="texture", budget=900)) == [
        "micromap", "omm", "budget"]
    # the view's hits are traced
    assert families_for(ns(command="omm", inputs=["a.glb"], expand=False, source="texture", budget=900,
                           weights="view")) == ["micromap", "omm", "budget", "trace"]
    assert families_for(ns(command="omm", inputs=["a.glb"], expand=False, source="texture")) == ["micromap", "omm"]
    assert families_for(ns(command="omm", inputs=["a.glb"], expand=False, source="vq2")) == [
        "micromap", "omm", "square", "vq2"]
    # --verify compiles the coverage kernels (in the omm family); --expand none
    assert families_for(ns(command="omm", inputs=[], verify="out", expand=False, source="texture")) == ["omm"]
    assert families_for(ns(command="omm", inputs=[], verify=None, expand=True, source="texture")) == []
    assert families_for(ns(command="encode", codec="vq4x64")) == ["square", "vq4"]
    assert families_for(ns(command="bake", scheme="tri4")) == ["micromap"]
    assert families_for(ns(command="decode", codec="vq4")) == []
    assert all(f in FAMILIES for f in ["square", "micromap", "trace", "vq2", "vq4", "omm", "budget", "budget-maps", "synth",
                                 "wavelet"])


def test_a_texture_bake_imports_no_codec_before_it_runs():
    """Finding an ``omm`` bake's families from the texture loads no codec or budget module (their
    imports took about half a second of every bake's start)."""
    code = ("import sys; from omaps.cli.main import parser; from omaps.cli import precompile; "
            "a = parser('omm').parse_args(['omm', 'leaf.png', 'uv.npy', '-o', 'out', '--level', '4']); "
            "precompile.uncached(precompile.families_for(a)); "
            "print(sorted(m for m in sys.modules if m.startswith(('omaps.codecs.vq', 'omaps.codecs.wavelet', "
            "'omaps.budget', 'omaps.allocate', 'omaps.bake.square'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.long
def test_empty_cache_is_announced_once_and_compiled_kernels_are_found(tmp_path):
    """With an empty private cache every family is uncached; a command announces its compile
    (one line) the first time only, and afterwards its families count as cached while the
    others still do not."""
    alpha = np.where(np.arange(64).reshape(8, 8) % 3 == 0, 255, 0).astype(np.uint8)
    Image.fromarray(np.dstack([alpha] * 4)).save(tmp_path / "leaf.png")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), OMAPS_PROGRESS="1", OMAPS_PRECOMPILE="0")
    check = [sys.executable, "-c", "from omaps.cli.precompile import FAMILIES, uncached; "
             "print(','.join(uncached(list(FAMILIES))))"]

    def run(argv):
        return subprocess.run(argv, env=env, capture_output=True, text=True, cwd=tmp_path)

    assert run(check).stdout.strip() == ",".join(FAMILIES)
    # the cheapest family to compile: the micromap baker's (tri2), about 9 s
    cmd = [sys.executable, "-m", "omaps", "eval", str(tmp_path / "leaf.png"), "--schemes", "tri2", "--quiet"]
    first = run(cmd)
    assert first.returncode == 0, first.stderr
    notes = [ln for ln in first.stderr.splitlines() if "compiling numba kernels for first use" in ln]
    assert len(notes) == 1 and notes[0].endswith(")") and "micromap" in notes[0], first.stderr
    second = run(cmd)
    assert second.returncode == 0 and "compiling" not in second.stderr, second.stderr
    still = run(check).stdout.strip().split(",")
    assert "micromap" not in still and "square" in still and "vq4" in still and "trace" in still
