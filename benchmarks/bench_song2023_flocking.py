"""Cost of one step of the per-agent EKF bank of Song et al. (2023), Sec. III-B, against N.

One step for all N agents = masked update (eqs. (16)-(20)), control on the own
estimate (eq. (39)) and prediction through f' with its Jacobian (eqs. (38),
(40)), batched over the agents. The state of each filter has size 4N, so the
covariance work grows like N * (4N)^3 = 64 N^4. For N <= 16 the same step is
also timed as a Python loop over agents with the paper's selection matrices
H_i and :func:`mascore.kalman.update` (reference implementation).
"""

from dataclasses import replace

import numpy as np
import pandas as pd

from benchmarks.timing import median_time
from mascore import distributed_ekf as dekf
from mascore import flocking, kalman, sensing
from mascore.graphs import proximity_graph
from mascore.papers import song2023_flocking as s


def _setup(N: int, rng: np.random.Generator):
    X = s.initial_states(rng, 1, replace(s.SETTINGS, n_agents=N))[0]
    X_hat = X[None] + rng.standard_normal((N, N, 4))
    M = 4 * N
    Sigma = np.broadcast_to(np.kron(np.eye(N), s.SIGMA0_AGENT), (N, M, M)).copy()
    A = proximity_graph(X[:, :2], s.SENSING_RANGE)
    Z, S = sensing.measure(rng, X, A, s.R_FIG5, allow_isolated=True)
    R = np.kron(np.eye(N), s.R_FIG5)
    Q = np.kron(np.eye(N), s.Q_AGENT)
    return X_hat, Sigma, Z, S, A, R, Q


def _batched_step(X_hat, Sigma, Z, S, R, Q):
    return dekf.ekf_flocking_step(X_hat, Sigma, Z, S, R, s.DT, s.GAINS, Q)


def _loop_step(X_hat, Sigma, Z, S, A, R, Q):
    N = X_hat.shape[0]
    out = []
    for i, H in enumerate(sensing.selection_matrices(A, 4, allow_isolated=True)):
        x, P = kalman.update(X_hat[i].ravel(), Sigma[i], sensing.stacked_measurement(Z, S, i), H, H @ R @ H.T)
        Xi = x.reshape(N, 4)
        u_i = flocking.flocking_control(Xi, s.GAINS)[i]
        F = flocking.closed_loop_jacobian(Xi, s.DT, s.GAINS)
        out.append((u_i, kalman.predict(flocking.closed_loop_step(Xi, s.DT, s.GAINS).ravel(), P, F, Q)))
    return out


def run(sizes=(8, 16, 32, 64)) -> pd.DataFrame:
    """Median wall time (s) of one step of all N filters, batched, and (N <= 16) looped.

    The two implementations are checked to agree before they are timed.
    """
    rng = np.random.default_rng(0)
    rows = []
    for N in sizes:
        X_hat, Sigma, Z, S, A, R, Q = _setup(N, rng)
        if N <= 16:  # same numbers from both implementations
            batched = _batched_step(X_hat, Sigma, Z, S, R, Q)
            for i, (u_i, (x_next, P_next)) in enumerate(_loop_step(X_hat, Sigma, Z, S, A, R, Q)):
                np.testing.assert_allclose(batched[2][i], u_i, rtol=1e-8, atol=1e-8)
                np.testing.assert_allclose(batched[4][i], P_next, rtol=1e-8, atol=1e-6)
        repeat = 7 if N <= 16 else 3
        row = {"N": N, "filter_state_size": 4 * N,
               "batched_step_s": median_time(lambda: _batched_step(X_hat, Sigma, Z, S, R, Q), repeat=repeat)}
        row["loop_over_agents_step_s"] = (
            median_time(lambda: _loop_step(X_hat, Sigma, Z, S, A, R, Q), repeat=3) if N <= 16 else np.nan
        )
        rows.append(row)
    return pd.DataFrame(rows)


if __name__ == "__main__":
    print(run().to_string(index=False))
