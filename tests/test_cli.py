import csv
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from conftest import TEXTURES, needs_shared
from omaps.cli import main
from omaps.schemes import DEFAULT_SCHEMES


@pytest.fixture
def textures(tmp_path, rng):
    d = tmp_path / "tex"
    d.mkdir()
    for i, (w, h) in enumerate([(40, 24), (64, 64), (17, 90)]):
        a = np.zeros((h, w), np.uint8)
        yy, xx = np.mgrid[0:h, 0:w]
        a[(xx - w / 2) ** 2 + (yy - h / 2) ** 2 < (min(w, h) / 2.5) ** 2] = 255
        a[(xx - w / 2) ** 2 + (yy - h / 2) ** 2 < (min(w, h) / 5) ** 2] = 100
        Image.fromarray(a).save(d / f"t{i}.png")
    return d


def test_default_corpus_runs(capsys):
    assert main(["eval", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "embedded procedural corpus" in out and "MEAN savings (6)" in out


def test_outputs(tmp_path, textures, capsys):
    j, c, p, s = tmp_path / "r.json", tmp_path / "r.csv", tmp_path / "p.png", tmp_path / "show"
    assert main(["eval", str(textures), "--json", str(j), "--csv", str(c), "--plot", str(p),
                 "--show", str(s), "--jobs", "1"]) == 0
    data = json.loads(j.read_text())
    assert set(data) == {"settings", "textures", "mean", "unreadable"} and data["unreadable"] == []
    assert list(data["settings"]["schemes"]) == list(DEFAULT_SCHEMES)
    assert data["settings"]["mode"] == "levels" and data["settings"]["filter"] == "nearest"
    assert [t["name"] for t in data["textures"]] == ["t0.png", "t1.png", "t2.png"]
    t0 = data["textures"][0]
    assert set(t0) == {"name", "width", "height", "schemes"} and (t0["width"], t0["height"]) == (40, 24)
    assert list(t0["schemes"]) == list(DEFAULT_SCHEMES)
    assert t0["schemes"]["sq16"] == {"savings": pytest.approx(t0["schemes"]["sq16"]["savings"]), "bits": 512}
    assert t0["schemes"]["tri3"]["bits"] == 256 and t0["schemes"]["texel"]["bits"] == 2 * 40 * 24
    for name in DEFAULT_SCHEMES:
        m = np.mean([t["schemes"][name]["savings"] for t in data["textures"]])
        assert data["mean"][name]["savings"] == pytest.approx(m)
        assert 0 <= m <= 1
    rows = list(csv.DictReader(c.open()))
    assert len(rows) == 3 * len(DEFAULT_SCHEMES) + len(DEFAULT_SCHEMES)
    assert Image.open(p).size[0] > 300
    shown = sorted(x.name for x in s.iterdir())
    assert shown == ["000_t0.png", "001_t1.png", "002_t2.png", "show.json"]
    manifest = json.loads((s / "show.json").read_text())
    assert [p["file"] for p in manifest["pictures"]] == shown[:3]
    assert [p["texture"] for p in manifest["pictures"]] == ["t0.png", "t1.png", "t2.png"]
    assert manifest["settings"] == data["settings"]


def test_jobs_give_same_results(tmp_path, textures):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["eval", str(textures), "--jobs", "1", "--quiet", "--json", str(a)]) == 0
    assert main(["eval", str(textures), "--jobs", "2", "--quiet", "--json", str(b)]) == 0
    assert json.loads(a.read_text()) == json.loads(b.read_text())


def test_min_size_and_schemes(tmp_path, textures, capsys):
    j = tmp_path / "r.json"
    assert main(["eval", str(textures), "--min-size", "30", "--schemes", "sq8, tri3,sq8", "--json", str(j)]) == 0
    data = json.loads(j.read_text())
    assert [t["name"] for t in data["textures"]] == ["t1.png"]  # 40x24 and 17x90 are skipped
    assert list(data["mean"]) == ["sq8", "tri3"]
    assert "skipped 2 textures smaller than 30 px" in capsys.readouterr().err


@pytest.mark.parametrize("args, message", [
    (["--schemes", "sq12"], "power of two"),
    (["--schemes", "sq256"], "power of two"),
    (["--schemes", "tri13"], "triL level must be an integer from 0 to 12"),
    (["--schemes", "vq9"], "unknown scheme"),
    (["--mode", "cutoff", "--cutoff", "2"], "cutoff must be in"),
    (["--jobs", "0"], "--jobs"),
])
def test_bad_options(tmp_path, textures, capsys, args, message):
    j = tmp_path / "r.json"
    assert main(["eval", str(textures), "--json", str(j)] + args) == 2
    assert message in capsys.readouterr().err
    assert not j.exists()


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_bad_file_in_folder_goes_on(tmp_path, textures, capsys, jobs):
    """A file in a folder that cannot be read is skipped, listed at the end and in the JSON, and
    the run exits 1 with its outputs written; a bad file named on the command line is exit 2."""
    (textures / "b_broken.png").write_bytes(b"not a png")
    (textures / "zz_broken.png").write_bytes(b"")
    j, s = tmp_path / "r.json", tmp_path / "show"
    assert main(["eval", str(textures), "--json", str(j), "--show", str(s), "--jobs", jobs]) == 1
    out, err = capsys.readouterr()
    assert "MEAN savings (3)" in out
    assert "2 files could not be read" in err
    assert "b_broken.png: not an image" in err and "zz_broken.png" in err
    data = json.loads(j.read_text())
    assert [t["name"] for t in data["textures"]] == ["t0.png", "t1.png", "t2.png"]
    assert [os.path.basename(u["path"]) for u in data["unreadable"]] == ["b_broken.png", "zz_broken.png"]
    assert all(u["problem"] for u in data["unreadable"])
    assert len(list(s.glob("*.png"))) == 3
    # named explicitly, the same file is bad input: exit 2, nothing written
    j2 = tmp_path / "r2.json"
    assert main(["eval", str(textures / "t0.png"), str(textures / "b_broken.png"), "--json", str(j2),
                 "--jobs", jobs]) == 2
    err = capsys.readouterr().err
    assert "b_broken.png: not an image" in err and not j2.exists()
    assert [p for p in os.listdir(tmp_path) if p.startswith(".omaps")] == []


def test_folder_of_only_unreadable_files(tmp_path, capsys):
    (tmp_path / "a.png").write_bytes(b"junk")
    j = tmp_path / "r.json"
    assert main(["eval", str(tmp_path), "--json", str(j)]) == 2
    err = capsys.readouterr().err
    assert "a.png: not an image" in err and "no texture could be read" in err and not j.exists()


def test_missing_and_no_alpha(tmp_path, capsys):
    assert main(["eval", str(tmp_path / "missing.png")]) == 2
    assert "missing.png: no such file" in capsys.readouterr().err
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "rgb.png")
    assert main(["eval", str(tmp_path / "rgb.png")]) == 2
    assert "rgb.png: image has no alpha channel" in capsys.readouterr().err
    assert main(["eval", str(tmp_path / "rgb.png"), "--channel", "R", "--quiet"]) == 0


