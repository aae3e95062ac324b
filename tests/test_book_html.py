"""What a reader sees: checks of the rendered book in book/_build/html.

`make test` builds the book first (`make book`), then runs these checks: every
registered figure of every paper is an image with its numbered caption in its
chapter, numbered in its chapter and with its caption as alt text, every chapter
shows its ledger table, no page shows raw LaTeX, an error or stderr block, or loads
anything from the network. In headless Chromium at 1280 px (offline), no display
equation or table is wider than the text column, no table cell shows NaN, no
figure is shrunk below legibility or has fewer than two image pixels per CSS pixel,
and no page shows more than about 4,000 words. The intro opens with its four reading
paths. Tests at the end show that each check fails on a page with a figure removed,
a formula broken or the layout overflowing, and that a page measured among others is
attributed its own measures.
"""

from __future__ import annotations

import html as html_module
import re
from pathlib import Path

import pytest

from mascore._booktools import page_problems
from mascore.registry import all_figures, paper_registries
from mascore.report import ledger_label

HTML = Path(__file__).resolve().parents[1] / "book" / "_build" / "html"

#: Sphinx turns straight quotes into typographic ones ("smartquotes"); compare without them.
SMART_QUOTES = str.maketrans({"\u2019": "'", "\u2018": "'", "\u201c": '"', "\u201d": '"'})


def _page(chapter: str) -> str:
    path = HTML / "notebooks" / f"{chapter}.html"
    if not path.exists():
        pytest.fail(f"{path} not found: build the book first (`make book`; `make test` does it)")
    return path.read_text()


def _html_id(label: str) -> str:
    """docutils' id of a label (lowercase; runs of other characters become one hyphen)."""
    return re.sub(r"[^a-z0-9]+", "-", label.lower()).strip("-")


def _figures(html: str) -> dict[str, str]:
    """``<figure id=...>`` blocks of a page by id."""
    return {m["id"]: m["body"] for m in
            re.finditer(r'<figure[^>]*\bid="(?P<id>[^"]+)"[^>]*>(?P<body>.*?)</figure>', html, re.S)}


def figure_problems(html: str, label: str, caption_start: str) -> list[str]:
    """Problems with one registered figure on a page: missing, no image, no numbered caption."""
    block = _figures(html).get(_html_id(label))
    if block is None:
        return [f"figure {label} is not on the page"]
    problems = []
    img = re.search(r'<img[^>]*src="(?P<src>[^"]+)"', block)
    if not img:
        problems.append(f"figure {label} has no image")
    elif not img["src"].startswith("data:") and not (HTML / "notebooks" / img["src"]).resolve().exists():
        problems.append(f"figure {label}: image {img['src']} missing from the build")
    caption = re.search(r"<figcaption>(.*?)</figcaption>", block, re.S)
    text = html_module.unescape(re.sub(r"<[^>]+>", "", caption.group(1))) if caption else ""
    text = text.translate(SMART_QUOTES)
    if not re.match(r"\s*Figure \d+\.\d+", text):
        problems.append(f"figure {label} has no caption numbered in its chapter ('Figure 4.2')")
    alt = re.search(r'<img[^>]*\balt="(?P<alt>[^"]*)"', block)
    if not alt or not alt["alt"].strip() or re.search(r"\.(png|svg|jpe?g)$", alt["alt"].strip()):
        problems.append(f"figure {label}: the image's alt text is not its caption")
    if " ".join(caption_start.split()) not in " ".join(text.split()):
        problems.append(f"figure {label}: caption does not start as registered ({caption_start!r})")
    return problems


def _caption_start(reg, spec) -> str:
    """The registered caption up to its first math or markup (what survives as plain text)."""
    return re.split(r"[$`*{\[]", reg.full_caption(spec))[0].strip()[:60]


FIGURES = all_figures()


@pytest.mark.parametrize("reg,study,spec", FIGURES, ids=[f"{r.key}-{s.name}" for r, _, s in FIGURES])
def test_registered_figure_is_on_its_chapter_page(reg, study, spec):
    problems = figure_problems(_page(study.chapter), reg.figure_label(spec.name), _caption_start(reg, spec))
    assert not problems, problems


STUDIES = [(reg, s) for reg in paper_registries() for s in reg.studies]


