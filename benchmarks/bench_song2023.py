"""One estimation-based filter step (Song et al. 2023, eqs. (14), (29)-(34), (16)-(20)) against N.

Compares the structured implementation (tensor form of the augmented
prediction, Kronecker factor of the double integrator, masked batched update;
``mascore.distributed_kf.eb_predict`` + ``eb_update``) with the plain one
written straight from the equations (``plain_estimation_based_step``: dense
``F_1``, ``F_2``, ``H_i``, ``G_i`` and a loop over agent pairs). Both advance
the full augmented covariance of all ``N`` agents' whole-team estimates
(size ``2nN^2``) and all N estimates, for one topology (a ring); the case is
``mascore.papers.song2023.estimator_step_seconds``, which the book also uses.
"""

from __future__ import annotations

import pandas as pd

from mascore.papers.song2023 import estimator_step_seconds

SIZES = (4, 8, 16, 32)


def run() -> pd.DataFrame:
    """Seconds per estimator step for each N, structured vs plain."""
    rows = []
    for N in SIZES:
        times = estimator_step_seconds(N, repeat=5 if N <= 16 else 3, plain_repeat=3 if N <= 16 else 1)
        rows.append({"N": N, "augmented_dim": 4 * N * N, **times})
    return pd.DataFrame(rows)


if __name__ == "__main__":  # pragma: no cover
    print(run().to_string(index=False))
