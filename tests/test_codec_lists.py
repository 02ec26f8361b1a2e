"""No hand-kept list of codecs outside the codecs' own modules and docs/FORMAT.md: the command
line's help, the docs' codec table and lists and the docs' scripts take them from the registry
(``omaps.codecs``), and docs/FORMAT.md records omaps' own format codes, which must stay those the
registry assigns."""

import importlib.util
import itertools
import re
import subprocess
import sys

import pytest
from conftest import ROOT

from omaps.cli.common import BUDGET_DEFAULTS, CODECS, CODECS_OR
from omaps.codecs import ENTRIES, codec_names, format_names

DOCS = ROOT / "docs"


def _hook():
    spec = importlib.util.spec_from_file_location("docs_codec_lists", DOCS / "hooks" / "codec_lists.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# ---- docs/FORMAT.md's format codes ----

def format_md_codes() -> dict[int, str]:
    """docs/FORMAT.md's table of format codes ("### Format codes": ``| code | codec |``, a row's
    code a number or a range A–B, its codecs named in backquotes, one per code, or ``none``)."""
    text = (DOCS / "FORMAT.md").read_text(encoding="utf-8")
    section = text.split("### Format codes", 1)[1].split("\n#", 1)[0]
    out: dict[int, str] = {}
    for line in section.splitlines():
        m = re.fullmatch(r"\|\s*(\d+)(?:\s*[–-]\s*(\d+))?\s*\|(.*)\|\s*", line)
        if not m:
            continue
        first, last = int(m.group(1)), int(m.group(2) or m.group(1))
        names = re.findall(r"`([^`]+)`", m.group(3)) or (["none"] if m.group(3).strip().startswith("none") else [])
        assert len(names) == last - first + 1, f"FORMAT.md: codes {first}..{last} name {names}"
        out.update(zip(range(first, last + 1), names))
    return out


def test_format_md_records_the_registrys_codes_of_omaps_own_codecs():
    recorded = format_md_codes()
    own = {0: "none"} | {e.code: e.name for e in ENTRIES if e.origin == "omaps"}
    assert recorded == own
    assert format_names()[:len(own)] == tuple(own[c] for c in range(len(own)))  # plug-ins' codes come after


# ---- no hand-kept lists ----

_NAME = re.compile(r"(?<![\w-])(" + "|".join(re.escape(n) for n in sorted(codec_names(), key=len, reverse=True))
                   + r")(?:-(?:paper|fast|medium|thorough))?(?![\w-])", re.IGNORECASE)
# what may stand between two names of one enumeration: commas, slashes, "or" / "and", quotes,
# backquotes, emphasis and white space (line ends included) -- at least some white space, so a
# scheme list as a command takes it (vq2,vq4,vq4x64: a chosen selection) is none
_SEPARATOR = re.compile(r"(?:[\s\"'`*,/+]|\bor\b|\band\b)+")

# places that name three or more codecs together on purpose (each with the reason), or that this
# change could not edit: the text the enumeration holds, by file
ALLOWED = {
    "docs/guide/batch.md": ("`wavelet3`, and `vq2`, `vq4`, `vq4x64`, `vq4-synth` each",),  # a benchmark's schemes, as run
    "docs/scripts/frontier.py": ("(`vq2`, `vq4`, \"\n        \"`vq4x64`)",),  # the schemes its run traces (SCHEMES)
}


def enumerations(text: str, least: int = 3):
    """(line, text) of each run of ``least`` or more different codecs (variants count as their
    codec) joined by list separators only."""
    found = list(_NAME.finditer(text))
    runs, run = [], found[:1]
    for a, b in itertools.pairwise(found):
        sep = text[a.end():b.start()]
        if _SEPARATOR.fullmatch(sep) and re.search(r"\s", sep):
            run.append(b)
        else:
            runs.append(run)
            run = [b]
    runs.append(run)
    for r in runs:
        if r and len({m.group(1).lower() for m in r}) >= least:
            yield text.count("\n", 0, r[0].start()) + 1, text[r[0].start():r[-1].end()]


def scanned_files():
    skip_docs = {"FORMAT.md", "changelog.md", "results.md", "frontier.md"}  # the spec; history; generated pages
    yield from (p for p in sorted((ROOT / "omaps").rglob("*.py")) if "codecs" not in p.relative_to(ROOT).parts)
    yield from (p for p in sorted(DOCS.rglob("*.md")) if p.name not in skip_docs)
    yield from sorted(DOCS.rglob("*.py"))
    yield ROOT / "README.md"


def test_the_scan_finds_an_enumeration_and_passes_a_selection():
    assert [t for _, t in enumerations("the codecs: vq2, vq4, vq4x64 and more")] == ["vq2, vq4, vq4x64"]
    assert list(enumerations('for name in ("vq2",\n             "vq4", "wavelet3-fast"):')) == [
        (1, 'vq2",\n             "vq4", "wavelet3-fast')]
    assert list(enumerations("`vq4-synth` or `wavelet3`; vq4 wins")) == []
    assert list(enumerations("--schemes none,tri3,sq16,vq2,vq4,vq4x64")) == []  # a command's selection
    assert list(enumerations("`vq4-paper`, `vq4-fast`, `vq4-thorough`")) == []  # one codec's variants


def test_no_hand_kept_list_of_codecs():
    """Three or more codecs named together outside the codecs' modules and docs/FORMAT.md are a
    list kept by hand: take it from the registry (``codec_names()``, ``codec_list``; in the docs
    the markers of docs/hooks/codec_lists.py)."""
    bad = []
    for path in scanned_files():
        rel = path.relative_to(ROOT).as_posix()
        for line, text in enumerations(path.read_text(encoding="utf-8")):
            if not any(text in allowed or allowed in text for allowed in ALLOWED.get(rel, ())):
                bad.append(f"{rel}:{line}: {' '.join(text.split())}")
    assert not bad, "codecs listed by hand (derive them from the registry):\n" + "\n".join(bad)


# ---- the command line ----

def _helps(monkeypatch) -> dict[str, str]:
    from omaps.cli.main import parser

    monkeypatch.setenv("COLUMNS", "4000")  # one line per option: no name broken at its hyphen
    sub = next(a for a in parser()._actions if a.dest == "command").choices
    return {c: sub[c].format_help() for c in ("eval", "trace", "omm", "encode", "decode")}


def test_the_help_names_every_codec(monkeypatch):
    for command, text in _helps(monkeypatch).items():
        missing = [n for n in codec_names() if not re.search(rf"(?<![\w-]){re.escape(n)}(?![\w-])", text)]
        assert not missing, f"omaps {command} --help does not name {missing}"
        assert not [m for m in (CODECS, CODECS_OR, BUDGET_DEFAULTS) if m in text], f"omaps {command}: a marker left"


def test_the_help_follows_the_registry(monkeypatch):
    """A codec the registry gains (a plug-in's) is in the help with no other change."""
    from omaps.codecs import registry

    monkeypatch.setattr(registry, "_COMPRESSED", (*registry._COMPRESSED, "zz-plugin"))
    for command, text in _helps(monkeypatch).items():
        assert "zz-plugin" in text, command


def test_the_omm_parser_loads_no_registry():
    """``omaps omm`` builds its parser without the codec registry (numpy and numba): the help's
    codecs are filled in only when it is shown."""
    code = ("import sys; from omaps.cli.main import parser; parser('omm'); "
            "print(sorted(m for m in sys.modules if m.startswith(('omaps.codecs', 'numba', 'numpy'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# ---- the docs' generated table and lists ----

def test_the_docs_codec_table_lists_every_entry():
    hook = _hook()
    rows, table = hook.codec_rows(), hook.codec_table()
    covered = [n for names, _ in rows for n in names]
    assert covered == [e.name for e in ENTRIES]
    for names, cells in rows:
        assert "| " + " | ".join(cells) + " |" in table
        assert all(f"`{n}`" in cells[0] for n in (names[0], names[-1]))
    for name in codec_names():
        e = next(x for x in ENTRIES if x.name == name)
        assert f"| `{name}` |" in table and e.description in table


def test_the_docs_markers():
    hook = _hook()
    listed = hook.render("{{ codec-list or }}")
    assert all(f"`{n}`" in listed for n in codec_names()) and " or " in listed
    assert hook.render("{{ codec-table }}") == hook.codec_table()
    with pytest.raises(ValueError, match="unknown marker"):
        hook.render("{{ codec-lists }}", "x.md")
    for page in DOCS.rglob("*.md"):  # every marker a page holds is known
        text = page.read_text(encoding="utf-8")
        if "{{" in text:
            assert "{{" not in hook.render(text, str(page)), page