def test_folder_images_without_alpha_are_skipped_in_one_line(tmp_path, capsys):
    """In a folder (a glTF sample's, say) the images with no alpha channel -- screenshots, normal
    maps, a palette without transparency -- are not alpha masks: skipped, counted in one line
    naming one and why, not errors; the images with alpha, the asset's foliage too, are read."""
    y, x = np.mgrid[:32, :32]
    disc = np.where((x - 16) ** 2 + (y - 16) ** 2 < 144, 255, 0).astype(np.uint8)
    rgba = np.dstack([np.full((32, 32, 3), 90, np.uint8), disc])
    d = tmp_path / "scenes"
    (d / "asset").mkdir(parents=True)
    Image.fromarray(rgba).save(d / "leaf.png")
    Image.fromarray(rgba).save(d / "asset" / "foliage.png")
    Image.fromarray(rgba[..., :3]).save(d / "asset" / "screenshot.png")
    Image.fromarray(rgba[..., :3]).save(d / "asset" / "screenshot.jpg")
    Image.fromarray(rgba[..., :3]).convert("P").save(d / "asset" / "palette.png")
    (d / "asset" / "scene.gltf").write_text("{}")
    j = tmp_path / "r.json"
    assert main(["eval", str(d), "--quiet", "--jobs", "1", "--schemes", "sq4", "--json", str(j)]) == 0
    out, err = capsys.readouterr()
    assert "2 textures from 2 files" in out
    said = [line for line in err.splitlines() if "without alpha" in line]
    assert len(said) == 1 and "skipped 3 images without alpha" in said[0], err
    assert "palette.png (palette image without transparency)" in said[0], said  # the first found, and why
    assert "could not be read" not in err and "error" not in err
    assert sorted(os.path.basename(t["name"]) for t in json.loads(j.read_text())["textures"]) == [
        "foliage.png", "leaf.png"]
    # a band picked: every image is read
    assert main(["eval", str(d), "--quiet", "--jobs", "1", "--schemes", "sq4", "--channel", "R"]) == 0
    out, err = capsys.readouterr()
    assert "5 textures from 5 files" in out and "without alpha" not in err
    # only images without alpha: nothing to evaluate, said so (exit 2)
    assert main(["eval", str(d / "asset" / "screenshot.png"), str(d / "asset" / "palette.png")]) == 2
    assert "screenshot.png: image has no alpha channel" in capsys.readouterr().err
    for f in ("leaf.png", "asset/foliage.png"):
        (d / f).unlink()
    assert main(["eval", str(d), "--quiet", "--jobs", "1", "--schemes", "sq4"]) == 2
    assert "no image with an alpha channel found (3 images without one" in capsys.readouterr().err


