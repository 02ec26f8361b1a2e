"""omaps report: the page is one self-contained file whose numbers are the library's (the trace
table equals ``omaps trace --json`` for the same settings), and headless Chromium draws each
scheme's map states on the mesh without a console error or a request leaving the file."""

import io
import json
import re

import numpy as np
import pytest

from conftest import SCENES, needs_scenes
from gltf_files import write_quad_gltf
from omaps.cli.main import main
from omaps.report import build_report
from omaps.report.browser import find_chromium, open_page

CHROMIUM = find_chromium()
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (apt-get install chromium; "
                                    "or set OMAPS_CHROMIUM): the browser checks are skipped")
SCHEMES = "none,tri3,vq4"


def disc_alpha(n=64):
    y, x = np.mgrid[:n, :n]
    return np.where((x - n / 2 + 0.5) ** 2 + (y - n / 2 + 0.5) ** 2 < (0.4 * n) ** 2, 255, 0).astype(np.uint8)


@pytest.fixture(scope="module")
def quad(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    scene = d / "quad.gltf"
    write_quad_gltf(scene, disc_alpha(), material={"alphaMode": "MASK"})
    res = build_report(scene, d / "quad.html", SCHEMES, size=48, jobs=1)
    return scene, res


def table_values(html_text: str) -> dict:
    """Per scheme row, the exact alpha tests per primary ray (the second cell's data-v)."""
    out = {}
    for row in re.findall(r"<tr>(.*?)</tr>", html_text):
        cells = re.findall(r"<td(?: data-v=\"([^\"]*)\")?>(.*?)</td>", row)
        if len(cells) > 2 and cells[1][0]:
            out[cells[0][1]] = float(cells[1][0])
    return out


def self_contained(text: str) -> None:
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text, re.I)
    assert not re.search(r"url\(\s*['\"]?https?:", text, re.I)
    assert "<link" not in text.lower()
    assert 'type="module"' not in text  # one classic script each, nothing imported


def trace_json(scene, tmp_path, size) -> dict:
    out = tmp_path / "t.json"
    # (exit 1, a scheme changing a visible pixel, still writes the JSON: that check is test_trace's)
    assert main(["trace", str(scene), "--schemes", SCHEMES, "--size", str(size), "--jobs", "1", "--quiet",
                 "--json", str(out)]) in (0, 1)
    return json.loads(out.read_text())


def test_quad_page_numbers_are_trace_json(quad, tmp_path):
    scene, res = quad
    text = open(res.path, encoding="utf-8").read()
    self_contained(text)
    assert res.kind == "scene" and res.bytes == len(text.encode())
    ref = trace_json(scene, tmp_path, 48)
    shown = table_values(text)
    assert list(shown) == ["none", "tri3", "vq4"]
    for n in shown:
        assert shown[n] == ref["schemes"][n]["alpha_tests_per_primary_ray"] == \
            res.numbers["schemes"][n]["alpha_tests_per_primary_ray"]
    assert shown["none"] > shown["vq4"] > 0  # the maps save tests, and the disc's edge still needs some
    data = json.loads(re.search(r'<script id="omaps-data" type="application/json">(.*?)</script>', text,
                                re.S).group(1))
    assert data["trace"]["schemes"]["tri3"] == res.numbers["schemes"]["tri3"]
    assert [s["name"] for s in data["view"]["schemes"]] == ["none", "tri3", "vq4"]


