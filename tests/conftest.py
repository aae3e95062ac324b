"""Test configuration: property-based tests draw the same examples on every run.

``make test`` and CI must give the same verdict on the same commit, so Hypothesis runs
derandomized (its examples follow from each test's code). To explore new random examples
locally, run ``HYPOTHESIS_PROFILE=explore pytest ...``.
"""

import os

from hypothesis import settings

settings.register_profile("reproducible", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "reproducible"))
