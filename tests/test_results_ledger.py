"""Checks on the ledgers written by `python -m mascore reproduce all` and `python -m mascore compare`
(run by `make test` first).

Each claims.json must follow shared/REPRODUCTION.md, hold the claim ids the
issues require, and carry verdicts that recompute from its own numbers.
"""

import json

import pytest

from mascore.ledger import VERDICTS, Claim
from mascore.registry import ledger_keys
from mascore.reproduce import results_dir

REQUIRED = {
    "song2023": ["fig2-error-matches-covariance", "fig3-position-std", "fig3-velocity-std",
                 "theorem1-lyapunov-decrease", "fig4-non-neighbour-error-bounded",
                 "fig5-position-std", "fig5-velocity-std", "fig6-within-boundary", "nees-rendezvous",
                 "nees-rendezvous-measurement-based"],
    "ren2005": ["fig1-consensus-equal", "fig1-confident-agent-dominates", "thm32-continuous-consensus",
                "thm39-switching-union-consensus", "no-spanning-tree-no-consensus",
                "noise-consensus-approximate", "beyond-fusion-bias", "beyond-overconfidence"],
    "bhattacharjee2021": ["lemma2-r", "coupling-gain-c", "bound-eq21", "fig2c-Ac-bound", "fig6-trace-limit",
                          "table1-row1-mean", "table1-row1-rms", "table1-row2-mean", "table1-row2-rms",
                          "table1-row3-mean", "table1-row3-rms", "containment"],
    "vlahakis": ["example1-L", "example1-phi-q2-5", "example1-J-q2-5", "example1-phi-q2-25",
                 "example1-J-q2-25", "example1-hurwitz", "fig2-faster-than-fig1", "structure-eq13"],
}


def _ledger(paper):
    path = results_dir() / paper / "claims.json"
    if not path.exists():
        pytest.skip(f"{path} not found: run `make reproduce` (make test does it first)")
    return json.loads(path.read_text())


@pytest.mark.parametrize("paper", ledger_keys())
def test_ledger_format_and_verdicts(paper):
    doc = _ledger(paper)
    assert doc["paper"] == paper
    assert {"seed", "mascore_version", "created_by", "claims"} <= set(doc)
    for record in doc["claims"]:
        assert record["id"].startswith(paper + "/")
        assert record["verdict"] in VERDICTS
        assert record["where"] and record["statement"]
        if record["paper_value"] is not None:
            recomputed = Claim.from_dict(record)
            assert recomputed.verdict == record["verdict"], record["id"]
            kind = "rel" if "rel" in record["tolerance"] else "abs"
            assert record["tolerance"][f"approx_{kind}"] <= 3 * record["tolerance"][kind] * (1 + 1e-9) \
                or record.get("band_reason"), f"{record['id']}: band wider than 3t without a reason"
        else:
            assert record["verdict"] in ("holds", "fails", "undecided") and record["tolerance"] is None


@pytest.mark.parametrize("paper", ledger_keys())
def test_required_claims_present(paper):
    ids = {c["id"] for c in _ledger(paper)["claims"]}
    assert ids, f"{paper}: an empty ledger"
    missing = [name for name in REQUIRED.get(paper, ()) if f"{paper}/{name}" not in ids]
    assert not missing, f"{paper} ledger lacks {missing}"
