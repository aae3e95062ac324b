"""Tests of the reproduction ledger and of the reproduce command."""

import json

import pytest

from mascore import ledger, reproduce
from mascore.formatting import math_text
from mascore.ledger import Claim

RESULTS_FIELDS = {"id", "where", "statement", "paper_value", "value", "tolerance", "verdict", "note"}


@pytest.mark.parametrize("value,tol,verdict", [
    (1.004, {"rel": 0.01}, "reproduces"),
    (1.025, {"rel": 0.01}, "approximately"),
    (1.05, {"rel": 0.01}, "does-not-reproduce"),  # 5 tolerances: outside the default 3t band
    (1.05, {"rel": 0.01, "approx_rel": 0.02}, "does-not-reproduce"),
    (1.5, {"rel": 0.01}, "does-not-reproduce"),
    ([1.0, 2.001], {"abs": 0.01}, "reproduces"),
    ([1.0, 2.5], {"abs": 0.01}, "does-not-reproduce"),
])
def test_verdict_is_computed_from_numbers(value, tol, verdict):
    paper = [1.0, 2.0] if isinstance(value, list) else 1.0
    assert Claim("ren2005/x", "Fig. 1", "s", paper, value, tol).verdict == verdict


def test_band_is_explicit_and_at_most_three_tolerances_without_a_reason():
    claim = Claim("ren2005/x", "Fig. 1", "s", 1.0, 1.0, {"rel": 0.05})
    assert claim.tolerance == {"rel": 0.05, "approx_rel": 0.15}
    with pytest.raises(ValueError, match="band_reason"):
        Claim("ren2005/x", "Fig. 1", "s", 1.0, 1.2, {"rel": 0.05, "approx_rel": 0.5})
    wide = Claim("ren2005/x", "Fig. 1", "s", 1.0, 1.2, {"rel": 0.05, "approx_rel": 0.5}, band_reason="read off a plot")
    assert wide.verdict == "approximately"
    with pytest.raises(ValueError, match="approx_rel"):
        Claim("ren2005/x", "Fig. 1", "s", 1.0, 1.0, {"rel": 0.05, "approx_rel": 0.01})


def test_claims_roundtrip_through_json_records():
    claims = [Claim("ren2005/x", "Table 1", "s", [1.0, 2.0], [1.1, 2.0], {"rel": 0.05}, labels=("a", "b"), unit="m"),
              Claim.qualitative("ren2005/q", "Thm 3.2", "s", {"max ratio": 0.4}, False, rule="max ratio < 0.1")]
    for c in claims:
        again = Claim.from_dict(json.loads(json.dumps(c.to_dict())))
        assert again == c and again.verdict == c.verdict


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
    (True, "yes"),
    (False, "no"),
    (0.076812, "0.07681"),
    (5.000000e-02, "0.05"),
    (2.7755575615628914e-17, "2.776 \u00d7 10\u207b\u00b9\u2077"),
    (12345.6, "12,346"),
    ([1.0, 2.0, 3.0, 4.0, 5.0], "[1, 2, 3, 4, \u2026]"),
    ({"a_b": 0.123456, "c": {"d": 1e-12}}, "a b = 0.1235; c = (d = 1 \u00d7 10\u207b\u00b9\u00b2)"),
])
def test_format_value_is_short_and_exact_to_four_digits(value, text):
    assert ledger.format_value(value) == text


def test_format_value_labels_and_units():
    assert ledger.format_value([136.4, 75.48], unit="s", labels=["a", "b"]) == "a: 136.4; b: 75.48 (s)"
    assert ledger.format_value(0.5, unit="m") == "0.5\u00a0m"


def test_show_claims_numbers_claims_states_them_and_prints_a_shared_note_once():
    shared = "The same long explanation."
    claims = [Claim("vlahakis/a", "Fig. 1 | left", "First statement.", 2.0, 2.0004, {"abs": 0.1},
                    note="own a\n\n" + shared),
              Claim.qualitative("vlahakis/b", "w", "Second statement.", {"max": 1.0}, False, note=shared,
                                rule="max < 1")]
    text = ledger.show_claims([claims[0], claims[1].to_dict()])._repr_markdown_()
    rows = [line for line in text.splitlines() if line.startswith("| 1 ") or line.startswith("| 2 ")]
    assert len(rows) == 2
    assert rows[0].count(" | ") == 4  # the '|' inside 'where' is escaped, not a new column
    assert "First statement." in rows[0] and "**reproduces**" in rows[0] and "tolerance 0.1" in rows[0]
    assert "**fails**" in rows[1] and "Decided by:* max < 1" in rows[1]
    assert text.count(shared) == 1 and "Claims 1, 2." in text and "Claim 1.* own a" in text


