"""A Griffe extension for the API reference (mkdocs.yml loads it): the Default column of a
docstring's parameter table is the signature's default, each parameter its own.

Griffe takes a numpy-style entry's default from the docstring before the signature, and reads more
into it than it says: an entry for several parameters (``filter, wrap : str``) gives each the
default of the first (``wrap`` would show ``'nearest'``, the default of ``filter``), and a set of
choices (``command : {"omm", "eval"}``) makes the first choice a default even for a required
parameter. Here every documented parameter of the signature shows the signature's default
(``required`` when it has none).
"""

from __future__ import annotations

import griffe


class SignatureDefaults(griffe.Extension):
    def on_object(self, *, obj, loader, **kwargs) -> None:
        if not (obj.is_function or obj.is_class) or obj.docstring is None:
            return
        try:
            signature = obj.parameters
        except (AttributeError, griffe.AliasResolutionError):
            return  # (a class whose __init__ cannot be read: nothing to take defaults from)
        for section in obj.docstring.parsed:
            if section.kind is griffe.DocstringSectionKind.parameters:
                for item in section.value:
                    if item.name in signature:
                        item.value = signature[item.name].default
