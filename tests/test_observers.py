"""Tests of mascore.observers: minimum-energy observer and the LMI distributed observer (Vlahakis and Halikias, Sec. 4)."""

import numpy as np
import pytest
import scipy.linalg as sla

from mascore import graphs, lqr, observers
from mascore._solver import SolverError

A = np.array([[0.0, 1.0], [-1.0, -0.1]])
B = np.array([[0.0], [1.0]])
C = np.array([[1.0, 0.0]])


def test_min_energy_scalar_closed_form():
    """x' = d, y = x + n: S = 1 / sqrt(Q R), L = sqrt(Q / R), cost trace(S) (eq. (25))."""
    obs = observers.min_energy_observer([[0.0]], [[1.0]], [[1.0]], [[4.0]], [[9.0]])
    assert obs.S[0, 0] == pytest.approx(1 / 6, rel=1e-12)
    assert obs.L[0, 0] == pytest.approx(2 / 3, rel=1e-12)
    assert obs.cost == pytest.approx(1 / 6, rel=1e-12)


def test_min_energy_dual_are_and_duality_with_lqr():
    Q, R = np.array([[10.0]]), np.array([[2.0]])
    obs = observers.min_energy_observer(A, B, C, Q, R)
    S = obs.S
    residual = A @ S + S @ A.T + B @ B.T / 2.0 - S @ C.T @ Q @ C @ S  # eq. (23)
    assert np.abs(residual).max() < 1e-10
    np.testing.assert_allclose(obs.L, S @ C.T @ Q)
    K, S_dual, _ = lqr.lqr(A.T, C.T, B @ B.T / 2.0, np.linalg.inv(Q))
    np.testing.assert_allclose(obs.L, K.T, rtol=1e-10)
    np.testing.assert_allclose(S, S_dual, rtol=1e-10)
    assert np.all(np.linalg.eigvals(A - obs.L @ C).real < 0)


def test_unobservable_and_uncontrollable_pairs_raise():
    with pytest.raises(ValueError, match="not observable"):
        observers.min_energy_observer(np.diag([-1.0, -2.0]), [[1.0], [1.0]], [[1.0, 0.0]], [[1.0]], [[1.0]])
    with pytest.raises(ValueError, match="not controllable"):
        observers.distributed_observer(np.diag([-1.0, -2.0]), [[1.0], [0.0]], [[1.0, 1.0]], 1, 1, 1,
                                       graphs.ring_graph(4))
    with pytest.raises(ValueError, match="not observable"):
        observers.distributed_observer(np.diag([-1.0, -2.0]), [[1.0], [1.0]], [[1.0, 0.0]], 1, 1, 1,
                                       graphs.ring_graph(4))


def test_bad_reading_and_disconnected_graph_raise():
    with pytest.raises(ValueError, match="reading must be one of"):
        observers.distributed_observer(A, B, C, 10, 5, 1, graphs.ring_graph(5), reading="matlab")
    with pytest.raises(ValueError, match="disconnected"):
        observers.distributed_observer(A, B, C, 10, 5, 1, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="Q1 must be positive definite"):
        observers.distributed_observer(A, B, C, 0, 5, 1, graphs.ring_graph(5))


@pytest.fixture(scope="module")
def ring_design():
    return observers.distributed_observer(A, B, C, 10, 5, 1, graphs.ring_graph(6))


def test_transformed_coordinates(ring_design):
    """Eqs. (27)-(34): C_hat = (0 C2), L_hat = (0; L2), S_hat = T S T^T block diagonal."""
    d = ring_design
    assert abs(d.C_hat[0, 0]) < 1e-12 and abs(d.L_hat[0, 0]) < 1e-12
    S = observers.min_energy_observer(A, B, C, [[10.0]], [[1.0]]).S
    S_hat = d.T @ S @ d.T.T
    assert abs(S_hat[0, 1]) < 1e-10
    np.testing.assert_allclose(d.A_hat, d.T @ A @ np.linalg.inv(d.T))


def test_cost_ordering_and_hurwitz(ring_design):
    d = ring_design
    assert d.centralized_cost <= d.cost <= d.bound * (1 + 1e-6)
    assert d.hurwitz


