"""Tests of the reproduction ledger and of the reproduce command."""

import json

import pytest

from mascore import ledger, reproduce
from mascore.ledger import Claim

RESULTS_FIELDS = {"id", "where", "statement", "paper_value", "value", "tolerance", "verdict", "note"}


@pytest.mark.parametrize("value,tol,verdict", [
    (1.004, {"rel": 0.01}, "reproduces"),
    (1.05, {"rel": 0.01}, "approximately"),
    (1.5, {"rel": 0.01}, "does-not-reproduce"),
    ([1.0, 2.001], {"abs": 0.01}, "reproduces"),
    ([1.0, 2.5], {"abs": 0.01}, "does-not-reproduce"),
])
def test_verdict_is_computed_from_numbers(value, tol, verdict):
    paper = [1.0, 2.0] if isinstance(value, list) else 1.0
    assert Claim("ren2005/x", "Fig. 1", "s", paper, value, tol).verdict == verdict


def test_qualitative_claims():
    assert Claim.qualitative("ren2005/q", "Thm 3.2", "s", 0.1, 0.1 < 1).verdict == "holds"
    assert Claim.qualitative("ren2005/q", "Thm 3.2", "s", 3.0, 3.0 < 1).verdict == "fails"


def test_claim_refuses_bad_input():
    with pytest.raises(ValueError, match="PAPER/short-name"):
        Claim("nopaper", "w", "s", 1.0, 1.0, {"abs": 1})
    with pytest.raises(ValueError, match="tolerance"):
        Claim("ren2005/x", "w", "s", 1.0, 1.0, {"percent": 1})
    with pytest.raises(ValueError, match="shape"):
        Claim("ren2005/x", "w", "s", [1.0, 2.0], 1.0, {"abs": 1})
    with pytest.raises(ValueError, match="finite"):
        Claim.qualitative("ren2005/x", "w", "s", float("nan"), False)


def test_write_and_load_roundtrip(tmp_path):
    claims = [Claim("vlahakis/a", "w", "s", 2.0, 2.0, {"abs": 0.1}),
              Claim.qualitative("vlahakis/b", "w", "s", {"max": 1.0}, True)]
    path = ledger.write_claims(claims, tmp_path / "vlahakis" / "claims.json", "vlahakis", 3, "cmd")
    doc = json.loads(path.read_text())
    assert doc["seed"] == 3 and doc["paper"] == "vlahakis" and doc["created_by"] == "cmd"
    records = ledger.load_claims(tmp_path)
    assert [r["id"] for r in records] == ["vlahakis/a", "vlahakis/b"]
    assert set(records[0]) == RESULTS_FIELDS | {"paper"}
    assert list(ledger.claims_table(records)["verdict"]) == ["reproduces", "holds"]
    with pytest.raises(ValueError, match="duplicate"):
        ledger.write_claims(claims * 2, tmp_path / "x.json", "vlahakis", 3, "cmd")


def test_cli_rejects_unknown_paper(capsys):
    with pytest.raises(SystemExit):
        reproduce.main(["reproduce", "nosuchpaper"])
    assert "invalid choice" in capsys.readouterr().err


@pytest.mark.parametrize("value,text", [
    (None, "\u2014"),
    (3, "3"),
    (2.4615707509952616, "2.462"),
    (True, "True"),
    ([1.0, 2.0, 3.0, 4.0, 5.0], "[1, 2, 3, 4, \u2026]"),
    ({"a": 0.123456, "b": {"c": 1e-12}}, "a: 0.1235; b: {c: 1e-12}"),
])
def test_format_value_is_short_and_exact_to_four_digits(value, text):
    assert ledger.format_value(value) == text


def test_show_claims_lays_out_one_row_and_one_note_per_claim():
    claims = [Claim("vlahakis/a", "Fig. 1 | left", "s", 2.0, 2.0004, {"abs": 0.1}, note="a note"),
              Claim.qualitative("vlahakis/b", "w", "s", {"max": 1.0}, False)]
    text = ledger.show_claims([claims[0], claims[1].to_dict()])._repr_markdown_()
    rows = [line for line in text.splitlines() if line.startswith("| **")]
    assert len(rows) == 2
    assert rows[0].count(" | ") == 4  # the '|' inside 'where' is escaped, not a new column
    assert rows[0].startswith("| **reproduces** | a |") and rows[0].endswith("| 2 | 2 |")
    assert rows[1].startswith("| **fails** | b |")
    assert "- `a`: a note" in text and "`b`:" not in text
