"""Autosummary tables show each object's whole summary line.

Sphinx's autosummary cuts the summary at the first ". " it finds, so "Fig. 2: fixed topology"
becomes "Fig." and "the law of eq. (6)" becomes "the law of eq.". Our docstrings follow numpydoc:
the first paragraph *is* the one-line summary, so the table shows that paragraph whole.
"""

from __future__ import annotations

from sphinx.ext import autosummary


def first_paragraph(doc: list[str], document) -> str:
    """The first paragraph of a docstring, joined into one line."""
    lines: list[str] = []
    for line in doc:
        if not line.strip():
            if lines:
                break
            continue
        lines.append(line.strip())
    return " ".join(lines)


def setup(app):
    autosummary.extract_summary = first_paragraph
    return {"parallel_read_safe": True, "parallel_write_safe": True}