def test_dense_error_matrix_matches_modes(ring_design):
    """Eigenvalues of A_e (eq. (42), error form) are the union over the modes of eq. (52)."""
    d = ring_design
    Lap = graphs.laplacian(graphs.ring_graph(6))
    A_e = observers.observer_error_matrix(A, d.L, C, d.Phi, Lap)
    def ordered(z):
        return z[np.lexsort((np.round(z.imag, 6), np.round(z.real, 6)))]

    dense = ordered(np.linalg.eigvals(A_e))
    modes = ordered(np.concatenate(
        [np.linalg.eigvals(A - d.L @ (np.eye(1) + l * d.Phi) @ C) for l in d.lam]))
    np.testing.assert_allclose(dense, modes, atol=1e-8)
    assert dense.real.max() == pytest.approx(d.spectral_abscissa, abs=1e-9)


def test_centralized_cost_equals_network_are_eq40(ring_design):
    """Sum over modes of eq. (53) equals the trace of the dense network ARE (40)."""
    d = ring_design
    N = 6
    Lap = graphs.laplacian(graphs.ring_graph(N))
    A_net = np.kron(np.eye(N), d.A_hat)
    W = np.kron(np.eye(N), d.Bbar_hat @ d.Bbar_hat.T)
    C_net = np.kron(np.eye(N), d.C_hat)
    Q_net = np.kron(np.eye(N), [[10.0]]) + np.kron(Lap, [[5.0]])
    S_net = sla.solve_continuous_are(A_net.T, C_net.T, W, np.linalg.inv(Q_net))
    assert np.trace(S_net) == pytest.approx(d.centralized_cost, rel=1e-8)


def test_repeated_eigenvalues_share_blocks():
    """The ring's paired eigenvalues give the same design as listing each pair once with doubled weight."""
    lam_ring = np.linalg.eigvalsh(graphs.laplacian(graphs.ring_graph(6)))
    lam_ring[0] = 0
    obs = observers.min_energy_observer(A, B, C, [[10.0]], [[1.0]])
    G = [B] * 6
    full = observers.coupled_gain_lmi(A, C, obs.L, lam_ring, G, [10 + 5 * l for l in lam_ring])
    assert list(full["multiplicity"]) == [1, 2, 2, 1]
    assert full["bound"] > 0


@pytest.mark.parametrize("adjacency", [graphs.path_graph(4), graphs.star_graph(5)], ids=["path4", "star5"])
def test_general_agent_three_states(adjacency):
    """Three states, other graphs: the design works beyond Example 1 (C is not (1 0 0)-aligned)."""
    A3 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -2.0, -0.5]])
    B3 = np.array([[0.0], [0.0], [1.0]])
    C3 = np.array([[1.0, 0.5, 0.0]])
    d = observers.distributed_observer(A3, B3, C3, [[10.0]], [[2.0]], [[1.0]], adjacency)
    assert d.hurwitz
    assert d.centralized_cost <= d.cost <= d.bound * (1 + 1e-6)
    np.testing.assert_allclose(d.C_hat[:, :2], 0, atol=1e-12)
    np.testing.assert_allclose(d.L_hat[:2], 0, atol=1e-10)


def test_infeasible_lmi_raises_solver_error():
    """A destabilizing local gain leaves the lambda = 0 mode (untouched by Phi) unstable: no S_i exists."""
    lam = np.array([0.0, 2.0])
    with pytest.raises(SolverError, match="status"):
        observers.coupled_gain_lmi(A, C, np.array([[-2.0], [-2.0]]), lam, [B, B], [[[1.0]], [[1.0]]])


def test_simulation_matches_matrix_exponential(ring_design):
    d = ring_design
    Lap = graphs.laplacian(graphs.ring_graph(6))
    A_e = observers.observer_error_matrix(A, d.L, C, d.Phi, Lap)
    e0 = np.random.default_rng(0).uniform(-1, 1, size=(6, 2))
    t = np.linspace(0, 5, 501)
    E = observers.simulate_estimation_errors(A_e, e0, t)
    np.testing.assert_allclose(E[-1].ravel(), sla.expm(A_e * 5) @ e0.ravel(), atol=1e-10)
    assert np.abs(observers.disagreement(E).mean(axis=1)).max() < 1e-12
    with pytest.raises(ValueError, match="uniform"):
        observers.simulate_estimation_errors(A_e, e0, np.array([0.0, 1.0, 3.0]))
    with pytest.raises(ValueError, match="N\\*n"):
        observers.simulate_estimation_errors(A_e, e0[:3], t)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_connected_graphs(seed):
    """Any connected undirected graph: Hurwitz A_e and centralized <= achieved <= bound."""
    import networkx as nx

    g = nx.connected_watts_strogatz_graph(8, 3, 0.5, seed=seed)
    adjacency = nx.to_numpy_array(g)
    d = observers.distributed_observer(A, B, C, 10, 5, 1, adjacency, reading="inverse-weight-are")
    assert d.hurwitz
    assert d.centralized_cost <= d.cost <= d.bound * (1 + 1e-6)
    assert d.lam[1] > 0


