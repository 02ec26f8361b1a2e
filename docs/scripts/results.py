"""Generate the results page (docs/results.md) from a run of omaps on the shared test data.

    python docs/scripts/results.py                 # run everything (a few minutes), then render
    python docs/scripts/results.py --render-only   # re-render docs/results.md from docs/results.json

The run: ``omaps eval`` over the real textures of at least 64 px in ``../shared/data/textures``
with every scheme the tables show; ``omaps trace`` of ``forest.glb`` (512x512, shadows, every
2-state rule); ``omaps omm`` of ``palm.glb``, ``smallpine`` and ``forest.glb`` (level 4,
4-state), of palm through VQ2 and sq16 pair maps, and palm's baked .glb traced with its own
micromaps. The figures the page shows are kept in ``docs/results.json`` (written by the run,
committed with the page); rendering is a pure function of that file, so the tests check that
the page is what this script renders from it (tests/test_readme.py).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from omaps.codecs import codec_names, get_codec
from omaps.schemes import codec_variants
from omaps.trace.experiment import DEFAULT_SCHEMES

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
RESULTS_JSON = DOCS / "results.json"
RESULTS_MD = DOCS / "results.md"

# the uncompressed square and micromap schemes of the corpus table
BASE = ["sq4", "sq8", "sq16", "sq32", "sq64", "tri2", "tri3", "tri4", "tri5", "texel"]


def _codecs() -> list[tuple[str, str, str]]:
    """Every codec of the registry at every variant: (scheme, codec family, encoder shown)."""
    out = []
    for c in codec_names():
        default = get_codec(c).default_effort
        out += [(c, c, f"{v} (default)") if v == default else (f"{c}-{v}", c, v) for v in codec_variants(c)]
    return out


def same_bits(bits: int) -> str | None:
    """The uncompressed scheme of ``bits`` per pair: sqN (2·N² bits), else triL (4^(L+1) bits)."""
    for n in (1 << k for k in range(8)):
        if 2 * n * n == bits:
            return f"sq{n}"
    for level in range(13):
        if 4 ** (level + 1) == bits:
            return f"tri{level}"
    return None


# every codec at every encoder: (scheme, codec family, encoder shown)
CODECS = _codecs()
# a codec -> its lossless square (its map size); its bits -> the uncompressed scheme of the same bits
LOSSLESS = {c: f"sq{get_codec(c).map_size}" for c in dict.fromkeys(fam for _, fam, _ in CODECS)}
SAME_BITS = {b: same_bits(b) for b in sorted({get_codec(c).bits for c in LOSSLESS})}
# the forest trace: the command's default schemes
TRACE_SCHEMES = DEFAULT_SCHEMES.split(",")
TWO_STATE_RULES = ["nearest", "opaque", "transparent", "hashed"]


def _omaps(*args: str, cwd: Path) -> None:
    cmd = [str(Path(sys.executable).with_name("omaps")), *args, "--quiet"]
    print("+ omaps " + " ".join(args), file=sys.stderr, flush=True)
    env = dict(os.environ)
    env.pop("OMAPS_PROGRESS", None)
    r = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL)
    if r.returncode != 0:
        raise SystemExit(f"omaps {' '.join(args)}: exit {r.returncode}")


def run(shared: Path, work: Path) -> dict:
    """Run the commands and keep the figures the page shows."""
    tex, scenes = shared / "data" / "textures", shared / "data" / "scenes"
    started = time.time()
    schemes = BASE + [s for s, _, _ in CODECS]
    _omaps("eval", str(tex), "--min-size", "64", "--schemes", ",".join(schemes), "--json", "eval.json", cwd=work)
    ev = json.loads((work / "eval.json").read_text())
    mean = {s: {"savings": v["savings"], "bits": v["bits"]} for s, v in ev["mean"].items()}

    def per_texture(s):
        return [t["schemes"][s]["savings"] if "schemes" in t else t[s] for t in ev["textures"]]

    vs_vq4 = {}
    for c in ("vq4-synth", "wavelet3"):
        a, b = per_texture(c), per_texture("vq4")
        vs_vq4[c] = {"above": sum(x > y + 1e-12 for x, y in zip(a, b)),
                     "below": sum(x < y - 1e-12 for x, y in zip(a, b))}

    _omaps("trace", str(scenes / "forest.glb"), "--schemes", ",".join(TRACE_SCHEMES), "--shadows",
           "--two-state", "all", "--json", "forest.json", cwd=work)
    tr = json.loads((work / "forest.json").read_text())
    keys = ["alpha_tests_per_primary_ray", "alpha_tests_per_shadow_ray", "deferred_alpha_tests_per_shadow_ray",
            "differing_pixels", "differing_shadow_rays", "map_bytes"]
    forest = {"size": [tr["camera"]["width"], tr["camera"]["height"]],
              "triangles": tr["scene"]["triangles"], "alpha_triangles": tr["scene"]["alpha_triangles"],
              "instances": tr["scene"]["instances"],
              "schemes": {s: {k: tr["schemes"][s][k] for k in keys} for s in TRACE_SCHEMES},
              "two_state": {s: {r: {k: v[r][k] for k in ("differing_fraction", "stopped_early_fraction",
                                                          "passed_through_fraction")} for r in TWO_STATE_RULES}
                            for s, v in tr["two_state"].items()}}

    omm = {}
    for name, path, extra in [("palm.glb", scenes / "palm.glb", []),
                              ("smallpine", scenes / "smallpine" / "scene.gltf", []),
                              ("forest.glb", scenes / "forest.glb", []),
                              ("palm.glb, --from vq2", scenes / "palm.glb", ["--from", "vq2"]),
                              ("palm.glb, --from sq16", scenes / "palm.glb", ["--from", "sq16"])]:
        out = work / f"omm{len(omm)}"
        _omaps("omm", str(path), "-o", str(out), *extra, cwd=work)
        st = json.loads((out / "omm.json").read_text())["statistics"]
        omm[name] = {k: st[k] for k in ("triangles", "micromaps", "data_bytes", "known_area_fraction")}

    _omaps("omm", str(scenes / "palm.glb"), "-o", "palm_omm.glb", cwd=work)
    _omaps("trace", "palm_omm.glb", "--schemes", "none,omm,tri4", "--size", "256", "--json", "palm.json", cwd=work)
    pt = json.loads((work / "palm.json").read_text())
    palm_trace = {s: {k: pt["schemes"][s][k] for k in ("alpha_tests_per_primary_ray", "differing_pixels")}
                  for s in ("none", "omm", "tri4")}

    from omaps import __version__

    return {"generated_by": "docs/scripts/results.py", "omaps": __version__,
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "run_seconds": round(time.time() - started),
            "corpus": {"textures": len(ev["textures"]), "min_size": 64, "mode": ev["settings"]["mode"],
                       "filter": ev["settings"]["filter"], "mean": mean, "vs_vq4": vs_vq4},
            "forest": forest, "omm": omm, "palm_omm_trace": palm_trace}


# ---- rendering: a pure function of the figures ----

def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]


def _pct(x: float, digits: int = 1) -> str:
    return f"{100 * x:.{digits}f} %"


def corpus_table(r: dict) -> list[str]:
    """The corpus table (also in README.md, which the tests compare with it)."""
    mean = r["corpus"]["mean"]
    bits = ["2·W·H" if s == "texel" else str(mean[s]["bits"]) for s in BASE]
    return _table(["scheme"] + BASE, [["bits per pair"] + bits,
                                      ["mean savings"] + [f"{mean[s]['savings']:.3f}" for s in BASE]])


def _and(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _same_bits_text(rows) -> str:
    """``tri3 for 256 bits, sq16 for 512, ...``: the codecs' bits of ``rows`` (``CODECS``)."""
    bits = sorted({get_codec(fam).bits for _, fam, _ in rows})
    return ", ".join(f"{SAME_BITS[b]} for {b}{' bits' if i == 0 else ''}" for i, b in enumerate(bits))


