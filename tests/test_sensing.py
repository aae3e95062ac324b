"""Tests of the team sensing model (Song et al. 2023, eqs. (2)-(3))."""

import numpy as np
import pytest

from mascore.graphs import path_graph, proximity_graph, ring_graph
from mascore.sensing import (
    IsolatedAgentError,
    measure,
    neighbor_sets,
    selection_matrices,
    selection_matrix,
    sensing_mask,
    stacked_measurement,
    team_noise_covariance,
)


def test_selection_matrix_matches_eq3_definition():
    """Song et al. eq. (3): block (l, m) of H_i is I_2n iff m is the l-th element of N̄_i."""
    H = selection_matrix(np.array([0, 2]), 3, 2)
    expected = np.zeros((4, 6))
    expected[0:2, 0:2] = np.eye(2)
    expected[2:4, 4:6] = np.eye(2)
    np.testing.assert_array_equal(H, expected)


def test_neighbor_sets_include_self_and_follow_adjacency():
    sets = neighbor_sets(path_graph(4))
    assert [s.tolist() for s in sets] == [[0, 1], [0, 1, 2], [1, 2, 3], [2, 3]]


def test_mask_equals_HtH_diagonal():
    """H_i^T H_i = diag(S[i]) ⊗ I_m: the mask and the selection matrices agree."""
    A = ring_graph(5)
    S = sensing_mask(A)
    for i, H in enumerate(selection_matrices(A, 3)):
        np.testing.assert_array_equal(H.T @ H, np.kron(np.diag(S[i].astype(float)), np.eye(3)))


def test_measure_equals_H_times_state_plus_noise():
    """Tensor measurements restacked are H_i (X + nu_i) with the same noise."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(4, 2))
    A = path_graph(4)
    R = np.diag([0.5, 2.0])
    Z, S = measure(np.random.default_rng(7), x, A, R)
    # reconstruct the noise tensor with the same seed and zero states
    Z0, _ = measure(np.random.default_rng(7), np.zeros_like(x), A, R)
    X = x.reshape(-1)
    for i, H in enumerate(selection_matrices(A, 2)):
        nu_i = np.zeros((4, 2))
        nu_i[S[i]] = Z0[i, S[i]]
        np.testing.assert_allclose(stacked_measurement(Z, S, i), H @ (X + nu_i.reshape(-1)))
    assert np.all(Z[~S] == 0)


def test_measure_is_deterministic_and_batched_over_runs_and_graphs():
    rng_x = np.random.default_rng(0)
    x = rng_x.normal(size=(6, 5, 4))  # 6 runs, 5 agents, m = 4
    A = np.stack([ring_graph(5)] * 3 + [path_graph(5)] * 3)
    Z1, S1 = measure(11, x, A, np.eye(4))
    Z2, S2 = measure(np.random.default_rng(11), x, A, np.eye(4))
    assert Z1.shape == (6, 5, 5, 4) and S1.shape == (6, 5, 5)
    np.testing.assert_array_equal(Z1, Z2)
    np.testing.assert_array_equal(S1[3], sensing_mask(path_graph(5)))


def test_measurement_noise_has_covariance_R():
    R = np.array([[2.0, 0.3], [0.3, 0.5]])
    x = np.zeros((20000, 3, 2))
    Z, _ = measure(5, x, ring_graph(3), R)
    nu = Z[:, 0, 1, :]
    np.testing.assert_allclose(np.cov(nu.T), R, atol=0.06)


def test_full_team_R_is_accepted():
    R_team = np.kron(np.eye(3), np.eye(2)) * 4.0
    np.testing.assert_array_equal(team_noise_covariance(R_team, 3, 2), R_team)
    np.testing.assert_array_equal(team_noise_covariance(np.eye(2), 3, 2), np.eye(6))


def test_isolated_agent_raises_naming_agent():
    p = np.array([[0.0, 0.0], [1.0, 0.0], [50.0, 0.0]])
    with pytest.raises(IsolatedAgentError, match="agent 2 has no neighbour"):
        sensing_mask(proximity_graph(p, 5.0))
    with pytest.raises(ValueError, match="agent 2"):
        measure(0, np.zeros((3, 4)), proximity_graph(p, 5.0), np.eye(4))
    S = sensing_mask(proximity_graph(p, 5.0), allow_isolated=True)
    assert S[2].tolist() == [False, False, True]


@pytest.mark.parametrize(
    "R, match",
    [(np.eye(3), "Incompatible dimensions of R"), (-np.eye(2), "positive semidefinite"),
     (np.array([[1.0, 2.0], [0.0, 1.0]]), "symmetric")],
)
def test_bad_R_raises(R, match):
    with pytest.raises(ValueError, match=match):
        measure(0, np.zeros((3, 2)), ring_graph(3), R)


def test_bad_adjacency_and_states_raise():
    with pytest.raises(ValueError, match="adjacency"):
        sensing_mask(np.ones((3, 4)))
    with pytest.raises(ValueError, match="zero diagonal"):
        sensing_mask(np.ones((3, 3)))
    with pytest.raises(ValueError, match="4 agents"):
        measure(0, np.zeros((4, 2)), ring_graph(3), np.eye(2))
    with pytest.raises(TypeError, match="rng"):
        measure("seed", np.zeros((3, 2)), ring_graph(3), np.eye(2))
    with pytest.raises(ValueError, match="distinct"):
        selection_matrix(np.array([0, 0]), 3, 2)
