"""Tests of mascore.lqr: LQR primitives and the network LQR of Vlahakis and Halikias, Sec. 3."""

import numpy as np
import pytest
import scipy.linalg as sla

from mascore import RiccatiError, graphs, lqr, riccati

A = np.array([[0.0, 1.0], [-1.0, -0.1]])  # Example 1 agent
B = np.array([[0.0], [1.0]])


def _random_system(rng, n, m):
    return rng.normal(size=(n, n)), rng.normal(size=(n, m))


def test_scalar_lqr_closed_form():
    """python-control's analytic check: A = 0, B = 1 gives S = sqrt(Q R), K = sqrt(Q / R)."""
    K, S, E = lqr.lqr([[0.0]], [[1.0]], [[4.0]], [[9.0]])
    assert S[0, 0] == pytest.approx(6.0, rel=1e-12)
    assert K[0, 0] == pytest.approx(2.0 / 3.0, rel=1e-12)
    assert E[0] == pytest.approx(-2.0 / 3.0, rel=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_riccati_residual_and_stability(seed):
    rng = np.random.default_rng(seed)
    Ar, Br = _random_system(rng, 4, 2)
    M = rng.normal(size=(4, 4))
    Q, R = M @ M.T + np.eye(4), np.diag([1.0, 3.0])
    K, S, E = lqr.lqr(Ar, Br, Q, R)
    residual = Ar.T @ S + S @ Ar - S @ Br @ np.linalg.solve(R, Br.T) @ S + Q
    assert np.abs(residual).max() < 1e-10 * max(1, np.abs(S).max())
    np.testing.assert_allclose(K, np.linalg.solve(R, Br.T @ S), atol=1e-12)
    assert np.all(E.real < 0)
    np.testing.assert_allclose(np.sort_complex(E), np.sort_complex(np.linalg.eigvals(Ar - Br @ K)), atol=1e-9)


def test_uncontrollable_pair_is_rejected():
    with pytest.raises(ValueError, match="not stabilizable"):
        lqr.lqr(np.diag([1.0, 2.0]), [[1.0], [0.0]], np.eye(2), [[1.0]])


def test_bad_inputs_name_the_argument():
    with pytest.raises(ValueError, match="Incompatible dimensions of B"):
        lqr.lqr(A, np.ones((3, 1)), np.eye(2), [[1.0]])
    with pytest.raises(ValueError, match="R must be positive definite"):
        lqr.lqr(A, B, np.eye(2), [[0.0]])
    with pytest.raises(ValueError, match="Q must be symmetric"):
        lqr.lqr(A, B, [[1.0, 1.0], [0.0, 1.0]], [[1.0]])


def test_no_stabilizing_solution_raises():
    """Undamped oscillator with Q = 0: the imaginary-axis modes are unobservable in Q."""
    with pytest.raises(RiccatiError):
        lqr.lqr([[0.0, 1.0], [-1.0, 0.0]], B, np.zeros((2, 2)), [[1.0]])


def test_is_controllable():
    assert riccati.is_controllable(A, B)
    assert not riccati.is_controllable(np.eye(2), B)


@pytest.mark.parametrize("n_agents", [2, 4, 6])
def test_structure_eq13_to_eq16(n_agents):
    """Dense ARE (9) with weights (11) equals the blocks (13) from (14)-(15), gain pattern (16)."""
    rng = np.random.default_rng(n_agents)
    M1, M2 = rng.normal(size=(2, 2)), rng.normal(size=(2, 2))
    Q1, Q2, R = M1 @ M1.T + 0.1 * np.eye(2), M2 @ M2.T, np.array([[2.0]])
    Lap = graphs.laplacian(graphs.complete_graph(n_agents))
    K, P, _ = lqr.centralized_network_lqr(A, B, Q1, Q2, R, Lap)
    blocks = lqr.borrelli_keviczky_structure(A, B, Q1, Q2, R, n_agents)
    np.testing.assert_allclose(P, blocks["P_network"], rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(K, blocks["K_network"], rtol=1e-9, atol=1e-10)
    # eq. (16): diagonal blocks K1, off-diagonal K2
    np.testing.assert_allclose(K[:1, :2], blocks["K1"], atol=1e-10)
    np.testing.assert_allclose(K[:1, 2:4], blocks["K2"], atol=1e-10)


def test_weights_eq11_on_complete_graph():
    Qt, Rt = lqr.network_lqr_weights(np.eye(2), 3 * np.eye(2), [[1.0]], graphs.laplacian(graphs.complete_graph(4)))
    np.testing.assert_allclose(Qt[:2, :2], (1 + 3 * 3) * np.eye(2))  # Q1 + (N-1) Q2
    np.testing.assert_allclose(Qt[:2, 2:4], -3 * np.eye(2))  # -Q2
    np.testing.assert_allclose(Rt, np.eye(4))


def test_centralized_cost_by_modes_matches_dense():
    Lap = graphs.laplacian(graphs.ring_graph(6))
    _, P, _ = lqr.centralized_network_lqr(A, B, np.eye(2), 2 * np.eye(2), [[1.0]], Lap)
    assert lqr.centralized_network_cost(A, B, np.eye(2), 2 * np.eye(2), [[1.0]], Lap) == pytest.approx(
        np.trace(P), rel=1e-10)


def test_controller_cost_by_modes_matches_dense_lyapunov():
    adj = graphs.path_graph(5)
    Lap = graphs.laplacian(adj)
    Q1, Q2, R = np.eye(2), np.eye(2), np.eye(1)
    gain = lqr.bottom_up_lqr(A, B, Q1, Q2, R, adj)
    K = lqr.assemble_network_gain(gain, Lap)
    Qt, Rt = lqr.network_lqr_weights(Q1, Q2, R, Lap)
    Acl = np.kron(np.eye(5), A) - np.kron(np.eye(5), B) @ K
    P = sla.solve_continuous_lyapunov(Acl.T, -(Qt + K.T @ Rt @ K))
    assert lqr.network_controller_cost(A, B, Q1, Q2, R, Lap, gain) == pytest.approx(np.trace(P), rel=1e-9)


def test_bottom_up_cost_between_optimum_and_bound():
    adj = graphs.ring_graph(7)
    Lap = graphs.laplacian(adj)
    args = (A, B, np.eye(2), 2 * np.eye(2), np.eye(1))
    gain = lqr.bottom_up_lqr(*args, adj)
    cost = lqr.network_controller_cost(*args, Lap, gain)
    assert lqr.centralized_network_cost(*args, Lap) <= cost <= gain.bound * (1 + 1e-6)
    np.testing.assert_allclose(gain.K_coupling, gain.Phi @ gain.K_self)


def test_top_down_equals_centralized_on_complete_graph():
    """With all-to-all links (N_L = N) eq. (17) is the centralized gain (16) itself."""
    adj = graphs.complete_graph(5)
    Lap = graphs.laplacian(adj)
    args = (A, B, np.eye(2), np.eye(2), np.eye(1))
    top = lqr.top_down_lqr(*args, adj)
    assert top.n_local == 5 and top.condition_holds
    K, _, _ = lqr.centralized_network_lqr(*args, Lap)
    np.testing.assert_allclose(lqr.assemble_network_gain(top, Lap), K, atol=1e-9)


def test_top_down_condition_is_only_sufficient():
    """Ring of 5: lambda_2 = 1.38 < N_L / 2 = 1.5, yet the closed loop is stable (LQR gain margin)."""
    top = lqr.top_down_lqr(A, B, np.eye(2), np.eye(2), np.eye(1), graphs.ring_graph(5))
    assert not top.condition_holds
    assert top.spectral_abscissa < 0


def test_disconnected_graph_is_rejected():
    adj = np.zeros((4, 4))
    adj[0, 1] = adj[1, 0] = adj[2, 3] = adj[3, 2] = 1
    with pytest.raises(ValueError, match="disconnected"):
        lqr.bottom_up_lqr(A, B, np.eye(2), np.eye(2), np.eye(1), adj)
    with pytest.raises(ValueError, match="symmetric"):
        graphs.laplacian_spectrum(graphs.laplacian(np.triu(graphs.ring_graph(4))))


#: Uncontrollable yet stabilizable agent: the mode -1 is untouched by B, so the Riccati equations
#: still have stabilizing solutions and only an explicit controllability check rejects it.
A_UNC, B_UNC = np.diag([-1.0, 1.0]), np.array([[0.0], [1.0]])
A_UNS = np.eye(2)  # with B_UNC: the uncontrollable mode z = 1 is unstable, so not stabilizable


def test_uncontrollable_agent_rejected_by_network_designs():
    assert not riccati.is_controllable(A_UNC, B_UNC) and not riccati.is_stabilizable(A_UNS, B_UNC)
    w = (np.eye(2), np.eye(2), np.eye(1))  # A = I, continuous time (every mode unstable): said with dt=0
    ring = graphs.ring_graph(4)
    Lap = graphs.laplacian(ring)
    with pytest.raises(ValueError, match=r"\(A, B\) is not stabilizable"):
        lqr.top_down_lqr(A_UNS, B_UNC, *w, ring, dt=0)
    with pytest.raises(ValueError, match=r"\(A, B\) is not stabilizable"):
        lqr.centralized_network_lqr(A_UNS, B_UNC, *w, Lap, dt=0)
    with pytest.raises(ValueError, match=r"\(A, B\) is not stabilizable"):
        lqr.centralized_network_cost(A_UNS, B_UNC, *w, Lap, dt=0)
    with pytest.raises(ValueError, match=r"\(A, B\) is not stabilizable"):
        lqr.borrelli_keviczky_structure(A_UNS, B_UNC, *w, 4, dt=0)
    with pytest.raises(ValueError, match=r"\(A, B\) is not stabilizable"):
        lqr.bottom_up_lqr(A_UNS, B_UNC, *w, ring, dt=0)
    # evaluating a given stabilizing gain needs no controllability
    gain = lqr.DistributedGain(np.array([[0.0, 3.0]]), np.zeros((1, 2)))
    assert np.isfinite(lqr.network_controller_cost(A_UNC, B_UNC, *w, Lap, gain, dt=0))


def test_centralized_network_lqr_rejects_disconnected_laplacian():
    adj = np.zeros((4, 4))
    adj[0, 1] = adj[1, 0] = adj[2, 3] = adj[3, 2] = 1
    with pytest.raises(ValueError, match="disconnected"):
        lqr.centralized_network_lqr(A, B, np.eye(2), np.eye(2), np.eye(1), graphs.laplacian(adj))
    with pytest.raises(ValueError, match=r"laplacian looks like an adjacency matrix; pass mascore.graphs.laplacian\(A\)"):
        lqr.centralized_network_lqr(A, B, np.eye(2), np.eye(2), np.eye(1), graphs.ring_graph(4))


# ---------------------------------------------------------------- discrete-time LQR and stabilizability


def _random_stabilizable(rng, n, m):
    A = rng.normal(size=(n, n)) / np.sqrt(n) * 1.2  # some modes outside the unit circle
    B = rng.normal(size=(n, m))
    return A, B


@pytest.mark.parametrize("n,m", [(2, 1), (6, 2), (12, 3)])
def test_dlqr_solves_the_dare_and_matches_scipy(n, m):
    """K, S from dlqr satisfy the discrete ARE and equal scipy's DARE solution (independent solver)."""
    rng = np.random.default_rng(n)
    A, B = _random_stabilizable(rng, n, m)
    Q, R = np.eye(n), np.diag(rng.uniform(0.5, 2.0, m))
    K, S, E = lqr.dlqr(A, B, Q, R)
    S_ref = sla.solve_discrete_are(A, B, Q, R)
    np.testing.assert_allclose(S, S_ref, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(K, np.linalg.solve(R + B.T @ S_ref @ B, B.T @ S_ref @ A), rtol=1e-9, atol=1e-10)
    residual = A.T @ S @ A - S - A.T @ S @ B @ K + Q
    assert np.abs(residual).max() < 1e-8 * max(1.0, np.abs(S).max())
    assert np.abs(E).max() < 1 and np.allclose(np.sort_complex(E), np.sort_complex(np.linalg.eigvals(A - B @ K)))


@pytest.mark.parametrize("n,m", [(2, 1), (6, 2)])
def test_dlqr_and_lqr_match_python_control(n, m):
    control = pytest.importorskip("control")
    rng = np.random.default_rng(10 + n)
    A, B = _random_stabilizable(rng, n, m)
    Q, R = np.eye(n), np.eye(m)
    K, S, _ = lqr.dlqr(A, B, Q, R)
    K_ref, S_ref, _ = control.dlqr(A, B, Q, R)
    np.testing.assert_allclose(K, K_ref, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(S, S_ref, rtol=1e-8, atol=1e-10)
    Kc, Sc, _ = lqr.lqr(A, B, Q, R)
    Kc_ref, Sc_ref, _ = control.lqr(A, B, Q, R)
    np.testing.assert_allclose(Kc, Kc_ref, rtol=1e-8, atol=1e-10)


def test_dlqr_tends_to_lqr_as_the_sampling_time_shrinks():
    """The discrete design for the plant sampled at dt, with weights Q dt and R dt, tends to the continuous one."""
    from scipy.signal import cont2discrete

    A = np.array([[0.0, 1.0], [2.0, -0.5]])
    B = np.array([[0.0], [1.0]])
    Kc, _, _ = lqr.lqr(A, B, np.eye(2), np.eye(1))
    errors = []
    for dt in (0.1, 0.01, 0.001):
        Ad, Bd, *_ = cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), dt)
        Kd, _, _ = lqr.dlqr(Ad, Bd, np.eye(2) * dt, np.eye(1) * dt)
        errors.append(np.abs(Kd - Kc).max())
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-2 * np.abs(Kc).max()


def test_stabilizable_but_uncontrollable_pair_gets_an_lqr():
    """A stable uncontrollable mode does not stop the LQR (stabilizability, not controllability, is needed)."""
    A = np.diag([1.0, -3.0])
    B = np.array([[1.0], [0.0]])
    assert not riccati.is_controllable(A, B) and riccati.is_stabilizable(A, B)
    K, _, E = lqr.lqr(A, B, np.eye(2), np.eye(1))
    assert E.real.max() < 0
    with pytest.raises(ValueError, match="not stabilizable"):
        lqr.lqr(np.diag([1.0, 3.0]), B, np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match="not stabilizable"):
        lqr.dlqr(np.diag([0.5, 1.5]), B, np.eye(2), np.eye(1))
    K, _, E = lqr.dlqr(np.diag([1.5, 0.5]), B, np.eye(2), np.eye(1))
    assert np.abs(E).max() < 1
