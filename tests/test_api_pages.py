"""The API reference: every public object documented exactly once, no page too long to read.

The pages ``book/api/*.md`` are written by ``make sync`` (:func:`mascore._booktools.write_api_pages`):
a page per module, and for the modules of :data:`mascore._booktools.API_TOPICS` sub-pages by topic, nested
under their module in ``book/_toc.yml``. The built pages' words are measured in Chromium with the reading
pages (tests/test_book_html.py).
"""

from __future__ import annotations

import re
import shutil
from collections import Counter
from pathlib import Path

import pytest
import yaml

from mascore import _booktools
from mascore._booktools import (
    API_TOPICS,
    api_modules,
    api_pages,
    public_objects,
    toc_with_api_pages,
    write_api_pages,
)

ROOT = Path(__file__).resolve().parents[1]

_ENTRY = re.compile(r"^\.\. auto(?:function|class):: (\w+)$", re.M)


def entries(pages: dict[str, str]) -> Counter:
    """How often each object has an autodoc entry on `pages` (file name -> MyST text)."""
    return Counter(name for text in pages.values() for name in _ENTRY.findall(text))


def table(page: str) -> list[str]:
    """The names of the autosummary table of a module's page."""
    m = re.search(r"\.\. autosummary::\n   :nosignatures:\n\n((?:   \w+\n)+)", page)
    return m.group(1).split() if m else []


@pytest.mark.parametrize("module", api_modules())
def test_every_public_object_has_exactly_one_entry_and_a_row_in_its_modules_table(module):
    pages = api_pages(module)
    objects = public_objects(module)
    counts = entries(pages)
    twice = sorted(n for n, c in counts.items() if c > 1)
    missing = sorted(set(objects) - set(counts))
    extra = sorted(set(counts) - set(objects))
    assert not (twice or missing or extra), f"mascore.{module}: documented twice {twice}, nowhere {missing}, " \
                                            f"not public {extra}"
    assert table(pages[f"{module}.md"]) == objects


def test_api_topics_name_modules_of_the_reference_and_each_sub_page_takes_objects():
    assert set(API_TOPICS) <= set(api_modules()), set(API_TOPICS) - set(api_modules())
    for module in API_TOPICS:
        pages = api_pages(module)
        assert len(pages) == 1 + len(API_TOPICS[module])
        for fname, text in pages.items():
            assert fname == f"{module}.md" or _ENTRY.search(text), f"{fname} documents nothing"


def test_a_new_name_in_no_topic_stays_on_its_modules_page(monkeypatch):
    """A public object no sub-page takes is documented on the module's page, not dropped."""
    monkeypatch.setitem(API_TOPICS, "compare", API_TOPICS["compare"][:2])  # "tables" and "plots" in no topic
    pages = api_pages("compare")
    on_page = set(_ENTRY.findall(pages["compare.md"]))
    assert {"headline", "plot_pareto", "knob_table"} <= on_page
    assert not on_page & set(_ENTRY.findall(pages["compare.tasks.md"]))
    assert sum(entries(pages).values()) == len(public_objects("compare"))
    assert "below it, or on" in pages["compare.md"]


def test_a_topic_that_takes_nothing_is_an_error(monkeypatch):
    monkeypatch.setitem(API_TOPICS, "fusion", (("gone", "Gone", ("no_such_submodule",)),))
    with pytest.raises(ValueError, match=r"API_TOPICS\['fusion'\]: the sub-page 'gone' takes no public object"):
        api_pages("fusion")


def test_topics_follow_the_submodules_of_a_package_and_the_kinds_of_a_module():
    assert _booktools.topic_key("compare", "headline") == "tables"  # defined in mascore.compare.tables
    assert _booktools.topic_key("fusion", "CentralizedFilter") == "classes"
    assert _booktools.topic_key("fusion", "track") == "functions"


def test_api_pages_and_the_table_of_contents_are_in_sync(tmp_path):
    """``book/api`` and the API part of ``book/_toc.yml`` are what `make sync` writes."""
    shutil.copytree(ROOT / "book" / "api", tmp_path / "api")
    shutil.copy(ROOT / "book" / "_toc.yml", tmp_path / "_toc.yml")
    assert write_api_pages(tmp_path / "api") == 0, "book/api or book/_toc.yml is out of date: run `make sync`"


def test_sub_pages_are_nested_under_their_module_in_the_table_of_contents():
    toc = yaml.safe_load((ROOT / "book" / "_toc.yml").read_text())
    reference = [c for part in toc["parts"] for c in part["chapters"] if c.get("file") == "api/index"][0]
    modules = {s["file"]: [c["file"] for c in s.get("sections", [])] for s in reference["sections"]}
    assert list(modules) == [f"api/{m}" for m in api_modules()]
    for module, topics in API_TOPICS.items():
        assert modules[f"api/{module}"] == [f"api/{module}.{slug}" for slug, _, _ in topics]


def test_the_table_of_contents_keeps_everything_but_the_api_sections():
    toc = ("parts:\n  - caption: Reference\n    chapters:\n      - file: api/index\n        sections:\n"
           "          - glob: api/*\n\n  - caption: After\n    chapters:\n      - file: z\n")
    new = toc_with_api_pages(toc, "api", [["a.md"], ["b.md", "b.x.md"]])
    assert new.startswith("parts:\n  - caption: Reference\n    chapters:\n      - file: api/index\n        sections:")
    assert new.endswith("  - caption: After\n    chapters:\n      - file: z\n")
    assert "glob" not in new
    sections = yaml.safe_load(new)["parts"][0]["chapters"][0]["sections"]
    assert sections == [{"file": "api/a"}, {"file": "api/b", "sections": [{"file": "api/b.x"}]}]
    assert toc_with_api_pages(new, "api", [["a.md"], ["b.md", "b.x.md"]]) == new
    with pytest.raises(ValueError, match="no entry '- file: api/index'"):
        toc_with_api_pages("parts: []\n", "api", [])
