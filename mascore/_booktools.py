"""Maintenance of the book: figure captions in the notebooks, checks of the rendered HTML.

``python -m mascore._booktools sync [NOTEBOOK ...]`` writes, into every code cell
that draws a registered figure (``STUDY.draw("NAME", ...)`` or
``REGISTRY.study(...).draw("NAME", ...)``), the MyST-NB figure metadata of that
figure: ``{"mystnb": {"figure": {"name": "fig-PAPER-NAME", "caption": ...}}}``,
the caption taken from the paper's registry. The book then renders the cell's
image as a numbered, captioned figure that the prose can reference with
``{numref}`fig-PAPER-NAME```. The tests check that the notebooks are in sync.

:func:`page_problems` lists what a reader would trip on in one built HTML page.
"""

from __future__ import annotations

import importlib
import json
import re
import sys
from pathlib import Path

from .ledger import PAPERS
from .registry import PaperRegistry, Study, paper_registry

__all__ = ["chapter_studies", "drawn_figures", "page_problems", "sync_notebook"]

_DRAW = re.compile(r"""\.draw\(\s*["'](?P<name>[A-Za-z0-9_\-]+)["']""")


def chapter_studies() -> dict[str, tuple[PaperRegistry, Study]]:
    """Notebook stem -> (paper, study) for every registered study."""
    out = {}
    for key in PAPERS:
        if not hasattr(importlib.import_module(f"mascore.papers.{key}"), "REGISTRY"):
            continue  # a paper module not (yet) on the registry
        reg = paper_registry(key)
        for study in reg.studies:
            out[study.chapter] = (reg, study)
    return out


def drawn_figures(cell_source: str) -> list[str]:
    """Names of the registered figures a code cell draws (``.draw("NAME", ...)`` calls)."""
    return _DRAW.findall(cell_source)


def sync_notebook(path: str | Path) -> int:
    """Write the registry's figure metadata into the notebook's figure cells; returns cells changed."""
    path = Path(path)
    chapters = chapter_studies()
    if path.stem not in chapters:
        return 0
    reg, study = chapters[path.stem]
    nb = json.loads(path.read_text())
    changed = 0
    for cell in nb["cells"]:
        if cell["cell_type"] != "code":
            continue
        names = drawn_figures("".join(cell["source"]))
        if not names:
            continue
        if len(names) > 1:
            raise ValueError(f"{path.name}: one registered figure per cell, found {names}")
        spec = study.figure(names[0])
        meta = {"name": reg.figure_label(spec.name), "caption": reg.full_caption(spec)}
        if cell["metadata"].get("mystnb", {}).get("figure") != meta:
            cell["metadata"].setdefault("mystnb", {})["figure"] = meta
            changed += 1
    if changed:
        path.write_text(json.dumps(nb, indent=1, ensure_ascii=False) + "\n")
    return changed


# ---------------------------------------------------------------- checks of the rendered HTML

#: LaTeX that must never be visible as text (outside MathJax's math containers).
RAW_LATEX = re.compile(
    r"\$|\\[A-Za-z]+\{|\\(mathbb|mathcal|frac|sum|sigma|Sigma|top|hat|bar|left|right|begin|mathrm|le|ge|in|otimes|"
    r"alpha|beta|gamma|delta|lambda|mu|nu|xi|Phi|Gamma|Omega|infty|cdot|quad|qquad)\b"
)


def page_problems(html: str) -> list[str]:
    """What a reader would trip on in one built page: raw LaTeX, network loads, error/warning output.

    Math rendered by MathJax sits in ``<span class="math ...">`` / ``<div class="math ...">``
    and in ``<script>``, code in ``<pre>``/``<code>``; everything else is text the reader
    sees, and must not contain ``$...`` or LaTeX commands.
    """
    from html.parser import HTMLParser

    problems: list[str] = []

    class Scan(HTMLParser):
        skip_tags = {"script", "style", "pre", "code", "textarea"}

        def __init__(self) -> None:
            super().__init__(convert_charrefs=True)
            self.stack: list[tuple[str, bool]] = []

        def skipping(self) -> bool:
            return any(skip for _, skip in self.stack)

        def handle_starttag(self, tag, attrs):
            a = dict(attrs)
            classes = (a.get("class") or "").split()
            for attr in ("src", "href"):
                url = a.get(attr) or ""
                loads = tag in ("script", "img", "iframe") or (tag == "link" and "stylesheet" in (a.get("rel") or ""))
                if loads and attr in a and re.match(r"^(https?:)?//", url):
                    problems.append(f"loads from the network: <{tag} {attr}={url!r}>")
            if "stderr" in classes or "traceback" in classes or "output_error" in classes:
                problems.append(f"an error or stderr block is shown (<{tag} class={a.get('class')!r}>)")
            if tag in ("br", "img", "meta", "link", "input", "hr", "source", "wbr"):
                return
            self.stack.append((tag, tag in self.skip_tags or "math" in classes))

        def handle_endtag(self, tag):
            while self.stack:
                open_tag, _ = self.stack.pop()
                if open_tag == tag:
                    break

        def handle_data(self, data):
            if self.skipping():
                return
            m = RAW_LATEX.search(data)
            if m:
                start = max(m.start() - 40, 0)
                problems.append(f"raw LaTeX in the text: ...{data[start:m.end() + 40].strip()!r}...")

    Scan().feed(html)
    return problems


def main(argv: list[str] | None = None) -> int:
    """``python -m mascore._booktools sync [NOTEBOOK ...]`` (default: every notebook of a study)."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] != "sync":
        print(__doc__.splitlines()[0], "\nusage: python -m mascore._booktools sync [NOTEBOOK ...]", file=sys.stderr)
        return 2
    paths = [Path(p) for p in argv[1:]] or sorted(Path("notebooks").glob("*.ipynb"))
    for p in paths:
        n = sync_notebook(p)
        if n:
            print(f"{p}: {n} figure cell(s) updated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
