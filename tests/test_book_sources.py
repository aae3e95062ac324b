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


def test_the_apply_chapter_comes_after_the_papers():
    """It uses the papers' equations and theorems by number: the reader meets them first."""
    toc = re.findall(r"file:\s*notebooks/(\w+)", (ROOT / "book" / "_toc.yml").read_text())
    last_paper = max(toc.index(c) for c in CHAPTERS)
    assert toc.index("apply_your_system") > last_paper, toc


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
    from mascore._booktools import plain_text

    labels = []
    for cell in _cells(chapter):
        meta = cell["metadata"].get("mystnb", {}).get("figure")
        if meta:
            assert meta.get("caption", "").strip(), f"{chapter}: figure {meta.get('name')} without caption"
            alt = cell["metadata"]["mystnb"].get("image", {}).get("alt")
            assert alt == plain_text(meta["caption"]), f"{chapter}: alt text of {meta['name']} is not its caption: `make sync`"
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


# ---------------------------------------------------------------- numbers the code produces are not typed

#: A measured time or speed ratio typed into prose: a number with a unit of computing time, an
#: "Nx" ratio or "N times faster", or seconds next to a word of measurement (takes, took, wall,
#: CPU, timed, measured). Simulated durations ("30 s", "sampled at 0.1 s") are settings, not timings.
TYPED_TIMING = re.compile(
    r"\b\d+(?:\.\d+)?\s*(?:ms|µs|us|ns)\b"
    r"|\b\d+(?:\.\d+)?x\b(?!\s*\d)"
    r"|\b\d+(?:\.\d+)?\s+times\s+(?:faster|slower)"
    r"|\b(?:takes?|took|wall|CPU|timed|measured)\b[^.|]{0,60}?\b\d+(?:\.\d+)?\s*s\b"
    r"|\|\s*\d+(?:\.\d+)?\s*s\s*\|",
    re.I,
)
#: Words of the workshop, not of the book: an issue, a claim's slug, the date of a measurement.
WORKSHOP_WORDS = re.compile(r"\bof the issue\b|\bthe issue's\b|\(claim `|\(claim [\w/-]+\)|\bclaim `[a-z0-9-]+`"
                            r"|\b\d{1,2} (?:Jan|Feb|Mar|Apr|May|"
                            r"Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]* 20\d\d\b|\b20\d\d-\d\d-\d\d\b")


def _markdown_cells():
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        for i, cell in enumerate(json.loads(path.read_text())["cells"]):
            if cell["cell_type"] == "markdown":
                text = re.sub(r"\{glue(?::\w+)?\}`[^`]*`", "", "".join(cell["source"]))  # computed numbers
                yield f"{path.stem}[{i}]", text


def prose_problems(where: str, text: str) -> list[str]:
    """Timings or ratios typed into a Markdown cell, and words of the workshop."""
    out = [f"{where}: typed timing {m.group(0)!r}: compute it (glue or a computed Markdown cell)"
           for m in TYPED_TIMING.finditer(text)]
    out += [f"{where}: workshop words {m.group(0)!r}" for m in WORKSHOP_WORDS.finditer(text)]
    return out


def test_no_timing_or_ratio_is_typed_into_the_prose():
    problems = [p for where, text in _markdown_cells() for p in prose_problems(where, text)]
    assert not problems, "\n".join(problems)


def test_prose_check_fails_on_typed_timings():
    assert prose_problems("x", "the design takes 0.32 s for N = 5")
    assert prose_problems("x", "3.6 ms per design") and prose_problems("x", "47x the plain recursion")
    assert prose_problems("x", "| 32 | 0.40 s | 3.0 s |") and prose_problems("x", "ten times faster, 8 times faster")
    assert prose_problems("x", "measured on 23 Nov 2026") and prose_problems("x", "(claim `fig5-error`)")
    assert prose_problems("x", "holds for this draw (claim fig5-error-below-initial)")
    assert not prose_problems("x", "sampled at 0.1 s, simulated for 30 s on 2 x 2 blocks, {glue:text}`t_ms` ms")


#: A decimal number in prose (a result quoted in a caption if it has three or more significant digits).
_DECIMAL = re.compile(r"(?<![\w.])\d+\.\d+(?![\w.])")


def typed_results(caption: str) -> list[str]:
    """Numbers of three or more significant digits typed into a caption (math and computed values aside)."""
    text = re.sub(r"\$[^$]*\$|\{\{[^}]*\}\}", "", caption)
    text = re.sub(r"(?:eqs?\.|Theorems?|Lemma|Sec\.|Table|Figs?\.)\s*\(?[\d.,\- and]+\)?", "", text)
    return [x for x in _DECIMAL.findall(text) if len(x.replace(".", "").lstrip("0")) >= 3]