@pytest.mark.parametrize("reg,study", STUDIES, ids=[f"{r.key}-{s.name}" for r, s in STUDIES])
def test_chapter_shows_its_ledger_table(reg, study):
    html = _page(study.chapter)
    label = _html_id(ledger_label(reg.key, study.name))
    section = re.search(rf'id="{label}"(.*?)(<section|$)', html, re.S)  # the target and its section
    assert section, f"{study.chapter}: no ledger section ({ledger_label(reg.key, study.name)})"
    assert re.search(r"<table.*?verdict.*?</table>", section.group(1), re.S), f"{study.chapter}: ledger table missing"


PAGES = sorted(HTML.rglob("*.html")) if HTML.exists() else []


def test_the_book_is_built():
    names = {p.relative_to(HTML).as_posix() for p in PAGES}
    needed = {"intro.html", "notation.html", "bibliography.html", "notebooks/reproduction_report.html"}
    needed |= {f"notebooks/{s.chapter}.html" for _, s in STUDIES}
    assert needed <= names, f"pages missing from {HTML}: {sorted(needed - names)}"


@pytest.mark.parametrize("path", [p for p in PAGES if "_static" not in p.parts and p.name not in ("search.html",)],
                         ids=lambda p: p.relative_to(HTML).as_posix())
def test_page_has_no_raw_latex_errors_or_network_loads(path):
    assert not page_problems(path.read_text()), page_problems(path.read_text())


def test_report_is_a_summary():
    """The report: the crosstab, links to the ledgers of the claims to look at, the errata; no ledger dump."""
    html = (HTML / "notebooks" / "reproduction_report.html").read_text()
    assert "Verdicts by paper" in html and "Errata and readings" in html
    assert html.count("<table") <= 2, "the report holds the crosstab and the claims to look at, no more"
    assert "claim (where the paper says it)" not in html, "the report repeats a chapter's ledger"
    if "Every claim reproduces or holds" not in html:
        assert re.search(r'href="[a-z0-9_]+\.html#[a-z0-9-]+-ledger"', html), "no link to a chapter ledger"


# ---------------------------------------------------------------- the checks can fail


def _sample_page() -> tuple[str, str, str]:
    reg, study, spec = FIGURES[0]
    return _page(study.chapter), reg.figure_label(spec.name), _caption_start(reg, spec)


def test_figure_check_fails_when_a_figure_is_removed():
    html, label, start = _sample_page()
    assert not figure_problems(html, label, start)
    without_img = re.sub(rf'(<figure[^>]*id="{_html_id(label)}"[^>]*>.*?)<img[^>]*>', r"\1", html, count=1, flags=re.S)
    assert any("no image" in p for p in figure_problems(without_img, label, start))
    without_fig = re.sub(rf'<figure[^>]*id="{_html_id(label)}"[^>]*>.*?</figure>', "", html, count=1, flags=re.S)
    assert any("not on the page" in p for p in figure_problems(without_fig, label, start))


def test_latex_check_fails_when_a_formula_breaks():
    html, _, _ = _sample_page()
    assert not page_problems(html)
    broken = html.replace("</h1>", "</h1><p>where $\\Sigma_i^- = F\\Sigma_i F^\\top$ holds</p>", 1)
    assert any("raw LaTeX" in p for p in page_problems(broken))
    inside_math = html.replace("</h1>", '</h1><span class="math notranslate nohighlight">\\(\\Sigma_i\\)</span>', 1)
    assert not page_problems(inside_math)


def test_network_stderr_and_date_checks_fail():
    html, _, _ = _sample_page()
    assert any("network" in p for p in page_problems(html + '<script src="https://cdn.example.org/x.js"></script>'))
    assert any("stderr" in p for p in page_problems(html + '<div class="output stderr"><pre>Warning</pre></div>'))
    assert any("date" in p for p in page_problems(html + '<p class="last-updated">Last updated on Nov 30, 2026.</p>'))


def test_every_image_of_a_chapter_is_a_captioned_figure():
    """Plots outside the registry get figure metadata by hand: no bare image in a chapter."""
    for _, study in STUDIES:
        html = _page(study.chapter)
        outside = re.sub(r"<figure.*?</figure>", "", html, flags=re.S)
        bare = re.findall(r'<img[^>]*src="(?!data:image/svg)[^"]*_images/[^"]*"', outside)
        assert not bare, f"{study.chapter}: {len(bare)} image(s) without a numbered caption"


