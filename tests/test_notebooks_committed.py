"""Notebooks are committed clean: valid nbformat 4.5 with cell ids, no outputs, in the book.

nbmake (run by `make test`) executes them; these checks keep what is committed
small, diffable and loadable by future nbformat versions.
"""

import json
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_is_clean_and_has_cell_ids(path):
    nb = json.loads(path.read_text())
    assert (nb["nbformat"], nb["nbformat_minor"]) >= (4, 5)
    ids = [cell.get("id") for cell in nb["cells"]]
    assert all(ids), f"{path.name}: cells without an id at {[i for i, x in enumerate(ids) if not x]}"
    assert len(set(ids)) == len(ids), f"{path.name}: duplicate cell ids"
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            assert not cell["outputs"] and cell["execution_count"] is None, f"{path.name}: outputs committed"
    assert nb["metadata"].get("kernelspec", {}).get("name") == "python3", f"{path.name}: no python3 kernelspec"


def test_every_notebook_is_in_the_book():
    toc = yaml.safe_load((ROOT / "book" / "_toc.yml").read_text())
    def files_of(entries):  # chapters and their sections (sub-pages), at any depth
        for entry in entries:
            if "file" in entry:
                yield entry["file"]
            yield from files_of(entry.get("sections", []))

    files = set(files_of(ch for part in toc["parts"] for ch in part["chapters"]))
    missing = [p.stem for p in NOTEBOOKS if f"notebooks/{p.stem}" not in files]
    assert NOTEBOOKS and not missing, f"notebooks missing from book/_toc.yml: {missing}"
