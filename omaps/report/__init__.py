"""Reports: one self-contained HTML page per scene or texture corpus (``omaps report``).

A scene's page holds the per-scheme table of ``omaps.trace.trace_scene`` (alpha tests per primary
and shadow ray, map bytes, known share), its heat map, render and bytes chart, per alpha material
its texture with the map states over the UV layout, and a 3D view (three.js, orbit and zoom) of
the mesh with every alpha triangle's states drawn on it, per scheme, or its alpha texture. A
corpus's page holds the savings chart, the mean table and a sortable table of every texture with
its map panels. Everything is inside the one file: it opens from disk without a network.

Example::

    >>> from omaps.report import build_report                                   # doctest: +SKIP
    >>> r = build_report("palm.glb", "palm.html", "none,tri3,vq4", size=128)    # doctest: +SKIP
    >>> r.bytes, r.numbers["schemes"]["vq4"]["alpha_tests_per_primary_ray"]    # doctest: +SKIP
"""

from .build import ReportResult, build_report

__all__ = ["build_report", "ReportResult"]
