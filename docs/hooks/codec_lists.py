"""mkdocs hook: the codec registry's lists in the pages, so no page keeps one by hand.

Markers a page may hold (outside code blocks), replaced before the page is rendered:

* ``{{ codec-table }}``: the table of every registry entry (``omaps.codecs.ENTRIES``): name, map
  size, bits per map, block bytes, encoders, variants, whether a byte budget may choose it, and
  its one-line description; the raw ``sqN`` and the ``succinctL`` options one row each.
* ``{{ codec-list }}``, ``{{ codec-list or }}``, ``{{ codec-list and }}``: the compressed codecs
  (``omaps.codecs.codec_names()``, plug-ins' included) inline, as `` `vq2`, `vq4` ... ``, the last
  two joined by the word given (none: commas only).
* ``{{ paper-codec-list and }}``: the codecs that have the deck's encoder (variant ``-paper``).
* ``{{ budget-codec-list or }}``: the codecs among a ``budget:BYTES`` scheme's default options
  (``CodecEntry.budget_default``).

An unknown marker is an error (the build stops). Registered in mkdocs.yml (``hooks:``); the
tests call ``codec_table`` and ``render`` directly.
"""

from __future__ import annotations

import re

MARKER = re.compile(r"\{\{\s*([a-z-]+)(?:\s+(or|and))?\s*\}\}")
_NUMBERED = re.compile(r"([a-z][a-z_-]*?)(\d+)")


def _phrase(items: list[str], conjunction: str | None) -> str:
    from omaps.codecs import codec_list

    return codec_list(conjunction or "", [f"`{n}`" for n in items])


def _groups(entries) -> list[list]:
    """Consecutive entries named PREFIX + number (``sq1`` ... ``sq128``, ``succinct0`` ...) of one
    origin and kind, three or more of them, as one group; every other entry alone."""
    out: list[list] = []
    for e in entries:
        m = _NUMBERED.fullmatch(e.name)
        last = out[-1][-1] if out else None
        lm = _NUMBERED.fullmatch(last.name) if last is not None else None
        if m and lm and m.group(1) == lm.group(1) and (e.origin, e.variable) == (last.origin, last.variable):
            out[-1].append(e)
        else:
            out.append([e])
    return [g for big in out for g in ([big] if len(big) >= 3 else [[e] for e in big])]


def _budget(entries) -> str:
    kinds = {e.name: "default" if e.budget_default else "when named" if e.budget else "no" for e in entries}
    if len(set(kinds.values())) == 1:
        return next(iter(kinds.values()))
    return "; ".join(f"{_span([n for n, k in kinds.items() if k == kind])}: {kind}"
                     for kind in dict.fromkeys(kinds.values()))


def _span(names: list[str]) -> str:
    return f"`{names[0]}`" if len(names) == 1 else f"`{names[0]}` … `{names[-1]}`"


def codec_rows() -> list[tuple[tuple[str, ...], list[str]]]:
    """The codec table's rows: (the entries' names a row covers, its cells), in registry order."""
    from omaps.codecs import ENTRIES, get_codec
    from omaps.schemes import codec_variants

    rows = []
    for group in _groups(ENTRIES):
        e = group[0]
        names = tuple(x.name for x in group)
        plugin = "" if e.origin == "omaps" else f" (plug-in {e.origin})"
        if len(group) > 1:
            letter = "L" if e.variable else "N"
            number = _NUMBERED.fullmatch(group[-1].name).group(2)
            about = re.sub(rf"(?<!\d){number}(?!\d)", letter, group[-1].description)
            if e.variable:
                cells = [f"two level-{letter} micromaps", "varies", "varies"]
            else:
                raws = [get_codec(n) for n in names]
                cells = [f"{letter} × {letter}", ", ".join(str(c.bits) for c in raws),
                         ", ".join(str(c.block_bytes) for c in raws)]
            rows.append((names, [f"{_span(list(names))}", *cells, "—", "—", _budget(group), about + plugin]))
            continue
        if e.variable:
            rows.append((names, [f"`{e.name}`", f"two level-{e.level} micromaps", "varies", "varies", "—", "—",
                                 _budget(group), e.description + plugin]))
            continue
        c = get_codec(e.name)
        encoders = ", ".join(f"`{x}`" + (" (default)" if x == c.default_encoder and len(c.encoders) > 1 else "")
                             for x in c.encoders) or "—"
        variants = ", ".join(f"`-{v}`" + (" (default)" if v == c.default_effort else "")
                             for v in codec_variants(e.name)) if c.compressed else "—"
        rows.append((names, [f"`{e.name}`", f"{c.map_size} × {c.map_size}", str(c.bits), str(c.block_bytes),
                             encoders, variants or "—", _budget(group), e.description + plugin]))
    return rows


def codec_table() -> str:
    """Every registry entry as a markdown table (``{{ codec-table }}``)."""
    head = ["codec", "map", "bits per map", "block bytes", "encoders", "variants", "byte budget", "description"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cells) + " |" for _, cells in codec_rows()]
    return "\n".join(lines)


def _paper_codecs() -> list[str]:
    from omaps.codecs import codec_names
    from omaps.schemes import codec_variants

    return [n for n in codec_names() if "paper" in codec_variants(n)]


def render(markdown: str, where: str = "page") -> str:
    """``markdown`` with its markers replaced; ValueError naming ``where`` for an unknown one."""
    from omaps.codecs import budget_options, codec_names

    def one(m: re.Match) -> str:
        kind, conjunction = m.group(1), m.group(2)
        if kind == "codec-table" and conjunction is None:
            return codec_table()
        if kind == "codec-list":
            return _phrase(codec_names(), conjunction)
        if kind == "paper-codec-list":
            return _phrase(_paper_codecs(), conjunction)
        if kind == "budget-codec-list":
            return _phrase([n for n in budget_options(default=True) if n in codec_names()], conjunction)
        raise ValueError(f"{where}: unknown marker {m.group(0)!r} (docs/hooks/codec_lists.py)")

    return MARKER.sub(one, markdown)


def on_page_markdown(markdown: str, page, config, files) -> str:
    return render(markdown, page.file.src_path)