# ---------------------------------------------------------------- the pages as a reader sees them, at 1280 px

#: The style's tick labels are 10 pt at 100 dpi, 13.9 px per em (digits 10 px high): an image shown at
#: less than 90 % of its layout width (its pixels over PIXEL_RATIO) puts them under 9 px.
MIN_IMAGE_SCALE = 0.9
#: Visible words a page may show (collapsed blocks excluded): about 15 minutes of reading.
MAX_WORDS = 4000
READ_PAGES = sorted({*(HTML / "notebooks").glob("*.html"), *(HTML / "api").glob("*.html"), HTML / "notation.html",
                     HTML / "intro.html", HTML / "bibliography.html"}) if HTML.exists() else []
READ_PAGES = [p for p in READ_PAGES if p.exists() and not p.name.startswith(".")]


def _browser() -> str:
    from mascore._booktools import chromium

    browser = chromium()
    if browser is None:
        pytest.skip("chromium is not installed here (apt-get install -y chromium; .ci/run installs it)")
    return browser


def layout_problems(m: dict) -> list[str]:
    """What overflows the text column, shows NaN or is shrunk, in the measures of :func:`measure_page`."""
    if "error" in m:
        return [f"the page could not be measured: {m['error']}"]
    out = [f"MathJax cannot typeset a formula: {e}" for e in m.get("math_errors", [])]
    out += [f"display equation {e['width']} px wide in a {m['column']:.0f} px column: {e['what']}" for e in m["equations"]]
    out += [f"table {t['width']} px wide in a {m['column']:.0f} px column: {t['what']}" for t in m["tables"]]
    out += [f"a table cell shows NaN/None: {head}" for head in sorted(set(m["nan"]))]
    from mascore.plotting import PIXEL_RATIO

    for i in m["images"]:
        layout = i["natural"] / PIXEL_RATIO  # the width the figure was laid out for, in CSS px
        if i["shown"] < MIN_IMAGE_SCALE * layout:
            out.append(f"figure {i['id']} shrunk to {i['shown'] / layout:.0%} of its width (tick labels under 9 px)")
        if i["natural"] < 1.95 * i["shown"]:
            out.append(f"figure {i['id']} has {i['natural'] / i['shown']:.2g} image pixels per CSS pixel "
                       f"(blurred on a HiDPI screen; {PIXEL_RATIO} needed)")
    if m.get("words", 0) > MAX_WORDS:
        out.append(f"{m['words']} visible words (more than about {MAX_WORDS}: split the page into sub-pages, "
                   "or collapse what a first reading can skip)")
    return out


#: Pages loading at once in the one Chromium that measures them all.
TABS = 2

#: The layout checks' self-test, measured among the reading pages: a page that fails every check (beside the
#: page it is made from, so that its links resolve) and a page that does not exist.
BAD_PAGE = HTML / "notebooks" / ".layout-selftest.html"
MISSING_PAGE = HTML / "notebooks" / ".no-such-page.html"
WIDE_CELL = "wide_column_name_without_breaks_anywhere"


def _bad_page() -> str:
    """building_blocks.html with a wide formula, a formula MathJax rejects, a wide table with a NaN cell, a
    shrunk and a blurred figure and too many words at the top of its article."""
    wide_math = "\\[" + " + ".join(f"x_{{{i}}}^{{2}}" for i in range(80)) + "\\]"
    bad = ('<div class="math notranslate nohighlight">' + wide_math + "</div>"
           '<div class="math notranslate nohighlight">\\[\\begin{split}x \\tag{1}\\end{split}\\]</div>'
           "<table><tr>" + f"<td>{WIDE_CELL}</td>" * 30 + "</tr>"
           "<tr><td>NaN</td></tr></table>"
           '<figure id="fig-shrunk"><img src="data:image/svg+xml;utf8,'
           "%3Csvg xmlns='http://www.w3.org/2000/svg' width='2000' height='10'%3E%3C/svg%3E\"></figure>"
           '<figure id="fig-blurry"><img style="width: 300px" src="data:image/svg+xml;utf8,'
           "%3Csvg xmlns='http://www.w3.org/2000/svg' width='300' height='10'%3E%3C/svg%3E\"></figure>"
           "<p>" + "word " * MAX_WORDS + "</p>")
    html = (HTML / "notebooks" / "building_blocks.html").read_text()
    return html.replace('<article class="bd-article">', '<article class="bd-article">' + bad, 1)