def test_network_observer_error_equals_error_dynamics(ring_design):
    """Plant + observer (42) fed by Y = (I (x) C) X: X - X_hat follows expm(A_e t) e0, an independent check."""
    d = ring_design
    Lap = graphs.laplacian(graphs.ring_graph(6))
    rng = np.random.default_rng(7)
    x0, x_hat0 = rng.uniform(-1, 1, size=(6, 2)), rng.uniform(-1, 1, size=(6, 2))
    t = np.linspace(0, 10, 1001)
    X, X_hat = observers.simulate_network_observer(A, C, d.L, d.Phi, Lap, x0, x_hat0, t)
    assert X.shape == X_hat.shape == (t.size, 6, 2)
    A_e = observers.observer_error_matrix(A, d.L, C, d.Phi, Lap)
    np.testing.assert_allclose(X - X_hat, observers.simulate_estimation_errors(A_e, x0 - x_hat0, t),
                               rtol=0, atol=1e-11)
    # the plant is not affected by the observer; the estimates converge to the true states
    np.testing.assert_allclose(X[-1].ravel(), sla.expm(np.kron(np.eye(6), A) * 10) @ x0.ravel(), atol=1e-11)
    assert np.abs(X - X_hat)[-1].max() < 1e-3 * np.abs(x0 - x_hat0).max()
    assert np.abs(X[-1]).max() > 0.1  # the states themselves have not died out: the estimates track them


def test_network_observer_with_constant_disturbance(ring_design):
    """Constant d on a non-uniform grid: e(t) = expm(A_e t) e0 + A_e^-1 (expm(A_e t) - I) (I (x) Bbar) d."""
    d = ring_design
    Lap = graphs.laplacian(graphs.ring_graph(6))
    rng = np.random.default_rng(8)
    x0, x_hat0 = rng.uniform(-1, 1, size=(6, 2)), np.zeros((6, 2))
    dist = rng.uniform(-1, 1, size=(6, 1))
    t = np.concatenate([np.linspace(0, 1, 11), np.linspace(1.5, 4, 6)])
    X, X_hat = observers.simulate_network_observer(A, C, d.L, d.Phi, Lap, x0, x_hat0, t, Bbar=B,
                                                   disturbance=np.broadcast_to(dist, (t.size, 6, 1)))
    A_e = observers.observer_error_matrix(A, d.L, C, d.Phi, Lap)
    forcing = np.kron(np.eye(6), B) @ dist.ravel()
    for k in (5, 10, t.size - 1):
        F = sla.expm(A_e * t[k])
        expected = F @ (x0 - x_hat0).ravel() + np.linalg.solve(A_e, (F - np.eye(12)) @ forcing)
        np.testing.assert_allclose((X[k] - X_hat[k]).ravel(), expected, atol=1e-10)
    # Phi = 0 and no disturbance: the agents' observers decouple (each one is x_e' = (A - L C) x_e + L y)
    X0, Xh0 = observers.simulate_network_observer(A, C, d.L, 0.0, Lap, x0, x_hat0, t)
    np.testing.assert_allclose((X0 - Xh0)[-1, 0], sla.expm((A - d.L @ C) * 4) @ (x0 - x_hat0)[0], atol=1e-11)


def test_network_observer_bad_input_names_the_argument(ring_design):
    d = ring_design
    Lap = graphs.laplacian(graphs.ring_graph(6))
    x0, t = np.zeros((6, 2)), np.linspace(0, 1, 11)
    sim = observers.simulate_network_observer
    with pytest.raises(ValueError, match="Incompatible dimensions of x0"):
        sim(A, C, d.L, d.Phi, Lap, np.zeros((5, 2)), x0, t)
    with pytest.raises(ValueError, match="Incompatible dimensions of x_hat0"):
        sim(A, C, d.L, d.Phi, Lap, x0, np.zeros((6, 3)), t)
    with pytest.raises(ValueError, match="laplacian looks like an adjacency matrix"):
        sim(A, C, d.L, d.Phi, graphs.ring_graph(6), x0, x0, t)
    with pytest.raises(ValueError, match="t must be strictly increasing"):
        sim(A, C, d.L, d.Phi, Lap, x0, x0, t[::-1])
    with pytest.raises(ValueError, match="Incompatible dimensions of Phi"):
        sim(A, C, d.L, np.eye(2), Lap, x0, x0, t)
    with pytest.raises(ValueError, match="disturbance needs Bbar"):
        sim(A, C, d.L, d.Phi, Lap, x0, x0, t, disturbance=np.zeros((11, 6, 1)))
    with pytest.raises(ValueError, match="disturbance must have shape"):
        sim(A, C, d.L, d.Phi, Lap, x0, x0, t, Bbar=B, disturbance=np.zeros((10, 6, 1)))


