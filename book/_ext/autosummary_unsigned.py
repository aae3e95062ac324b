"""Autosummary tables with ``:nosignatures:`` do not compute the signatures they leave out.

Sphinx's autosummary formats the signature of every object it lists, and only then looks at
``:nosignatures:`` to leave it out of the table. Formatting one is costly here: autodoc
inspects the object (for a class, its ``__init__`` and ``__new__``), reads its source again
for ``autodoc_preserve_defaults``, and numpydoc's ``autodoc-process-signature`` handler parses
the whole docstring. The API pages' tables (written by ``make sync`` with ``:nosignatures:``)
list about 430 objects, each documented again below its table with its signature: formatting the
tables' signatures took about a third of the CPU of reading the API pages. The tables are unchanged.
"""

from __future__ import annotations

from sphinx.ext.autosummary import Autosummary


class UnsignedAutosummary(Autosummary):
    """``autosummary`` that, with ``:nosignatures:``, formats no signature (the table shows none)."""

    def create_documenter(self, app, obj, parent, full_name):
        documenter = super().create_documenter(app, obj, parent, full_name)
        if "nosignatures" in self.options:
            documenter.format_signature = lambda **kwargs: ""
        return documenter


def setup(app):
    app.setup_extension("sphinx.ext.autosummary")
    app.add_directive("autosummary", UnsignedAutosummary, override=True)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
