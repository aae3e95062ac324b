"""Each scenario's bound and floor against an independent computation, within the Monte Carlo interval.

The comparison's headline tables divide every method's RMSE by the centralized filter's
(own state, common target, localization) or the central fusion's (shared quantity). These
tests check both ends of each scale: the bound and the method that does not cooperate agree
with a steady-state DARE (own state) or the exact expected error of the fusion (shared
quantity), within twice the half-width of the 95 % interval of 200 runs. The common target and
localization are checked in ``test_compare.py`` (DARE and ``fusion.error_covariance``).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from mascore import compare

RUNS = 200


def _posterior_position_mse(n_measurements: int) -> float:
    """Steady-state posterior MSE (m²) of one agent's planar position from `n_measurements` full-state measurements.

    The agents' states are independent and every measurement sees one agent's full state, so the
    centralized filter's error for agent i is that of a Kalman filter on ``x_i`` alone, whose
    ``n`` measurements of covariance ``R`` are one of covariance ``R / n``.
    """
    s = compare.SETTINGS
    team = compare.team_setup(4, "gaussian", 1.0, s)
    R = team.R / n_measurements
    prior = sla.solve_discrete_are(team.A.T, np.eye(4), team.Q, R)
    posterior = prior - prior @ np.linalg.solve(prior + R, prior)
    return float(np.trace(posterior[:2, :2]))


def _within_interval(per_run_mse: np.ndarray, expected: float) -> tuple[bool, str]:
    half = 1.96 * per_run_mse.std(ddof=1) / np.sqrt(per_run_mse.size)
    gap = abs(per_run_mse.mean() - expected)
    return gap < 2 * half, f"Monte Carlo {per_run_mse.mean():.6g} ± {half:.2g}, expected {expected:.6g}"


@pytest.mark.parametrize("method, n_measurements", [("centralized", 3), ("forwarding", 3), ("local", 1)])
def test_own_state_bound_and_floor_match_the_dare(method, n_measurements):
    """Ring of 8 (degree 2): the centralized filter uses 1 + 2 measurements of each agent, the local filter 1."""
    m = compare.simulate_team(method, 8, 21, runs=RUNS)
    ok, message = _within_interval(m["rmse_own"] ** 2, _posterior_position_mse(n_measurements))
    assert ok, message
    assert abs(m["nees_own"].mean() - 1) < 0.05


def test_the_reference_can_fail():
    """The DARE reference separates the bound from the floor: the local filter does not pass as centralized."""
    m = compare.simulate_team("local", 8, 21, runs=RUNS)
    assert not _within_interval(m["rmse_own"] ** 2, _posterior_position_mse(3))[0]


def _shared_variances(seed: int, n_agents: int) -> np.ndarray:
    """The prior variances the shared task draws for `seed` (its first spawned stream), shape (runs, N)."""
    s = compare.SETTINGS
    init_rng = np.random.default_rng(seed).spawn(4)[0]
    lo, hi = np.log(s.shared_var[0]), np.log(s.shared_var[1])
    return np.exp(init_rng.uniform(lo, hi, (RUNS, n_agents)))


@pytest.mark.parametrize("method", ["central-fusion", "no-fusion"])
def test_shared_bound_and_floor_match_the_expected_error(method):
    """Central fusion: E|e|² = 2 / sum_i (1 / p_i); no fusion: the mean over agents of 2 p_i (planar, per run)."""
    var = _shared_variances(4, 8)
    expected = 2 / np.sum(1 / var, -1) if method == "central-fusion" else 2 * var.mean(-1)
    m = compare.simulate_shared(method, 8, 4, runs=RUNS)
    ok, message = _within_interval(m["rmse_own"] ** 2, float(expected.mean()))
    assert ok, message
    # run by run, the ratio of the observed to the expected squared error averages to one
    assert abs(np.mean(m["rmse_own"] ** 2 / expected) - 1) < 0.15