def test_report_bad_input_exits_2_and_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "notes.txt"
    bad.write_text("x")
    out = tmp_path / "r.html"
    assert main(["report", str(bad), "-o", str(out)]) == 2
    assert "notes.txt" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "missing.glb"), "-o", str(out)]) == 2
    assert "missing.glb" in capsys.readouterr().err
    broken = tmp_path / "broken.glb"
    broken.write_bytes(b"not a glb")
    assert main(["report", str(broken), "-o", str(out), "--jobs", "1"]) == 2
    assert "broken.glb" in capsys.readouterr().err
    assert main(["report", str(tmp_path), "-o", str(tmp_path / "r.txt")]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.glb", "notes.txt"]


def test_corpus_report(tmp_path):
    from PIL import Image

    folder = tmp_path / "tex"
    folder.mkdir()
    Image.fromarray(disc_alpha(64)).save(folder / "disc.png")
    Image.fromarray(np.tile(np.repeat(np.array([0, 255], np.uint8), 8), (64, 4))).save(folder / "bars.png")
    out = tmp_path / "c.html"
    assert main(["report", str(folder), "-o", str(out), "--schemes", "sq8,tri2", "--jobs", "1", "--quiet"]) == 0
    text = out.read_text(encoding="utf-8")
    self_contained(text)
    data = json.loads(re.search(r'<script id="omaps-data" type="application/json">(.*?)</script>', text,
                                re.S).group(1))
    assert sorted(t["name"].rsplit("/", 1)[-1] for t in data["eval"]["textures"]) == ["bars.png", "disc.png"]
    assert text.count('class="sortable panel"') == 1 and text.count("alt=\"maps of ") == 2
    disc = next(t for t in data["eval"]["textures"] if t["name"].endswith("disc.png"))
    assert f'data-v="{disc["schemes"]["sq8"]["savings"]!r}"' in text


def state_pixels(png: bytes) -> dict:
    """Pixels near each state colour (shaded by at most 20 %)."""
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return {"T": int(((r < 40) & (g > 190) & (abs(g - b) < 25)).sum()),
            "O": int(((g < 40) & (r > 190) & (abs(r - b) < 25)).sum()),
            "C": int(((r < 40) & (b < 40) & (g > 150) & (g < 215)).sum())}


def look(path, schemes, shots=None):
    """Open a report, draw each scheme; per scheme the state pixels of the 3D canvas; the console
    errors and every request."""
    counts = {}
    with open_page(CHROMIUM, path, 1100, 900) as p:
        p.wait("window.omapsReport && window.omapsReport.ready", 300)
        rect = p.evaluate("(() => { const c = document.getElementById('view3d'); c.scrollIntoView(); "
                          "const r = c.getBoundingClientRect(); return {x: r.x + scrollX, y: r.y + scrollY, "
                          "width: r.width, height: r.height}; })()")
        for name in schemes:
            n = p.evaluate("window.omapsReport.frames")
            p.evaluate(f"window.omapsReport.setScheme({json.dumps(name)})")
            p.wait(f"window.omapsReport.frames > {n}", 120)
            png = p.screenshot(rect)
            counts[name] = state_pixels(png)
            if shots is not None:
                (shots / f"{name}.png").write_bytes(png)
        n = p.evaluate("window.omapsReport.frames")
        p.evaluate("window.omapsReport.setMode('alpha')")
        p.wait(f"window.omapsReport.frames > {n}", 120)
        counts["alpha"] = state_pixels(p.screenshot(rect))
        errors, requests = p.console_errors() + [e for e in p.log if e[0] == "error"], list(p.requests)
    return counts, errors, requests


@needs_chromium
def test_quad_page_in_chromium(quad, tmp_path):
    _, res = quad
    counts, errors, requests = look(res.path, ["tri3", "vq4", "none"], tmp_path)
    assert errors == []
    assert all(u.startswith(("file://", "data:")) for u in requests), requests
    assert requests[0].startswith("file://") and sum(u.startswith("file://") for u in requests) == 1
    for n in ("tri3", "vq4"):  # the disc: T corners, O inside, C on the rim
        assert min(counts[n].values()) > 200, (n, counts[n])
    assert counts["none"]["C"] > 2000 and counts["none"]["T"] == counts["none"]["O"] == 0
    assert counts["vq4"]["C"] < counts["tri3"]["C"]  # a finer map: less C
    assert sum(counts["alpha"].values()) < 50  # the alpha texture: grey, no state colours


@pytest.fixture(scope="module")
def palm(tmp_path_factory):
    d = tmp_path_factory.mktemp("palm")
    return build_report(SCENES / "palm.glb", d / "palm.html", SCHEMES, size=64, jobs=1)


@needs_scenes
def test_palm_page_numbers_are_trace_json(palm, tmp_path):
    text = open(palm.path, encoding="utf-8").read()
    self_contained(text)
    ref = trace_json(SCENES / "palm.glb", tmp_path, 64)
    shown = table_values(text)
    assert shown == {n: ref["schemes"][n]["alpha_tests_per_primary_ray"] for n in ("none", "tri3", "vq4")}
    assert palm.bytes < 8 * 2 ** 20


@needs_scenes
@needs_chromium
def test_palm_page_in_chromium(palm):
    counts, errors, requests = look(palm.path, ["tri3", "vq4"])
    assert errors == []
    assert all(u.startswith(("file://", "data:")) for u in requests), requests
    for n in ("tri3", "vq4"):
        assert counts[n]["C"] > 1000 and counts[n]["T"] > 1000, (n, counts[n])



def test_a_profile_still_being_written_is_removed(tmp_path, monkeypatch):
    """A browser's helper processes may still write into its profile folder as they stop: removing
    it then raised "Directory not empty" (seen under load). ``remove_tree`` tries again, and a
    folder that stays busy past its patience is left behind without an error."""
    import errno
    import shutil

    from omaps.report import browser

    profile = tmp_path / "profile"
    (profile / "Default").mkdir(parents=True)
    real, calls = shutil.rmtree, []

    def busy_twice(path, ignore_errors=False):
        calls.append(ignore_errors)
        if len(calls) <= 2 and not ignore_errors:
            raise OSError(errno.ENOTEMPTY, "Directory not empty", "Default")
        real(path, ignore_errors=ignore_errors)

    monkeypatch.setattr(browser.shutil, "rmtree", busy_twice)
    browser.remove_tree(profile)
    assert not profile.exists() and calls == [False, False, False]

    (profile / "Default").mkdir(parents=True)
    calls.clear()

    def always_busy(path, ignore_errors=False):
        calls.append(ignore_errors)
        if not ignore_errors:
            raise OSError(errno.ENOTEMPTY, "Directory not empty", "Default")

    monkeypatch.setattr(browser.shutil, "rmtree", always_busy)
    browser.remove_tree(profile, patience=0.3)  # never raises
    assert calls[-1] is True and calls.count(False) >= 2
