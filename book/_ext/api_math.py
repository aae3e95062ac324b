"""Formulas written as code in the docstrings render as math on the API pages.

Docstrings write formulas as inline literals (``x_{k+1} = A x_k + B u_k``, ``\\Sigma_i``), which
the API pages would show as code, braces and backslashes included. On the pages of ``book/api``
an inline literal that contains TeX (a brace subscript or superscript, or a backslash command)
becomes inline math; code names (``x_hat``, ``settings=SETTINGS``) stay code.
"""

from __future__ import annotations

import re

from docutils import nodes
from sphinx.transforms import SphinxTransform

#: TeX markup: ``_{...}``, a superscript (``^{...}``, ``^T``) or a backslash command such as ``\Sigma``.
LOOKS_LIKE_TEX = re.compile(r"[_^]\{|\\[A-Za-z]+|\^[A-Za-z0-9]")


class LiteralFormulasToMath(SphinxTransform):
    """Inline literals with TeX in them become math nodes (API pages only)."""

    default_priority = 400  # before the domains collect the page (SphinxDomains, 850): MathJax is loaded

    def apply(self, **kwargs) -> None:
        if not self.env.docname.startswith("api/"):
            return
        for node in list(self.document.findall(nodes.literal)):
            text = node.astext()
            if LOOKS_LIKE_TEX.search(text):
                tex = re.sub(r"(?<!\\)\b(sum|trace|det|min|max)(?=[_ (])", r"\\\1", text)  # sum_k -> \sum_k
                tex = tex.replace("\\trace", "\\operatorname{trace}")
                node.replace_self(nodes.math(tex, tex))


def setup(app):
    app.add_transform(LiteralFormulasToMath)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
