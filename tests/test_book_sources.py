"""The book's sources agree with the registries: figure cells, captions, ledger targets, bibliography."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from mascore._booktools import chapter_studies, drawn_figures
from mascore.registry import paper_keys, paper_registry
from mascore.report import ledger_label

ROOT = Path(__file__).resolve().parents[1]
CHAPTERS = chapter_studies()


def _cells(chapter: str) -> list[dict]:
    return json.loads((ROOT / "notebooks" / f"{chapter}.ipynb").read_text())["cells"]


def test_every_paper_is_registered():
    assert {reg.key for reg, _ in CHAPTERS.values()} == set(paper_keys())


def test_papers_are_in_the_order_of_the_table_of_contents():
    """Each study's chapter is in book/_toc.yml, and the papers' order (their positions) is the book's."""
    toc = re.findall(r"file:\s*notebooks/(\w+)", (ROOT / "book" / "_toc.yml").read_text())
    missing = sorted(set(CHAPTERS) - set(toc))
    assert not missing, f"chapters missing from book/_toc.yml: {missing}"
    in_book = [CHAPTERS[c][0].key for c in toc if c in CHAPTERS]
    assert list(dict.fromkeys(in_book)) == list(paper_keys())


@pytest.mark.parametrize("chapter", sorted(CHAPTERS))
def test_each_registered_figure_is_drawn_once_with_the_registry_caption(chapter):
    reg, study = CHAPTERS[chapter]
    drawn: dict[str, int] = {}
    for cell in _cells(chapter):
        if cell["cell_type"] != "code":
            continue
        for name in drawn_figures("".join(cell["source"])):
            drawn[name] = drawn.get(name, 0) + 1
            spec = study.figure(name)
            meta = cell["metadata"].get("mystnb", {}).get("figure", {})
            assert meta.get("name") == reg.figure_label(name), f"{chapter}: run `make captions` ({name})"
            assert meta.get("caption") == reg.full_caption(spec), f"{chapter}: caption of {name} out of date: `make captions`"
    assert drawn == {f.name: 1 for f in study.figures}, f"{chapter}: registered figures drawn {drawn}"


@pytest.mark.parametrize("chapter", sorted(CHAPTERS))
def test_every_figure_cell_has_a_unique_label_and_a_caption(chapter):
    labels = []
    for cell in _cells(chapter):
        meta = cell["metadata"].get("mystnb", {}).get("figure")
        if meta:
            assert meta.get("caption", "").strip(), f"{chapter}: figure {meta.get('name')} without caption"
            labels.append(meta["name"])
    assert len(labels) == len(set(labels)), f"{chapter}: duplicate figure labels"
    assert all(label.startswith("fig-") for label in labels)


@pytest.mark.parametrize("chapter", sorted(CHAPTERS))
def test_chapter_has_its_ledger_target(chapter):
    reg, study = CHAPTERS[chapter]
    text = "".join("".join(c["source"]) for c in _cells(chapter) if c["cell_type"] == "markdown")
    assert f"({ledger_label(reg.key, study.name)})=" in text


def test_bibliography_entries_are_complete():
    bib = (ROOT / "book" / "references.bib").read_text()
    years = re.findall(r"year\s*=\s*\{([^}]*)\}", bib)
    assert years and all(re.fullmatch(r"\d{4}", y) for y in years), years
    for key in paper_keys():
        assert f"{{{key}," in bib


def test_registry_captions_are_stated():
    for key in paper_keys():
        reg = paper_registry(key)
        for study in reg.studies:
            for spec in (*study.figures, *study.tables):
                assert len(spec.caption.split()) >= 8, f"{key}/{spec.name}: caption too short to say what to look for"
