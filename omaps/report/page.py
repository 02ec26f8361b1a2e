"""The report page: one self-contained HTML file. Its styles, scripts (three.js bundled with
``OrbitControls``, ``assets/three.min.js``; the page's own ``assets/report.js``), images (PNG
data URIs) and data (JSON in a ``<script type="application/json">``) are all inside it, so it
opens from disk and loads nothing from anywhere."""

from __future__ import annotations

import html
import json
from importlib import resources

__all__ = ["asset", "page", "table", "figure", "esc"]


def asset(name: str) -> str:
    """The text of a file of ``omaps/report/assets``."""
    return resources.files(__package__).joinpath("assets", name).read_text(encoding="utf-8")


def esc(text) -> str:
    return html.escape(str(text), quote=True)


def _script_safe(js: str, name: str) -> str:
    if "</script" in js.lower():
        raise ValueError(f"{name} holds '</script' and cannot be inlined")
    return js


def page(title: str, body: str, data: dict, three: bool) -> str:
    """The whole page: ``body`` (HTML), ``data`` for the script (``data["view"]``: the 3D view's,
    when ``three``)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    scripts = []
    if three:
        scripts.append(f"<script>{_script_safe(asset('three.min.js'), 'three.min.js')}</script>")
    scripts.append(f"<script>{_script_safe(asset('report.js'), 'report.js')}</script>")
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            # nothing is loaded from anywhere: every image is a data URI, every script inline
            "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; "
            "img-src data: blob:; style-src 'unsafe-inline'; script-src 'unsafe-inline'\">\n"
            f"<title>{esc(title)}</title>\n<style>{asset('report.css')}</style>\n</head>\n<body>\n{body}\n"
            f"<script id=\"omaps-data\" type=\"application/json\">{text}</script>\n"
            + "\n".join(scripts) + "\n</body>\n</html>\n")


def table(headers, rows, cls: str = "sortable", caption: str | None = None) -> str:
    """An HTML table. ``headers``: (label, title) pairs; ``rows``: lists of cells, each text or
    (text, number): the number (kept exact, ``repr``) is its ``data-v``, what sorting reads."""
    head = "".join(f"<th title=\"{esc(t)}\">{esc(h)}</th>" for h, t in headers)
    body = []
    for row in rows:
        cells = []
        for c in row:
            if isinstance(c, tuple):
                text, v = c
                cells.append(f"<td data-v=\"{'' if v is None else repr(float(v))}\">{text}</td>")
            else:
                cells.append(f"<td>{c}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{esc(caption)}</caption>" if caption else ""
    return (f"<table class=\"{cls}\">{cap}<thead><tr>{head}</tr></thead>\n<tbody>\n" + "\n".join(body)
            + "\n</tbody></table>")


def figure(uri: str, caption: str, alt: str, cls: str = "") -> str:
    return (f"<figure class=\"{cls}\"><img src=\"{uri}\" alt=\"{esc(alt)}\"><figcaption>{esc(caption)}"
            "</figcaption></figure>")