def test_fixed_phi_program_cross_checks_the_lmi():
    """Eqs. (56)-(58) at fixed Phi, solved in S_i (no W = S^-1, Y2 = W2 L2 Phi change of variables):
    its minimum over Phi is the LMI (62) optimum, reached at the LMI's Phi."""
    lam = np.linalg.eigvalsh(graphs.laplacian(graphs.ring_graph(5)))
    lam[0] = 0.0
    L = np.array([[3.0], [1.0]])  # stabilizing but not optimal for any mode: the program is not degenerate
    G, noise = [B] * 5, [[[10.0 + 5.0 * l]] for l in lam]
    res = observers.coupled_gain_lmi(A, C, L, lam, G, noise)
    phi = res["Phi"].item()
    at_phi = observers.bound_at_fixed_phi(A, C, L, lam, G, noise, phi)
    # the LMI carries the strictness margin, so its bound is a hair above the non-strict optimum
    assert at_phi == pytest.approx(res["bound"], rel=1e-3)
    assert at_phi <= res["bound"]
    for other in (phi - 0.2, phi - 0.05, phi + 0.05, phi + 0.2):
        assert observers.bound_at_fixed_phi(A, C, L, lam, G, noise, other) > at_phi * (1 + 1e-6)


def test_fixed_phi_program_unstable_mode_is_infinite():
    lam = np.array([0.0, 2.0])
    obs = observers.min_energy_observer(A, B, C, [[10.0]], [[1.0]])
    # Phi = -1 / lambda makes the second mode's gain zero: A itself, whose poles have real part -0.05 (stable);
    # a more negative Phi flips the sign of the gain and destabilizes it
    assert observers.bound_at_fixed_phi(A, C, obs.L, lam, [B, B], [[[10.0]], [[20.0]]], -2.0) == float("inf")


@pytest.mark.filterwarnings("ignore:Solution may be inaccurate")
def test_lmi_not_solved_to_optimality_raises(monkeypatch):
    from mascore import _solver

    monkeypatch.setitem(_solver.SOLVER_OPTIONS, "max_iter", 1)
    with pytest.raises(SolverError, match=r"distributed observer LMI \(62\).*expected 'optimal'"):
        observers.distributed_observer(A, B, C, 10, 5, 1, graphs.ring_graph(5))


def test_achieved_cost_matches_design_and_dense_lyapunov(ring_design):
    """achieved_cost equals the design's cost, and the trace of the dense network Lyapunov equation."""
    d = ring_design
    noise = [[[10.0 + 5.0 * l]] for l in d.lam]
    assert observers.achieved_cost(A, B, C, [[1.0]], d.L, d.Phi, d.lam, noise, T=d.T) == pytest.approx(d.cost, rel=1e-10)
    Lap = graphs.laplacian(graphs.ring_graph(6))
    A_e = observers.observer_error_matrix(A, d.L, C, d.Phi, Lap)
    Lnet = np.kron(np.eye(6), d.L) + np.kron(Lap, d.L @ d.Phi)  # input matrix of Y in eq. (42)
    Qnet = np.kron(np.eye(6), [[10.0]]) + np.kron(Lap, [[5.0]])
    S = sla.solve_continuous_lyapunov(A_e, -(np.kron(np.eye(6), B @ B.T) + Lnet @ np.linalg.solve(Qnet, Lnet.T)))
    assert np.trace(S) == pytest.approx(observers.achieved_cost(A, B, C, [[1.0]], d.L, d.Phi, d.lam, noise), rel=1e-8)
    assert observers.achieved_cost(A, B, C, [[1.0]], -d.L, d.Phi, d.lam, noise) == float("inf")
