"""Test configuration: property-based tests draw the same examples on every run.

``make test`` and CI must give the same verdict on the same commit, so Hypothesis runs
derandomized (its examples follow from each test's code). To explore new random examples
locally, run ``HYPOTHESIS_PROFILE=explore pytest ...``.
"""

import os

import pytest
from hypothesis import settings

# The test processes draw without a display. The variable MPLBACKEND is not set for them: the notebooks'
# kernels that nbmake starts inherit the environment and need ipykernel's inline backend to keep figures.
try:
    import matplotlib
except ImportError:  # the core's tests on its minimum versions (make test-min) have no matplotlib
    pass
else:
    matplotlib.use("Agg")

settings.register_profile("reproducible", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "reproducible"))


# ---------------------------------------------------------------- the published results


@pytest.fixture(scope="session")
def published():
    """``published(paper) -> (folder, claims)``: the ledger `make test` reproduced before pytest.

    ``make test`` runs ``python -m mascore reproduce all --out results`` (and the quick
    comparison) first, so the tests about a paper's published ledger read it from
    ``results/`` (:func:`mascore.reproduce.results_dir`) instead of running the study
    again. The folder's figures and tables are checked against the ledger's hashes
    (:func:`mascore.ledger.verify_outputs`); the claims come back as
    :class:`mascore.ledger.Claim`, their verdicts recomputed from their numbers.
    """
    from mascore.ledger import Claim, verify_outputs
    from mascore.reproduce import results_dir

    def load(paper: str):
        folder = results_dir() / paper
        if not (folder / "claims.json").exists():
            pytest.skip(f"{folder / 'claims.json'} not found: run `make reproduce` (make test does it first)")
        doc = verify_outputs(folder)
        claims = [Claim.from_dict(record) for record in doc["claims"]]
        for claim, record in zip(claims, doc["claims"]):
            assert claim.verdict == record["verdict"], f"{record['id']}: verdict does not follow from its numbers"
        return folder, claims

    return load