@pytest.fixture(scope="session")
def measured() -> dict[Path, dict]:
    """Every reading page measured once per session, all in one Chromium, with the self-test's bad and
    missing pages among them (a page that fails maps to ``{"error": ...}``, reported by its own test).

    `make test` runs this file in one process (no xdist workers, which would each measure every page).
    """
    from mascore._booktools import measure_pages

    browser = _browser()
    half = len(READ_PAGES) // 2
    BAD_PAGE.write_text(_bad_page())
    try:
        return measure_pages([*READ_PAGES[:half], BAD_PAGE, MISSING_PAGE, *READ_PAGES[half:]], browser=browser,
                             tabs=TABS)
    finally:
        BAD_PAGE.unlink(missing_ok=True)


@pytest.mark.parametrize("path", READ_PAGES, ids=lambda p: p.relative_to(HTML).as_posix())
def test_page_fits_its_column_at_1280px(path, measured):
    """No formula MathJax rejects, no display equation or table wider than the column, no NaN cell, no
    figure shrunk or blurred (2 image pixels per CSS pixel), at most about 4,000 visible words (headless
    Chromium)."""
    problems = layout_problems(measured[path])
    assert not problems, "\n".join(problems)


def test_layout_check_fails_on_wide_math_tables_nan_shrunk_or_blurry_figures_and_long_pages(measured):
    """The bad page, measured among the good ones in one browser, fails every check, and its problems are its
    own; the missing page is reported as such."""
    problems = "\n".join(layout_problems(measured[BAD_PAGE]))
    assert "display equation" in problems and "table" in problems and "NaN" in problems, problems
    assert "MathJax cannot typeset" in problems, problems
    assert "fig-shrunk" in problems, problems
    assert "fig-blurry has 1 image pixels per CSS pixel" in problems, problems
    assert "visible words" in problems, problems
    assert WIDE_CELL in problems, problems
    others = [p for p, m in measured.items() if p != BAD_PAGE and WIDE_CELL in str(m)]
    assert not others, f"the bad page's table measured on {others}"
    assert layout_problems(measured[MISSING_PAGE]) == ["the page could not be measured: Chromium could not open "
                                                       f"{MISSING_PAGE.resolve().as_uri()}: net::ERR_FILE_NOT_FOUND"]


@pytest.mark.parametrize("bad,message", [({"width": 0}, "width must be"), ({"tabs": 1.5}, "tabs must be"),
                                         ({"timeout": -1}, "timeout must be")])
def test_measure_pages_refuses_bad_arguments(bad, message):
    from mascore._booktools import measure_pages

    with pytest.raises(ValueError, match=message):
        measure_pages([HTML / "intro.html"], **bad)


def test_a_page_measured_after_another_starts_with_empty_storage(tmp_path):
    """Pages loaded one after another in one window: what a page stores (as the theme stores its mode and the
    sidebar's scroll) is gone when the next page runs, as in a fresh profile."""
    writer = tmp_path / "writer.html"
    writer.write_text("<script>localStorage.setItem('seen', '1'); addEventListener('pagehide', () => "
                      "sessionStorage.setItem('seen', '1'));</script><article class='bd-article'>one</article>")
    reader = tmp_path / "reader.html"  # 1 word if both storages are empty, 3 or 5 more if either is not
    reader.write_text("<article class='bd-article'></article><script>document.querySelector('article').textContent ="
                      " 'empty' + (localStorage.getItem('seen') ? ' local storage kept' : '') +"
                      " (sessionStorage.getItem('seen') ? ' session storage kept from before' : '');</script>")
    from mascore._booktools import measure_pages

    measured = measure_pages([writer, reader], browser=_browser(), tabs=1)
    assert [measured[writer]["words"], measured[reader]["words"]] == [1, 1], measured


def test_a_page_that_never_finishes_is_reported_not_waited_for(tmp_path):
    """A page whose typesetting never ends fails its own measure once its time is up."""
    page = tmp_path / "never.html"
    page.write_text("<script>window.MathJax = {startup: {promise: new Promise(() => {})}};</script><p>text</p>")
    from mascore._booktools import measure_page

    with pytest.raises(RuntimeError, match="never.html: the page was not measured: not measured within 1 s"):
        measure_page(page, browser=_browser(), timeout=1)


