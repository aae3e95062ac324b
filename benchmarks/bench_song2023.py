"""One estimation-based filter step (Song et al. 2023, eqs. (14), (29)-(34), (16)-(20)) against N.

Compares the structured implementation (tensor form of the augmented
prediction, Kronecker factor of the double integrator, masked batched update;
``mascore.distributed_kf.eb_predict`` + ``eb_update``) with the plain one
written straight from the equations (``plain_estimation_based_step``: dense
``F_1``, ``F_2``, ``H_i``, ``G_i`` and a loop over agent pairs). Both advance
the full augmented covariance of all ``N`` agents' whole-team estimates
(size ``2nN^2``) and all N estimates, for one topology (a ring).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from mascore import distributed_kf as dk
from mascore.agents import double_integrator
from mascore.graphs import laplacian, ring_graph
from mascore.rendezvous import rendezvous_gain
from mascore.sensing import measure, stacked_measurement

from .timing import median_time

SIZES = (4, 8, 16, 32)


def _case(N: int):
    agent = double_integrator(2, 0.1)
    K = rendezvous_gain(0.5, 1.5, 2)
    model = dk.team_filter_model(agent.A, agent.B, K, np.eye(4), np.eye(4), N)
    rng = np.random.default_rng(N)
    adj = ring_graph(N)
    Sig = dk.eb_initial_covariance(model, np.diag([100.0, 100.0, 1.0, 1.0]), common=False)
    Xh = rng.normal(size=(1, N, N, 4))
    Z, S = measure(rng, rng.normal(size=(1, N, 4)), adj, np.eye(4))
    return agent, model, adj, Sig, Xh, Z, S


def run() -> pd.DataFrame:
    """Seconds per estimator step for each N, structured vs plain."""
    rows = []
    for N in SIZES:
        agent, model, adj, Sig, Xh, Z, S = _case(N)
        L = laplacian(adj)

        def structured():
            Xp, Sp = dk.eb_predict(model, Xh, Sig, L)
            return dk.eb_update(model, Xp, Sp, Z, S[0])

        t_s = median_time(structured, repeat=5 if N <= 16 else 3)
        Sig_full = dk.expand_covariance(Sig[0], model.kron)
        z = [stacked_measurement(Z[0], S[0], i) for i in range(N)]

        def plain():
            return dk.plain_estimation_based_step(
                Xh[0].reshape(N, -1), Sig_full, agent.A, model.BK, np.eye(4), model.R, adj, z)

        t_p = median_time(plain, repeat=3 if N <= 16 else 1)
        rows.append({"N": N, "augmented_dim": 4 * N * N, "structured_s": t_s, "plain_s": t_p,
                     "speedup": t_p / t_s})
    return pd.DataFrame(rows)


if __name__ == "__main__":  # pragma: no cover
    print(run().to_string(index=False))