def test_the_typed_result_check_catches_a_typed_number():
    assert typed_results("the fused value (dotted, 6.985); a limit of 2.462") == ["6.985", "2.462"]
    assert typed_results("the fused value ({{fused:.4g}}), $P_7(0)=0.001$, eqs. (4)-(5), Theorem 3.9") == []


@pytest.mark.parametrize("chapter", sorted(CHAPTERS))
def test_captions_quote_computed_values_not_typed_ones(chapter):
    """A caption's result numbers come from the run (``{{name:fmt}}`` placeholders glued by the chapter)."""
    reg, study = CHAPTERS[chapter]
    typed = {spec.name: typed_results(spec.caption) for spec in study.figures}
    workshop = [p for spec in study.figures for p in prose_problems(f"{chapter} {spec.name}", spec.caption)]
    assert not workshop, "\n".join(workshop)
    assert not any(typed.values()), f"{chapter}: numbers typed into captions: { {k: v for k, v in typed.items() if v} }"
    quoting = [spec.name for spec in study.figures if spec.placeholders()]
    if quoting:
        sources = "".join("".join(c["source"]) for c in _cells(chapter) if c["cell_type"] == "code")
        assert "glue_caption_values(STUDY, result)" in sources, (
            f"{chapter}: the captions of {quoting} quote computed values, but the chapter does not glue them")


# ---------------------------------------------------------------- figures: no legend over the data

RESULTS = ROOT / "results"


@pytest.mark.parametrize("key,what", [("legend_overlaps", "legends over the data"),
                                      ("unlabelled_lines", "panels with more than five unlabelled lines")])
def test_registered_figures_keep_their_legends_off_the_data_and_label_their_lines(key, what):
    """Every registered figure, as `mascore reproduce` drew it: no legend covers a data line or marker
    (measured from the artists' extents, :func:`mascore.plotting.legend_overlaps`), no panel shows more
    than five lines without a legend entry (:func:`mascore.plotting.unlabelled_lines`); both are written
    beside each figure."""
    from mascore.registry import all_figures

    missing, offenders = [], []
    for reg, _, spec in all_figures():
        layout = RESULTS / reg.key / "figures" / f"{spec.name}.layout.json"
        if not layout.exists():
            missing.append(f"{reg.key}/{spec.name}")
            continue
        record = json.loads(layout.read_text())
        if key not in record:
            missing.append(f"{reg.key}/{spec.name}")
        offenders += [f"{reg.figure_label(spec.name)}: {o}" for o in record.get(key, [])]
    if len(missing) == len(all_figures()):
        pytest.skip(f"no figure layouts in {RESULTS}: run `python -m mascore reproduce all --out results` first")
    assert not missing, f"figures without a layout record (rerun `mascore reproduce`): {missing}"
    assert not offenders, f"{what}:\n" + "\n".join(offenders)


# ---------------------------------------------------------------- glossary and bibliography complete

def _reader_texts() -> list[tuple[str, str]]:
    """(where, text) of what the book shows in words: Markdown of the notebooks and book pages, figure
    captions, the ledgers' statements, notes and rules (when results/ exists), the errata, docstrings."""
    from mascore.ledger import load_claims
    from mascore.registry import all_figures, paper_registries

    out = [(where, text) for where, text in _markdown_cells()]
    out += [(p.name, p.read_text()) for p in sorted((ROOT / "book").glob("*.md"))]
    out += [(reg.figure_label(spec.name), spec.caption) for reg, _, spec in all_figures()]
    out += [(f"{reg.key} errata", e) for reg in paper_registries() for e in reg.errata]
    if (RESULTS / "song2023" / "claims.json").exists():
        out += [(r["id"], " ".join((r["statement"], r.get("note", ""), r.get("rule", ""))))
                for r in load_claims(RESULTS, verify=False)]
    return out


def _prose(text: str) -> str:
    """Text without code blocks, inline code, math, roles' targets and link targets."""
    text = re.sub(r"```.*?```|\$\$.*?\$\$", " ", text, flags=re.S)
    text = re.sub(r"\{[a-z:]+\}`[^`]*`|`[^`]*`|\$[^$]*\$|\]\([^)]*\)", " ", text)
    return text


#: Capitalized words that are not abbreviations (names, Roman numerals, a logical AND in a rule).
NOT_ABBREVIATIONS = {"II", "III", "IV", "VI", "MATLAB", "NumPy", "SciPy", "NaN", "AND", "OR", "CPU", "JupyterLab"}