def _lossless_text(rows) -> str:
    """``sq16 for vq2, sq32 for vq4 and vq4-synth, ...``: each lossless square and its codecs."""
    by: dict[str, list[str]] = {}
    for fam in dict.fromkeys(fam for _, fam, _ in rows):
        by.setdefault(LOSSLESS[fam], []).append(fam)
    return ", ".join(f"{sq} for {_and(fams)}" for sq, fams in by.items())


def render(r: dict) -> str:
    c, mean = r["corpus"], r["corpus"]["mean"]
    sav = {s: v["savings"] for s, v in mean.items()}
    shown = [row for row in CODECS if row[0] in mean]  # the registry's codec schemes the run has figures of
    out = ["<!-- GENERATED by docs/scripts/results.py from docs/results.json: do not edit by hand;",
           "     run `python docs/scripts/results.py` (or `--render-only`) to regenerate. -->", "",
           "# Results", "",
           f"Every figure on this page comes from one run of `docs/scripts/results.py` (omaps {r['omaps']}, "
           f"{r['run_seconds']} s on {r['machine']}, a shared machine) on the shared test data (`../shared/data`: real game "
           "textures and scenes, third-party, not part of the repository). Re-run it to check them.", "",
           "## Savings on the texture corpus", "",
           f"The {c['textures']} real textures of at least {c['min_size']} px (`{c['mode']}` mode: T if "
           f"alpha ≤ 30, O if alpha ≥ 225; `{c['filter']}` filter), each mapped to a pair of triangles "
           "covering the whole texture. *Savings* is the fraction of hits that need no any-hit shader "
           "(see [Concepts](concepts.md#savings)):", "",
           "```console", "omaps eval ../shared/data/textures --min-size 64 --json out/r.json", "```", ""]
    out += corpus_table(r)
    out += ["", f"Higher resolution saves more, with diminishing gains; a square map over the pair beats the "
            f"two per-triangle micromaps of the same storage (sq16 / tri3 = {sav['sq16'] / sav['tri3']:.2f}, "
            "512 against 256 bits; sq32 against tri4, 2048 against 1024 bits: "
            f"{sav['sq32'] / sav['tri4']:.2f}). `texel` is the limit of a map with one region per texel.", "",
            "![Mean savings against bits per pair on the shared corpus](img/savings_shared_corpus.png)", "",
            "## Compressed square maps", "",
            "Same corpus, every codec at every encoder. *× same bits* compares with the uncompressed scheme "
            f"of the same storage ({_same_bits_text(shown)}); *kept* is the share of "
            f"the savings of the codec's own lossless map ({_lossless_text(shown)}). The codecs never lose "
            "conservativeness: a stored map only turns known cells into C.", ""]
    rows = []
    for s, fam, enc in shown:
        b = mean[s]["bits"]
        rows.append([f"`{s}`", enc, str(b), f"{sav[s]:.4f}", f"{sav[s] / sav[SAME_BITS[b]]:.3f}",
                     _pct(sav[s] / sav[LOSSLESS[fam]])])
    out += _table(["scheme", "encoder", "bits per pair", "mean savings", "× same bits", "kept"], rows)
    vs = c["vs_vq4"]
    out += ["", "Textures where the two newer 512-bit codecs save more / less than `vq4` (default efforts): "
            f"`vq4-synth` {vs['vq4-synth']['above']} / {vs['vq4-synth']['below']}, "
            f"`wavelet3` {vs['wavelet3']['above']} / {vs['wavelet3']['below']} "
            f"(of {c['textures']}).", ""]

    f = r["forest"]
    w, h = f["size"]
    sch = f["schemes"]
    out += ["## Ray tracing a forest", "",
            f"`forest.glb`: {f['instances']} instances, {f['triangles']:,} triangles "
            f"({f['alpha_triangles']:,} alpha-tested), the default grazing camera, {w}×{h}, shadow rays to a "
            "directional light:", "",
            "```console", "omaps trace ../shared/data/scenes/forest.glb --shadows --two-state all --json out/forest.json",
            "```", ""]
    none = sch["none"]["alpha_tests_per_primary_ray"]
    rows = [["alpha tests / primary ray"] + [f"{sch[s]['alpha_tests_per_primary_ray']:.3f}" for s in TRACE_SCHEMES],
            ["× fewer than none"] + [f"{none / sch[s]['alpha_tests_per_primary_ray']:.2f}" for s in TRACE_SCHEMES],
            ["alpha tests / shadow ray (deferred C)"]
            + [f"{sch[s]['alpha_tests_per_shadow_ray']:.2f} ({sch[s]['deferred_alpha_tests_per_shadow_ray']:.2f})"
               for s in TRACE_SCHEMES],
            ["map KiB"] + [f"{sch[s]['map_bytes'] / 1024:,.0f}" for s in TRACE_SCHEMES],
            ["differing pixels, shadow rays"] + [f"{sch[s]['differing_pixels']}, {sch[s]['differing_shadow_rays']}"
                                                 for s in TRACE_SCHEMES]]
    out += _table([""] + [f"`{s}`" for s in TRACE_SCHEMES], rows)
    out += ["", "Every scheme gives exactly the image of `none` (every candidate alpha-tested): the maps are "
            "conservative. *Deferred C* looks for an O hit first and tests the C candidates only if there is "
            "none (shadow rays need any hit, not the nearest).", "",
            "![Alpha tests per pixel on forest.glb, none beside each scheme on one colour scale](img/forest_heatmap.png)",
            "", "*Alpha tests per pixel on `forest.glb` (`--heatmap` of a `--shadows` run: primary and shadow "
            "rays together), `none` beside each scheme on one colour scale. The alpha-tested render "
            "(`--render`) is [img/forest_render.png](img/forest_render.png).*", "",
            "### 2-state: C cells resolved to O or T", "",
            "`--two-state all` also traces each square and codec map with its C cells resolved, so that no ray "
            "runs the any-hit shader. That is not exact: the share of pixels whose visible hit differs from "
            "`none` (stopped early / passed through):", ""]
    rows = []
    for s, rules in f["two_state"].items():
        rows.append([f"`{s}`"] + [f"{_pct(v['differing_fraction'])} ({_pct(v['stopped_early_fraction'])} / "
                                  f"{_pct(v['passed_through_fraction'])})" for v in (rules[k] for k in TWO_STATE_RULES)])
    out += _table(["map"] + TWO_STATE_RULES, rows)
    out += ["", "The majority rule (`nearest`) differs least per pixel; `hashed` stops about as many rays early as "
            "it lets through, which keeps the average coverage; finer maps make either far better.", "",
            "## Standard opacity micromaps", "",
            "`omaps omm SCENE -o DIR` at level 4, 4-state; *known area* is the share of the alpha-tested "
            "triangles' area whose micro-triangles are T or O (the rest run the any-hit shader). With "
            "`--from`, each pair of triangles stores a square map through the codec, expanded to micromaps.", ""]
    rows = [[f"`{n}`", f"{v['triangles']:,}", f"{v['micromaps']:,}", f"{v['data_bytes']:,}",
             _pct(v["known_area_fraction"])] for n, v in r["omm"].items()]
    out += _table(["input", "triangles baked", "micromaps after reuse", "data bytes", "known area"], rows)
    p = r["palm_omm_trace"]
    pn = p["none"]["alpha_tests_per_primary_ray"]
    out += ["", "Identical micromaps are stored once, and uniform triangles take special indices, so foliage "
            "cards repeated across a scene cost little.", "",
            "Palm's micromaps written into the scene (`omaps omm palm.glb -o palm_omm.glb`, the "
            "`EXT_mesh_opacity_micromap` extension) and traced from the file (`omaps trace palm_omm.glb "
            "--schemes none,omm,tri4 --size 256`):", ""]
    out += _table(["", "`none`", "`omm` (from the file)", "`tri4` (baked by the tracer)"],
                  [["alpha tests / primary ray"] + [f"{p[s]['alpha_tests_per_primary_ray']:.3f}" for s in
                                                    ("none", "omm", "tri4")],
                   ["× fewer than none"] + [f"{pn / p[s]['alpha_tests_per_primary_ray']:.2f}" for s in
                                            ("none", "omm", "tri4")],
                   ["differing pixels"] + [str(p[s]["differing_pixels"]) for s in ("none", "omm", "tri4")]])
    out.append("")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--render-only", action="store_true", help="re-render docs/results.md from docs/results.json")
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared", help="the shared folder (../shared)")
    args = ap.parse_args(argv)
    if not args.render_only:
        if not (args.shared / "data" / "textures").is_dir():
            raise SystemExit(f"{args.shared / 'data'} not found: the results need the shared test data")
        with tempfile.TemporaryDirectory() as tmp:
            figures = run(args.shared.resolve(), Path(tmp))
        RESULTS_JSON.write_text(json.dumps(figures, indent=1) + "\n", encoding="utf-8")
    RESULTS_MD.write_text(render(json.loads(RESULTS_JSON.read_text(encoding="utf-8"))), encoding="utf-8")
    print(f"wrote {RESULTS_MD.relative_to(ROOT)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