def test_ledger_table_and_summary_show_ascii_symbols_as_math_and_leave_written_math_alone():
    claim = Claim("bhattacharjee2021/a", "Table 1", "Mean of |delta_bar_k| with alpha_w = 0.05.", 1.0, 1.5,
                  {"rel": 0.05})
    rule = Claim.qualitative("bhattacharjee2021/b", "Fig. 2", "|A_c^k| <= 1.1 * 0.9^k for all k.", {"max": 1.0},
                             True, rule="max over k of |A_c^k| / (alpha mu^k) <= 1")
    table = ledger.show_claims([claim, rule])._repr_markdown_()
    summary = ledger.ledger_summary([claim, rule])
    for text in (table, summary):
        assert r"$\lvert \bar{\delta}_{k} \rvert$" in text and r"$\alpha_{w}$" in text
        assert "|delta_bar_k|" not in text and "alpha_w" not in text
    assert r"$\lvert A_{c}^{k} \rvert$ ≤ 1.1 × $0.9^{k}$" in table and "<=" not in table
    written = r"spread $\sqrt{\mathrm{mean}_i \lVert y_i - \bar y\rVert^2}$ of P_0"
    assert math_text(written) == r"spread $\sqrt{\mathrm{mean}_i \lVert y_i - \bar y\rVert^2}$ of $P_{0}$"


def test_write_claims_refuses_an_unknown_ledger_or_a_foreign_claim(tmp_path):
    claim = Claim("vlahakis/a", "w", "s", 2.0, 2.0, {"abs": 0.1})
    with pytest.raises(ValueError, match="paper must be one of"):
        ledger.write_claims([claim], tmp_path / "claims.json", "vlahakis2", 1, "cmd")
    with pytest.raises(ValueError, match="ids 'ren2005/...'"):
        ledger.write_claims([claim], tmp_path / "claims.json", "ren2005", 1, "cmd")


@pytest.mark.parametrize("value,verdict,sentence", [
    (1.00736, "reproduces", "0.736 % off; tolerance 5 %"),
    (1.099, "approximately", "9.9 % off; tolerance 5 %, approximately within 15 %"),
    (1.4, "does-not-reproduce", "40 % off; more than the 15 % of 'approximately'"),
])
def test_one_verdict_sentence_per_number_agrees_with_the_verdict(value, verdict, sentence):
    """The ledger's verdict cell says the verdict once, in words, and a deviation sentence that does not
    contradict it (no 'reproduces within 5 %' under a number that does not)."""
    record = Claim("ren2005/x", "Fig. 1", "A number.", 1.0, value, {"rel": 0.05}).to_dict()
    assert record["verdict"] == verdict
    assert ledger.deviation_sentence(record).replace("\xa0", " ") == sentence
    cell = ledger._verdict_text(record).replace("\xa0", " ")
    assert cell == f"**{ledger.verdict_words(verdict)}**<br>{sentence}"
    assert "-" not in cell.split("<br>")[0] and cell.count("reproduce") <= 1


def test_verdict_words_refuses_an_unknown_verdict():
    with pytest.raises(ValueError, match="verdict must be one of"):
        ledger.verdict_words("reproduced")


def test_deviation_sentence_carries_the_unit_of_an_absolute_tolerance():
    record = Claim("ren2005/x", "Fig. 1", "A number.", 1.5, 1.56, {"abs": 0.05}, unit="m").to_dict()
    assert ledger.deviation_sentence(record).replace("\xa0", " ") == "0.06 m off; tolerance 0.05 m, approximately within 0.15 m"


def test_why_is_kept_in_the_record():
    claim = Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.4, {"rel": 0.05}, why="The paper rounds.")
    assert claim.to_dict()["why"] == "The paper rounds." and Claim.from_dict(claim.to_dict()) == claim
    assert "why" not in Claim("ren2005/x", "Fig. 1", "A number.", 1.0, 1.0, {"rel": 0.05}).to_dict()


def _paper_records():
    ok = Claim("ren2005/a", "Sec. 2", "A number.", 2.0, 2.01, {"rel": 0.01}).to_dict() | {"paper": "ren2005"}
    off = Claim("ren2005/b", "Sec. 3", "Another.", 2.0, 3.0, {"rel": 0.01},
                note="Ours is run 0.\n\nThe gap is systematic: the paper rounds.").to_dict() | {"paper": "ren2005"}
    told = Claim("ren2005/c", "Sec. 4", "A third.", 2.0, 3.0, {"rel": 0.01}, note="Ours.",
                 why="The printed value is a misprint.").to_dict() | {"paper": "ren2005"}
    return ok, off, told


def test_report_names_papers_and_verdicts_in_words():
    from mascore.report import verdict_summary

    table = verdict_summary(list(_paper_records()))
    assert list(table.index) == ["Ren, Beard and Kingston 2005", "all papers"]
    assert list(table.columns) == ["reproduces", "does not reproduce", "total"]


def test_report_says_why_each_claim_to_look_at_is_there():
    from mascore.report import attention_list

    text = str(attention_list(list(_paper_records()))).replace("\xa0", " ")
    header, _, *rows = text.splitlines()
    assert header == "| verdict | paper, where | claim | why |" and len(rows) == 2
    assert rows[0].endswith("| 50 % off; more than the 3 % of 'approximately'. The gap is systematic: the paper rounds. |")
    assert rows[1].endswith("| 50 % off; more than the 3 % of 'approximately'. The printed value is a misprint. |")
    assert "does-not-reproduce" not in text and "ren2005 " not in text and "**does not reproduce**" in text


