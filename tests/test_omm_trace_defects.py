"""``omaps omm`` and ``omaps trace`` messages and figures: the scene-file rule both commands share,
the --from choices derived from what is accepted, the summary's counts of what the output holds,
the opaque-relative speed from repeated side-by-side timings, and the progress of a --budget
bake."""

import json
import re

import numpy as np
import pytest
from PIL import Image

import omm_decoder
from gltf_files import png_bytes, write_quad_gltf
from omaps.cli import main
from omaps.errors import InputError


# ---- a scene must be .gltf or .glb: one rule, in the scene loader ---------------------------

SCENE_RULE = "a scene must end in .gltf, .glb, .usd, .usda, .usdc or .usdz"


def test_scene_loader_names_the_file_and_the_suffix_rule(tmp_path):
    from omaps.scene import load_scene

    png = tmp_path / "leaf.png"
    png.write_bytes(png_bytes(np.full((4, 4), 255, np.uint8)))
    with pytest.raises(InputError) as e:
        load_scene(png)
    assert e.value.path == str(png) and SCENE_RULE in e.value.problem
    assert "UnicodeDecodeError" not in str(e.value)


@pytest.mark.parametrize("command", ["trace", "omm"])
def test_trace_and_omm_reject_a_non_gltf_scene_alike(tmp_path, capsys, command):
    png = tmp_path / "leaf.png"
    png.write_bytes(png_bytes(np.full((4, 4), 255, np.uint8)))
    out = tmp_path / "out"
    args = ["trace", str(png), "--json", str(out) + ".json", "--quiet"] if command == "trace" else \
        ["omm", str(png), "-o", str(out), "--quiet"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"{png}:" in err and SCENE_RULE in err, err
    assert "UnicodeDecodeError" not in err and "cannot read glTF" not in err
    assert not out.exists() and not (tmp_path / "out.json").exists()


# ---- omm --from: the choices in the message are the accepted ones ---------------------------

def _listed(message: str) -> set[str]:
    """Every scheme name the --from message lists (``sqN: N = 1, 2, ...`` and ``base[-a|-b]``)."""
    inside = message[message.index("(") + 1:message.index("), not")]
    names = set()
    m = re.search(r"csmL, L = (\d+) \.\. (\d+)", inside)
    if m:
        names |= {f"csm{lv}" for lv in range(int(m.group(1)), int(m.group(2)) + 1)}
        inside = inside[:m.start()]
    m = re.search(r"sqN, N = ([\d, or]+)", inside)
    if m:
        names |= {f"sq{n}" for n in re.findall(r"\d+", m.group(1))}
    for base, variants in re.findall(r"([a-z][\w-]*)\[((?:-\w+\|?)+)\]", inside):
        names.add(base)
        names |= {base + v for v in variants.split("|")}
    for word in re.findall(r"(?<![\w\[|-])([a-z][\w-]*\d[\w-]*)(?![\w\[-])", inside):  # a bare codec name
        if not word.startswith("sq"):
            names.add(word)
    return names


def _accepted(source: str) -> bool:
    from omaps.omm.pipeline import OmmSettings

    try:
        OmmSettings(source=source)
    except InputError:
        return False
    return True


def test_from_message_lists_exactly_the_accepted_schemes(tex_and_uvs, tmp_path, capsys):
    from omaps.codecs.registry import codec_names
    from omaps.schemes import VARIANTS

    png, uvs, _, _ = tex_and_uvs
    out = tmp_path / "o"
    assert main(["omm", str(png), str(uvs), "-o", str(out), "--from", "tri3"]) == 2
    err = capsys.readouterr().err
    assert "--from takes texture, a square scheme" in err and "'tri3'" in err
    listed = _listed(err.strip().splitlines()[-1])
    assert {"sq1", "sq16", "sq128", "vq2", "vq4-paper", "vq4-synth", "wavelet3-fast", "csm0", "csm12"} <= listed, listed
    for name in listed:  # every scheme listed is accepted ...
        assert _accepted(name), name
    candidates = {f"sq{n}" for n in range(0, 260)} | {"tri3", "none", "texel", "omm", "file:vq2", "budget:1000"}
    candidates |= {f"{kind}{lv}" for kind in ("csm", "succinct", "tri") for lv in range(-1, 15)}
    for c in codec_names() + ["vq8", "sq"]:
        candidates |= {c} | {f"{c}-{v}" for v in VARIANTS + ("best", "slow")}
    accepted = {c for c in candidates if _accepted(c)}
    assert accepted == listed, (accepted - listed, listed - accepted)  # ... and every accepted one is listed
    assert not out.exists()


def test_every_listed_from_codec_bakes(tex_and_uvs, tmp_path):
    """The listed codecs (and the smallest and largest raw maps) really bake (fast effort)."""
    from omaps.codecs.registry import codec_names

    png, uvs, _, _ = tex_and_uvs
    for source in ["sq1", "sq128"] + codec_names():
        out = tmp_path / source
        assert main(["omm", str(png), str(uvs), "-o", str(out), "--from", source, "--effort", "fast",
                     "--quiet"]) == 0, source
        assert (out / "pair_blocks.bin").is_file()


# ---- omm's summary line: what the output holds ------------------------------------------------

def _output_counts(folder) -> np.ndarray:
    """Micro-triangles of each OMM state (0..3) over every triangle, read back independently."""
    counts = np.zeros(4, np.int64)
    data, records, index, summary, _ = omm_decoder.read_folder(folder)
    level = summary["statistics"]["levels"]
    assert len(level) == 1
    n = 4 ** int(next(iter(level)))
    for lv, s in omm_decoder.triangle_states(folder):
        s = np.array(s * (n if lv is None else 1))
        counts += np.bincount(s, minlength=4)
    return counts


@pytest.mark.parametrize("fmt", ["4state", "2state"])
@pytest.mark.parametrize("promote", ["nearest", "opaque", "transparent", "hashed"])
def test_summary_counts_what_the_output_holds(tex_and_uvs, tmp_path, capsys, fmt, promote):
    png, uvs, _, _ = tex_and_uvs
    out = tmp_path / "o"
    assert main(["omm", str(png), str(uvs), "-o", str(out), "--level", "3", "--format", fmt,
                 "--promote", promote, "--quiet"]) == 0
    line = capsys.readouterr().out
    m = re.search(r"\((\d+) T, (\d+) O, (\d+) unknown", line)
    assert m, line
    t, o, unknown = map(int, m.groups())
    held = _output_counts(out)
    st = json.loads((out / "omm.json").read_text())["statistics"]
    assert st["unknown"] > 0  # the bake has unknown micro-triangles to resolve
    assert (t, o, unknown) == (held[0], held[1], held[2] + held[3]), line
    if fmt == "2state":
        assert unknown == 0
        m = re.search(r"(\d+) unknown resolved to 2 states by " + promote + r", (\d+) to T and (\d+) to O", line)
        assert m, line
        resolved, to_t, to_o = map(int, m.groups())
        assert resolved == st["unknown"] == to_t + to_o
        assert (to_t, to_o) == (st["unknown_resolved"]["transparent"], st["unknown_resolved"]["opaque"])
    else:
        assert "resolved" not in line


# ---- trace: the opaque-relative speed is the best of side-by-side repeats --------------------

class _Part:
    def __init__(self, seconds):
        self.seconds = seconds


class _Run:
    def __init__(self, p, s=None):
        self.primary = _Part(p)
        self.shadow = None if s is None else _Part(s)


def test_timing_rounds_interleave_and_keep_the_best():
    from omaps.trace.timing import time_side_by_side

    calls = []
    script = {"a": iter([(5.0, 1.0), (2.0, 0.5), (3.0, 0.1)]), None: iter([(4.0, 1.0), (1.0, 1.0), (9.0, 9.0)])}

    def trace_once(name):
        calls.append(name)
        return _Run(*next(script[name]))

    runs = {"a": _Run(7.0, 2.0), None: _Run(6.0, 1.0)}  # the counting runs: round one
    samples = time_side_by_side(runs, trace_once, rounds=4)
    assert calls == ["a", None, "a", None, "a", None]  # side by side, round after round
    assert samples["a"] == [9.0, 6.0, 2.5, 3.1] and samples[None] == [7.0, 5.0, 2.0, 18.0]
    assert (runs["a"].primary.seconds, runs["a"].shadow.seconds) == (2.0, 0.5)  # the best round
    assert (runs[None].primary.seconds, runs[None].shadow.seconds) == (1.0, 1.0)


def test_trace_speed_column_is_the_best_of_repeats(tmp_path, capsys, rng):
    alpha = (rng.random((8, 8)) < 0.5).astype(np.uint8) * 255
    f = write_quad_gltf(tmp_path / "q.gltf", alpha)
    j = tmp_path / "t.json"
    assert main(["trace", str(f), "--schemes", "none,sq8,vq2", "--size", "24", "--shadows", "--quiet",
                 "--json", str(j), "--camera", "0.5,0.5,2:0.5,0.5,0:40"]) == 0
    out = capsys.readouterr().out
    rep = json.loads(j.read_text())
    o = rep["opaque_only"]
    assert o["timing"]["rounds"] >= 3 and len(o["timing"]["seconds"]) == o["timing"]["rounds"]
    opaque_rate = o["timing"]["rays"] / min(o["timing"]["seconds"])
    assert o["rays_per_second"] == pytest.approx(opaque_rate)
    rows = {line.split()[0]: line.split() for line in out.splitlines()}
    assert rows["scheme"][-4:] == ["x", "opaque", "map", "KiB"]  # x opaque: a row's last cell but one
    for n in ("none", "sq8", "vq2"):
        r = rep["schemes"][n]
        assert len(r["timing"]["seconds"]) == r["timing"]["rounds"] == o["timing"]["rounds"]
        rate = r["timing"]["rays"] / min(r["timing"]["seconds"])
        assert r["rays_per_second"] == pytest.approx(rate)
        assert r["rays_per_second_over_opaque"] == pytest.approx(rate / opaque_rate)
        assert rows[n][-2].rstrip("*") == f"{rate / opaque_rate:.2f}"


# ---- omm --budget: the progress bar -------------------------------------------------------------

class _Recorder:
    def __init__(self):
        self.events = []

    def stage(self, name, total, unit):
        self.events.append(("stage", name, total, unit))

    def advance(self, n=1):
        self.events.append(("advance", n))


def _stages(events):
    out = []
    for e in events:
        if e[0] == "stage":
            out.append([e[1], e[2], e[3], []])
        else:
            out[-1][3].append(e[1])
    return out


def test_budget_progress_totals_are_known_from_the_start(tex_and_uvs, monkeypatch):
    from omaps.alpha_test import StateRule
    from omaps.omm import Geometry, OmmSettings, budget, build, pipeline
    from omaps.texture import AlphaTexture

    monkeypatch.setattr(budget, "PROGRESS_CHUNK", 64)  # the pricing's bakes in pieces: the same states

    _, _, a, tris = tex_and_uvs
    test = StateRule("cutoff").alpha_test(AlphaTexture("m", a, 255))
    geoms = [Geometry("g1", test, tris), Geometry("g2", test, tris[:5])]
    rec = _Recorder()
    plain = build(geoms, OmmSettings(budget=600))
    res = build(geoms, OmmSettings(budget=600), progress=rec)
    assert res.data.tobytes() == plain.data.tobytes() and np.array_equal(res.index, plain.index)
    stages = _stages(rec.events)
    assert [s[0] for s in stages] == ["pricing", "baking"]
    (_, p_total, p_unit, p_steps), (_, b_total, b_unit, b_steps) = stages
    assert p_unit == "micro-triangles" and p_total > 0 and sum(p_steps) == p_total and len(p_steps) > 2
    assert b_unit == "micro-triangles" and b_total == sum(b_steps) > 0
    rec = _Recorder()
    monkeypatch.setattr(pipeline, "CHUNK_MICRO_TRIANGLES", 40)  # several steps per geometry
    build(geoms, OmmSettings(level=2), progress=rec)
    distinct = len(np.unique(tris.reshape(len(tris), -1), axis=0))  # identical triangles baked once
    (name, total, unit, steps), = _stages(rec.events)
    distinct5 = len(np.unique(tris[:5].reshape(5, -1), axis=0))
    assert (name, unit, total) == ("baking", "micro-triangles", 16 * (distinct + distinct5))
    assert sum(steps) == total and len(steps) > 2 and all(s % 16 == 0 for s in steps)


def test_budget_progress_bar_reads_well(tex_and_uvs, tmp_path, capsys, monkeypatch):
    png, uvs, _, _ = tex_and_uvs
    monkeypatch.setenv("OMAPS_PROGRESS", "1")
    assert main(["omm", str(png), str(uvs), "-o", str(tmp_path / "o"), "--budget", "600"]) == 0
    err = capsys.readouterr().err
    assert "micro-triangles" in err and "geometries" not in err, err
    assert not re.search(r"\dgeometr", err), err
    def number(text):  # tqdm's scaled numbers: 189, 1.28k
        return float(text.rstrip("kMG")) * 1000 ** ("kMG".index(text[-1]) + 1 if text[-1] in "kMG" else 0)

    pairs = re.findall(r"([\d.]+[kMG]?)/([\d.]+[kMG]?)", err)
    assert pairs, err
    for n, total in pairs:
        assert number(n) <= number(total), err


# ---- counts take the noun's number --------------------------------------------------------------

def test_counts_in_omm_and_trace_lines_take_the_nouns_number(tmp_path, capsys, rng):
    a = np.full((8, 8), 255, np.uint8)
    a[:, :3] = 0
    Image.fromarray(a).save(tmp_path / "m.png")
    np.save(tmp_path / "one.npy", np.array([[[0.1, 0.1], [0.9, 0.1], [0.1, 0.9]]]))
    assert main(["omm", str(tmp_path / "m.png"), str(tmp_path / "one.npy"), "-o", str(tmp_path / "o"),
                 "--level", "0", "--no-special", "--quiet"]) == 0
    line = capsys.readouterr().out
    assert ": 1 triangle, 1 micro-triangle (" in line and "; 1 micromap after reuse" in line, line
    assert main(["omm", "--verify", str(tmp_path / "o")]) == 0
    assert "OK (1 triangle, 1 micromap, 1 data byte)" in capsys.readouterr().out
    f = write_quad_gltf(tmp_path / "q.gltf", (rng.random((8, 8)) < 0.5).astype(np.uint8) * 255)
    assert main(["trace", str(f), "--schemes", "none", "--size", "8", "--quiet",
                 "--camera", "0.5,0.5,2:0.5,0.5,0:40"]) == 0
    out = capsys.readouterr().out
    assert ": 1 instance of 1 mesh, 2 triangles (2 alpha-tested); 1 prototype pair," in out, out
    assert main(["trace", str(f), "--camera", "0.5,0.5,2:0.5,0.5,0:x", "--quiet"]) == 2
    assert "--camera fov: expected a number, got 'x'" in capsys.readouterr().err
