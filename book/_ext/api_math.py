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
#: Operator names written as words (``sum_k``, ``max_t``), and their TeX.
OPERATORS = re.compile(r"(?<!\\)\b(sum|trace|det|min|max)(?=[_ (])")
#: Greek letters written as words (``alpha mu^k``, ``Sigma^{-1}``, ``tau_1``): a whole word, not part of a name
#: (``mu_bar``, ``sigma_max`` stay as they are; ``nu_ij`` is a subscript).
GREEK = re.compile(r"(?<![\\\w])(alpha|beta|gamma|delta|epsilon|zeta|eta|theta|iota|kappa|lambda|mu|nu|xi|pi|rho|"
                   r"sigma|tau|phi|chi|psi|omega|Gamma|Delta|Theta|Lambda|Xi|Pi|Sigma|Phi|Psi|Omega)(?![A-Za-z]|_[A-Za-z]{3})")


def to_tex(text: str) -> str:
    r"""The TeX of a formula written as code: operator names and Greek letters written as words become commands.

    >>> to_tex("max_k |M^k| / (alpha mu^k)")
    '\\max_k |M^k| / (\\alpha \\mu^k)'
    """
    tex = OPERATORS.sub(r"\\\1", text)
    tex = GREEK.sub(r"\\\1", tex)
    return tex.replace("\\trace", "\\operatorname{trace}")


class LiteralFormulasToMath(SphinxTransform):
    """Inline literals with TeX in them become math nodes (API pages only)."""

    default_priority = 400  # before the domains collect the page (SphinxDomains, 850): MathJax is loaded

    def apply(self, **kwargs) -> None:
        if not self.env.docname.startswith("api/"):
            return
        for node in list(self.document.findall(nodes.literal)):
            text = node.astext()
            if LOOKS_LIKE_TEX.search(text):
                tex = to_tex(text)
                node.replace_self(nodes.math(tex, tex))


def setup(app):
    app.add_transform(LiteralFormulasToMath)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