def glossary_terms() -> set[str]:
    block = re.search(r"```\{glossary\}\n(.*?)```", (ROOT / "book" / "notation.md").read_text(), re.S).group(1)
    return {line.strip() for line in block.splitlines() if line.strip() and not line.startswith(" ")}


def abbreviations(text: str) -> set[str]:
    """Words of two or more capitals (``EKF``, ``CoM``, ``SDPs`` as ``SDP``) in the prose of `text`."""
    words = re.findall(r"\b(?:[A-Z]{2,}[a-z]?|[A-Z][a-z]?[A-Z]+)s?\b", _prose(text))
    return {w[:-1] if w.endswith("s") and w[:-1].isupper() else w for w in words} - NOT_ABBREVIATIONS


def test_every_abbreviation_is_in_the_glossary():
    terms = glossary_terms()
    missing = {}
    for where, text in _reader_texts():
        for word in abbreviations(text) - terms:
            missing.setdefault(word, where)
    assert not missing, f"abbreviations without a glossary entry (book/notation.md): {missing}"


def test_the_abbreviation_check_sees_abbreviations():
    assert abbreviations("The EKF and two SDPs about the CoM; $LMI$ and `DARE` are not prose.") == {"EKF", "SDP", "CoM"}
    assert {"DARE", "EKF", "SMF", "ISS", "CoM", "HCMCI", "ICF"} <= glossary_terms()


def bibliography_surnames() -> set[str]:
    bib = (ROOT / "book" / "references.bib").read_text()
    names = set()
    for authors in re.findall(r"author\s*=\s*\{(.*)\},?\n", bib):
        for person in authors.split(" and "):
            names.add(person.split(",")[0].strip().strip("{}"))
    return names


_SURNAME = r"[A-Z][a-z]+(?:-[A-Z][a-z]+)?"


def cited_surnames(text: str) -> set[str]:
    """Surnames cited in prose: ``Kamal et al.``, ``Cattivelli and Sayed``, ``Xiao, Boyd and Lall 2005``."""
    text = _prose(text)
    names = set(re.findall(rf"\b({_SURNAME}) et al\.", text))
    for m in re.finditer(rf"\b((?:{_SURNAME}, )*{_SURNAME}) and ({_SURNAME})\b(?=\)|,|;|'s| \(?\d{{4}}| \{{cite)", text):
        names |= {n.strip() for n in m.group(1).split(",")} | {m.group(2)}
    return names


#: Capitalized pairs that read like "A and B" citations but are not people.
NOT_PEOPLE = {"Graphs", "Laplacians", "Theorems", "Figs", "Tables", "Sec", "Secs", "Lemma", "Kalman", "Riccati",
              "Gaussian", "Song", "Remark"}


def test_every_name_cited_has_a_bibliography_entry():
    """A name cited in the book's prose, captions, ledgers or docstrings is an author in book/references.bib."""
    known = bibliography_surnames()
    texts = _reader_texts() + [(p.name, p.read_text()) for p in sorted((ROOT / "mascore").rglob("*.py"))]
    missing = {}
    for where, text in texts:
        for name in cited_surnames(text) - known - NOT_PEOPLE:
            missing.setdefault(name, where)
    assert not missing, f"names cited without a bibliography entry: {missing}"


def test_the_citation_check_sees_citations():
    text = "(`ci-L1`, Battistelli and Chisci), Kamal et al. and Hu, Xie and Zhang 2012; Graphs and Laplacians"
    assert cited_surnames(text) == {"Battistelli", "Chisci", "Kamal", "Hu", "Xie", "Zhang"}
    assert {"Battistelli", "Chisci", "Kamal", "Cattivelli", "Sayed", "Hu", "Deshpande"} <= bibliography_surnames()


def test_alt_text_has_no_placeholder():
    """Alt text is the caption as the reader sees it, with the run's values in place (no '(the value of this run)')."""
    from mascore._booktools import plain_text
    from mascore.registry import all_figures

    placeholders = [reg.figure_label(spec.name) for reg, _, spec in all_figures()
                    if re.search(r"value of this run|glue|\{\{", plain_text(reg.full_caption(spec)))]
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        for cell in json.loads(path.read_text())["cells"]:
            alt = cell["metadata"].get("mystnb", {}).get("image", {}).get("alt", "")
            if "value of this run" in alt:
                placeholders.append(f"{path.stem}: {cell['metadata']['mystnb']['figure']['name']}")
    assert not placeholders, f"alt text with a placeholder instead of the run's value: {sorted(set(placeholders))}"