def test_report_takes_the_why_its_paper_module_states(monkeypatch):
    from mascore.papers import ren2005
    from mascore.report import attention_list

    monkeypatch.setattr(ren2005, "WHY", {"ren2005/b": "The paper's schedule is not ours."}, raising=False)
    rows = str(attention_list([_paper_records()[1]])).splitlines()
    assert rows[2].endswith("'approximately'. The paper's schedule is not ours. |")


def test_ledger_summary_says_one_number_in_words():
    one = Claim("ren2005/a", "Fig. 1", "A number.", 2.0, 2.01, {"rel": 0.05})
    statement = Claim.qualitative("ren2005/b", "Sec. 2", "A statement.", {"x": 1.0}, False, rule="x < 1")
    assert ledger.ledger_summary([one]) == "The one published number checked here reproduces."
    assert ledger.ledger_summary([one, statement]).splitlines()[0] == (
        "The one published number checked here reproduces. Its one statement without a number fails.")
    assert ledger.ledger_summary([statement]).splitlines()[0] == (
        "The paper prints no number we check; its one statement without a number fails.")


def test_intro_names_the_closest_methods_in_words_not_by_their_table_ids():
    from mascore.report import method_words, reading_paths

    ok = Claim("ren2005/a", "Sec. 2", "A number.", 2.0, 2.01, {"rel": 0.01}).to_dict() | {"paper": "ren2005"}
    best = {"common target": ("hcmci-L5", 1.03), "own state": ("forwarding", 1.0)}
    line = str(reading_paths([ok], best)).splitlines()[1]
    assert "common target: HCMCI with 5 consensus steps, RMSE 1.03" in line and "own state: forwarding, RMSE 1.00" in line
    assert "hcmci-L5" not in line and "`forwarding`" not in line
    assert method_words("ci-L1") == "CI with 1 consensus step" and method_words("icf-L5") == "ICF with 5 consensus steps"


def test_deviation_of_a_vector_names_its_worst_entry():
    record = Claim("vlahakis/v", "Sec. 5", "A gain.", [2.6, 22.8], [2.1, 2.05], {"abs": 1e-4}).to_dict()
    assert ledger.deviation_sentence(record).startswith("worst entry 20.75 off;")
    scalar = Claim("vlahakis/s", "Sec. 5", "A number.", 2.0, 3.0, {"abs": 1e-4}).to_dict()
    assert ledger.deviation_sentence(scalar).startswith("1 off;")


def test_the_ledger_marks_claims_not_decided_on_held_out_data_or_changed_after_it():
    """A reader of the ledger sees, beside each verdict, a claim changed after its data were seen and one decided
    (wholly or partly) on the seed blocks it was written from; a claim decided on held-out blocks has no mark."""
    base = {"where": "w", "statement": "s", "verdict": "holds", "written_from": "seed blocks 0-1"}
    records = [
        {**base, "id": "compare/held-out", "decided_on": "seed blocks 2-3 (held out)"},
        {**base, "id": "compare/in-sample", "decided_on": "seed blocks 0-1: the blocks it was written from"},
        {**base, "id": "compare/partly", "decided_on": "seed blocks 2-3 (held out) where the sweep has them, else 0-1"},
        {**base, "id": "compare/post-hoc", "decided_on": "seed blocks 2-3 (held out)", "post_hoc": "Loosened."},
    ]
    rows = [line for line in str(ledger.show_claims(records)).splitlines() if line.startswith("| ")][1:]
    assert "written from" not in rows[0] and "seen" not in rows[0]
    assert "*decided on the blocks it was written from*" in rows[1]
    assert "*partly decided on the blocks it was written from*" in rows[2]
    assert "*changed after the data were seen*" in rows[3] and "written from" not in rows[3]


def test_checks_of_our_own_are_counted_apart_from_the_papers_claims():
    """A claim the paper does not state (own_check) keeps its verdict but is not counted as the paper's."""
    from mascore.ledger import ledger_summary
    from mascore.report import reading_paths, verdict_summary

    paper = Claim("ren2005/a", "Fig. 1", "A number.", 2.0, 2.01, {"rel": 0.05})
    ours = Claim.qualitative("ren2005/b", "beyond the paper", "A check of ours.", {"gap": 0.0}, True,
                             rule="gap >= 0", own_check="a reference the paper does not give")
    assert Claim.from_dict(ours.to_dict()) == ours and ours.to_dict()["own_check"].startswith("a reference")
    assert "own_check" not in paper.to_dict()
    text = ledger_summary([paper, ours]).splitlines()[0]
    assert text == "The one published number checked here reproduces. Beside them, one check of our own, which holds."
    records = [c.to_dict() | {"paper": "ren2005"} for c in (paper, ours)]
    assert "All 1 published claims reproduce or hold; beside them, 1 of 1 checks of our own hold" in \
        str(reading_paths(records))
    assert "a check of our own" in str(ledger.show_claims([ours])) and "our own" not in str(ledger.show_claims([paper]))
    table = verdict_summary(records)
    assert table.loc["all papers", "total"] == 2 and table.loc["all papers", "of them, our own checks"] == 1