def test_bake(tmp_path, textures, capsys):
    out = tmp_path / "m.npy"
    assert main(["bake", str(textures / "t1.png"), "--scheme", "sq16", "-o", str(out)]) == 0
    assert np.load(out).shape == (16, 16)
    uvs = np.array([[[0.1, 0.1], [0.9, 0.2], [0.5, 0.9]], [[0, 0], [2, 0], [0, 2]]])
    np.save(tmp_path / "uv.npy", uvs)
    assert main(["bake", str(textures / "t1.png"), "--scheme", "tri3", "--uvs", str(tmp_path / "uv.npy"),
                 "--wrap", "wrap", "-o", str(out)]) == 0
    assert np.load(out).shape == (2, 64)
    good = np.load(out)
    # a triangle with no UV area is baked (grown regions read the texels it touches)
    flat = uvs.copy()
    flat[1, 2] = flat[1, 1]
    np.save(tmp_path / "flat.npy", flat)
    out_flat = tmp_path / "flat_out.npy"
    assert main(["bake", str(textures / "t1.png"), "--scheme", "tri3", "--uvs", str(tmp_path / "flat.npy"),
                 "--wrap", "wrap", "-o", str(out_flat)]) == 0
    baked_flat = np.load(out_flat)
    assert baked_flat.shape == (2, 64)
    np.testing.assert_array_equal(baked_flat[0], good[0])
    bad = uvs.copy()
    bad[1, 2, 0] = np.nan
    np.save(tmp_path / "bad.npy", bad)
    out2 = tmp_path / "m2.npy"
    capsys.readouterr()
    assert main(["bake", str(textures / "t1.png"), "--scheme", "tri3", "--uvs", str(tmp_path / "bad.npy"),
                 "-o", str(out2)]) == 2
    err = capsys.readouterr().err
    assert "bad.npy: UV triangle 1 has NaN or infinite coordinates" in err and not out2.exists()


def test_console_script(tmp_path):
    r = subprocess.run([sys.executable, "-m", "omaps.cli", "eval", "--quiet", "--schemes", "sq4,tri1"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "MEAN" in r.stdout


@needs_shared
@pytest.mark.long
def test_real_corpus_eval(tmp_path):
    j = tmp_path / "real.json"
    assert main(["eval", str(TEXTURES), "--min-size", "64", "--quiet", "--json", str(j)]) == 0
    data = json.loads(j.read_text())
    assert len(data["textures"]) == 46


def test_show_picture_holds_every_panel(tmp_path):
    """An --show picture draws each scheme's map at its pixels: every T / O / C colour pixel of
    the picture belongs to a panel (the text is black and grey), as many as the panels hold."""
    from omaps import drawing, states
    from omaps.corpus.evaluate import evaluate_texture
    from omaps.corpus.report import show_texture
    from omaps.schemes import get_scheme
    from omaps.texture import load_alpha

    a = np.zeros((24, 40), np.uint8)
    a[4:20, 6:30] = 255
    a[8:12, 10:14] = 0
    names = ["sq4", "sq16", "tri3", "texel"]
    r = evaluate_texture(load_alpha(a), [get_scheme(n) for n in names], keep_maps=True)
    show_texture(tmp_path / "s.png", r, panel=96)
    pic = np.asarray(Image.open(tmp_path / "s.png").convert("RGB"))
    panels = [drawing.scheme_image(get_scheme(n).kind, r.maps[n], 96) for n in names]
    for colour in states.COLOURS:
        drawn = sum(int(np.all(p == colour, axis=2).sum()) for p in panels)
        assert drawn > 0 and int(np.all(pic == colour, axis=2).sum()) == drawn, colour


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="counts threads through Linux's /proc")
def test_command_line_keeps_numpy_to_one_blas_thread():
    """numpy's OpenBLAS would start a thread per further core that spins about 0.1 s of CPU; the
    command line asks for one (before numpy loads) unless the caller chose a number."""
    code = ("import os, sys, omaps.cli; assert 'numpy' not in sys.modules; import numpy; "
            "print(os.environ['OPENBLAS_NUM_THREADS'], len(os.listdir('/proc/self/task')))")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["1", "1"]
    out = subprocess.run([sys.executable, "-c", code], env=dict(env, OPENBLAS_NUM_THREADS="2"), capture_output=True,
                         text=True, check=True)
    assert out.stdout.split()[0] == "2"
