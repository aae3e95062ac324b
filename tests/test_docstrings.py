"""Every public class and function is documented the numpydoc way, with an Examples section (properties without).

The public objects are those of each API module's ``__all__`` (the ones the book's API
reference pages show, :data:`mascore._booktools.API_GROUPS`), plus the public methods and
properties those classes define. The examples themselves run as doctests (``make test``
passes ``--doctest-modules mascore``).
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

import pytest

numpydoc_validate = pytest.importorskip("numpydoc.validate")

from mascore._booktools import api_modules, api_page, public_objects  # noqa: E402

#: The numpydoc checks every public docstring must pass.
CHECKS = {
    "GL08": "has a docstring",
    "SS01": "has a one-line summary",
    "PR01": "documents every parameter",
    "PR02": "documents no parameter that does not exist",
    "PR07": "describes every parameter",
    "RT01": "has a Returns section if it returns something",
    "EX01": "has an Examples section",
}

BOOK_API = Path(__file__).resolve().parents[1] / "book" / "api"

def _targets(module: str) -> list[str]:
    mod = importlib.import_module(f"mascore.{module}")
    out = []
    for name in public_objects(module):
        obj = getattr(mod, name)
        out.append(f"mascore.{module}.{name}")
        if inspect.isclass(obj):
            fields = getattr(obj, "__dataclass_fields__", {})
            for attr, value in vars(obj).items():
                if attr.startswith("_") or attr in fields:  # a field's default is data, not a method
                    continue
                if inspect.isfunction(value) or isinstance(value, (classmethod, staticmethod, property)):
                    out.append(f"mascore.{module}.{name}.{attr}")
    return out


def _problems(target: str) -> list[str]:
    result = numpydoc_validate.validate(target)
    is_property = result["type"] == "property"  # a property is data: its summary says what it is, no example
    return [f"{target}: {code} {msg}" for code, msg in result["errors"]
            if code in CHECKS and not (is_property and code == "EX01")]


@pytest.mark.parametrize("module", api_modules())
def test_public_docstrings_pass_numpydoc_validation(module):
    problems = [p for target in _targets(module) for p in _problems(target)]
    assert not problems, "\n".join(problems)


def test_validation_catches_a_function_without_sections(tmp_path, monkeypatch):
    """The check above fails on an undocumented function (so it is not a test that cannot fail)."""
    (tmp_path / "undocumented_mod.py").write_text(
        '__all__ = ["f"]\n\n\ndef f(x):\n    """Return x."""\n    return x\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    codes = {code for code, _ in numpydoc_validate.validate("undocumented_mod.f")["errors"]}
    assert {"PR01", "RT01", "EX01"} <= codes


@pytest.mark.parametrize("module", api_modules())
def test_api_page_is_in_sync_with_the_module(module):
    """``book/api/<module>.md`` lists exactly the module's public objects (rewrite with `make sync`)."""
    page = BOOK_API / f"{module}.md"
    assert page.exists(), f"{page} is missing: run `make sync`"
    assert page.read_text() == api_page(module), f"{page} is out of date: run `make sync`"
