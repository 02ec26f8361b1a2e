"""Regenerate every image in docs/img from omaps itself, on the shared test data.

    python docs/scripts/images.py                  # all four (a few minutes: the forest trace)
    python docs/scripts/images.py --only leaves    # one or more: leaves, savings, forest
    python docs/scripts/images.py --out /tmp/img   # somewhere else than docs/img

What makes each image (the same commands as the README's):

* ``leaves_maps.png``: the embedded procedural ``leaves.png`` texture and its maps (``tri3``,
  ``sq16``, ``sq64``, ``texel``), the picture ``omaps eval --show`` draws for it
  (``omaps.corpus.report.show_texture``), each map's number the share of the pair's area whose
  state is T or O ("known", the savings).
* ``savings_shared_corpus.png``: ``omaps eval ../shared/data/textures --min-size 64 --quiet --plot
  savings_shared_corpus.png --schemes sq4,...,texel`` (the 46 real textures of at least 64 px,
  every scheme of ``SAVINGS_SCHEMES``): mean savings against bits per pair.
* ``forest_heatmap.png`` and ``forest_render.png``: one ``omaps trace ../shared/data/scenes/forest.glb
  --shadows --heatmap forest_heatmap.png --render forest_render.png`` (512x512, the default camera
  and schemes, ``omaps.trace.experiment.DEFAULT_SCHEMES``): alpha tests per pixel, a primary ray and,
  where it hits, a shadow ray per pixel (the shadow rays test every C candidate: not deferred),
  and the alpha-tested render lit by the same light.

The PNGs are written smaller than matplotlib writes them: charts and the heat map as 256-colour
palette images, the render losslessly recompressed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
IMG = DOCS / "img"
DATA = ROOT.parent / "shared" / "data"
TEXTURES = DATA / "textures"
FOREST = DATA / "scenes" / "forest.glb"

LEAVES_SCHEMES = ["tri3", "sq16", "sq64", "texel"]


def _savings_schemes() -> list[str]:
    """The uncompressed squares and micromaps, every codec of the registry with its default
    encoder and, where it has it, the deck's (``-paper``), and ``texel``."""
    from omaps.codecs import codec_names
    from omaps.schemes import codec_variants

    codecs = [s for c in codec_names() for s in [c] + ([f"{c}-paper"] if "paper" in codec_variants(c) else [])]
    return ["sq4", "sq8", "sq16", "sq32", "sq64", "tri2", "tri3", "tri4", "tri5", *codecs, "texel"]


SAVINGS_SCHEMES = _savings_schemes()
IMAGES = {"leaves": ["leaves_maps.png"], "savings": ["savings_shared_corpus.png"],
          "forest": ["forest_heatmap.png", "forest_render.png"]}


def _compact(path: Path, palette: bool) -> None:
    """Rewrite a PNG smaller: a 256-colour palette (charts, the heat map) or just recompressed."""
    from PIL import Image

    img = Image.open(path).convert("RGB")
    if palette:
        img = img.quantize(256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    tmp = path.with_suffix(".tmp.png")
    img.save(tmp, format="PNG", optimize=True)
    os.replace(tmp, path)


def leaves(out: Path) -> None:
    from omaps.corpus import EvalConfig, default_corpus, evaluate_texture
    from omaps.corpus.report import show_texture
    from omaps.schemes import parse_schemes

    tex = next(t for t in default_corpus() if t.name == "leaves.png")
    r = evaluate_texture(tex, parse_schemes(",".join(LEAVES_SCHEMES)), EvalConfig(), keep_maps=True)
    show_texture(out / "leaves_maps.png", r)
    _compact(out / "leaves_maps.png", palette=True)


def savings(out: Path, jobs: int | None) -> None:
    from omaps.cli import main

    args = ["eval", str(TEXTURES), "--min-size", "64", "--quiet", "--plot", str(out / "savings_shared_corpus.png"),
            "--schemes", ",".join(SAVINGS_SCHEMES)]
    if jobs:
        args += ["--jobs", str(jobs)]
    if main(args) != 0:
        raise SystemExit("omaps eval failed")
    _compact(out / "savings_shared_corpus.png", palette=True)


def forest(out: Path, jobs: int | None) -> None:
    from omaps.cli import main

    args = ["trace", str(FOREST), "--shadows", "--quiet", "--heatmap", str(out / "forest_heatmap.png"),
            "--render", str(out / "forest_render.png"), "--json", str(out / "forest_trace.json")]
    if jobs:
        args += ["--jobs", str(jobs)]
    if main(args) != 0:
        raise SystemExit("omaps trace failed")
    os.remove(out / "forest_trace.json")
    _compact(out / "forest_heatmap.png", palette=True)
    _compact(out / "forest_render.png", palette=False)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", default=",".join(IMAGES), help="comma-separated: " + ", ".join(IMAGES))
    p.add_argument("--out", default=str(IMG), help="folder for the images (default: docs/img)")
    p.add_argument("--jobs", type=int, default=None, help="worker processes for eval and trace (default: all)")
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    only = [k.strip() for k in a.only.split(",") if k.strip()]
    bad = [k for k in only if k not in IMAGES]
    if bad:
        p.error(f"unknown image(s) {', '.join(bad)}: choose from {', '.join(IMAGES)}")
    if {"savings", "forest"} & set(only) and not DATA.is_dir():
        p.error(f"the shared test data is missing: {DATA}")
    for k in only:
        t0 = time.perf_counter()
        if k == "leaves":
            leaves(out)
        elif k == "savings":
            savings(out, a.jobs)
        else:
            forest(out, a.jobs)
        for name in IMAGES[k]:
            print(f"{out / name}: {(out / name).stat().st_size / 1024:.0f} KiB ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