def _next_page(path: Path) -> str:
    """The page the 'Next' button of a page leads to."""
    m = re.search(r'<a[^>]*class="right-next"[^>]*href="([^"#]+)', path.read_text()) or \
        re.search(r'<a[^>]*href="([^"#]+)"[^>]*class="right-next"', path.read_text())
    assert m, f"{path.name}: no 'Next' link"
    return (path.parent / m.group(1)).resolve().relative_to(HTML.resolve()).as_posix()


def test_the_bibliography_comes_before_the_api_reference():
    assert _next_page(HTML / "notebooks" / "performance.html") == "bibliography.html"
    assert _next_page(HTML / "bibliography.html").startswith("api/")


def test_performance_met_column_says_met_missed_or_reported_only():
    html = (HTML / "notebooks" / "performance.html").read_text()
    table = re.search(r"<table[^>]*dataframe.*?</table>", html, re.S).group(0)
    header = [html_module.unescape(re.sub(r"<[^>]+>", "", h)).strip() for h in re.findall(r"<th[^>]*>(.*?)</th>", table, re.S)]
    assert "met" in header, header
    cells = {html_module.unescape(c).strip() for c in re.findall(r"<td>([^<]*)</td>", table)}
    assert "NO" not in cells and "yes" not in cells and "reported only" in cells, sorted(cells)[:20]


@pytest.mark.parametrize("name", ["py-modindex.html", "genindex.html", "notation.html"])
def test_every_image_of_the_index_pages_exists(name):
    path = HTML / name
    if not path.exists():
        pytest.skip(f"{name} is not built")
    srcs = re.findall(r'<img[^>]*src="([^"]+)"', path.read_text())
    missing = [s for s in srcs if not s.startswith("data:") and not (path.parent / s.split("?")[0]).exists()]
    assert not missing, missing


@pytest.mark.parametrize("path", sorted((HTML / "api").glob("*.html")) if HTML.exists() else [],
                         ids=lambda p: p.name)
def test_api_pages_show_formulas_as_math_not_code(path):
    """A docstring's ``x_{k+1} = A x_k`` is rendered by MathJax, not shown as code with its braces."""
    code = [html_module.unescape(re.sub(r"<[^>]+>", "", c))
            for c in re.findall(r'<code class="docutils literal[^"]*">(.*?)</code>', path.read_text(), re.S)]
    tex = [c for c in code if re.search(r"[_^]\{|\\[A-Za-z]+", c)]
    assert not tex, tex[:5]


@pytest.mark.parametrize("chapter", sorted({s.chapter for _, s in STUDIES} | {"building_blocks", "apply_your_system",
                                                                         "apply_control_designs"}))
def test_a_tagged_equation_has_one_number(chapter):
    """An equation that carries the paper's number (``\\tag``) gets no second, Sphinx number beside it."""
    blocks = re.findall(r'<div class="[^"]*\bmath\b[^"]*"[^>]*>(.*?)</div>', _page(chapter), re.S)
    double = [b[:80] for b in blocks if 'class="eqno"' in b and "\\tag" in b]
    assert not double, double


def test_the_intro_opens_with_four_reading_paths():
    """Each question on the intro's first screen, with its one-line answer and a link to its page."""
    html = (HTML / "intro.html").read_text()
    article = html[html.index('<article class="bd-article">'):]
    first = html_module.unescape(re.sub(r"<[^>]+>", "", article))[:4000]
    targets = {"Did it reproduce?": "reproduction_report.html", "Which method for my team?": "comparing_methods.html",
               "How do I use it on my system?": "apply_your_system.html",
               "How does paper X work?": "ren2005_kalman_consensus.html"}
    for question, page in targets.items():
        assert question in first, f"{question!r} is not on the intro's first screen"
        item = re.search(rf"{re.escape(question)}</strong>(.*?)</li>", article, re.S)
        assert item and f"notebooks/{page}" in item.group(1), f"{question!r} does not link to {page}"
        assert re.search(r"\d", re.sub(r"<[^>]+>", "", item.group(1))), f"{question!r}: no computed answer"


def test_the_apply_chapter_ends_with_the_comparison():
    html = (HTML / "notebooks" / "apply_your_system.html").read_text()
    last = re.search(r'<section id="where-to-go-from-here">(.*?)</section>', html, re.S)
    assert last and "comparing_methods.html" in last.group(1), "the apply chapter does not point to the comparison"
