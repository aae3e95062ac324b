"""Tests of mascore.consensus: Kalman consensus of Ren, Beard and Kingston (2005) and its tools."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.linalg import block_diag

from mascore import consensus as cs
from mascore import kalman
from mascore.graphs import adjacency_from_edges


def _random_spd(rng, n, m):
    A = rng.standard_normal((n, m, m))
    return A @ np.swapaxes(A, -1, -2) + 0.3 * np.eye(m)


def _random_graph(rng, n, p=0.4):
    G = (rng.random((n, n)) < p).astype(float)
    np.fill_diagonal(G, 0.0)
    return G


# --------------------------------------------------------------------------- the update equations


def test_step_matches_textbook_kalman_update():
    """Eqs. (4)-(5) are the Kalman filter of Table II-B with H_i = stacked I and R_i block diagonal."""
    rng = np.random.default_rng(0)
    n, m = 5, 2
    xi, P = rng.standard_normal((n, m)), _random_spd(rng, n, m)
    G = _random_graph(rng, n, 0.5)
    Q, Om = 0.2 * np.eye(m), _random_spd(rng, n * n, m).reshape(n, n, m, m) * 0.1
    xi_next, P_next = cs.kalman_consensus_step(xi, P, G, Q, Om)
    for i in range(n):
        heard = [j for j in range(n) if G[i, j] > 0 or j == i]  # g_ii = 1
        z = np.concatenate([xi[j] for j in heard])
        H = np.vstack([np.eye(m)] * len(heard))
        R = block_diag(*[P[j] + Om[i, j] for j in heard])
        x_ref, P_ref = kalman.update(xi[i], P[i] + Q, z, H, R)
        np.testing.assert_allclose(xi_next[i], x_ref, atol=1e-10)
        np.testing.assert_allclose(P_next[i], P_ref, atol=1e-10)


def test_scalar_equals_one_by_one_vector():
    rng = np.random.default_rng(1)
    n = 6
    xi, P = rng.standard_normal(n), rng.uniform(0.1, 2, n)
    G = cs.random_pairings(n, 20, rng)
    s = cs.kalman_consensus_discrete(xi, P, G, 0.1, 0.3)
    v = cs.kalman_consensus_discrete(xi[:, None], P[:, None, None], G, [[0.1]], [[0.3]])
    assert s.xi.shape == (21, n) and v.xi.shape == (21, n, 1)
    np.testing.assert_allclose(s.xi, v.xi[..., 0], atol=1e-13)
    np.testing.assert_allclose(s.P, v.P[..., 0, 0], atol=1e-13)


def test_diagonal_covariances_decouple_into_scalar_runs():
    """Sec. III: 'The vector case reduces to the scalar case if P_i0 is a diagonal matrix.'"""
    rng = np.random.default_rng(2)
    n, m = 7, 3
    xi = rng.standard_normal((n, m))
    var = rng.uniform(0.1, 2.0, (n, m))
    q, om = np.array([0.1, 0.2, 0.05]), np.array([0.1, 0.01, 0.5])
    G = cs.random_pairings(n, 30, rng)
    vec = cs.kalman_consensus_discrete(xi, var[..., None] * np.eye(m), G, np.diag(q), np.diag(om))
    for a in range(m):
        sca = cs.kalman_consensus_discrete(xi[:, a], var[:, a], G, q[a], om[a])
        np.testing.assert_allclose(vec.xi[..., a], sca.xi, atol=1e-12)
        np.testing.assert_allclose(vec.P[..., a, a], sca.P, atol=1e-12)


def test_batch_runs_equal_separate_runs():
    rng = np.random.default_rng(3)
    n, R = 5, 4
    xi, P = rng.standard_normal((R, n)), rng.uniform(0.1, 1, (R, n))
    G = cs.random_pairings(n, 15, rng, size=R)
    batch = cs.kalman_consensus_discrete(xi, P, G, 0.1, 0.1)
    for r in range(R):
        one = cs.kalman_consensus_discrete(xi[r], P[r], G[:, r], 0.1, 0.1)
        np.testing.assert_allclose(batch.xi[:, r], one.xi, atol=1e-13)


@given(st.integers(2, 8), st.integers(0, 10_000), st.booleans())
@settings(max_examples=40, deadline=None)
def test_consensus_matrix_is_stochastic_with_positive_diagonal(n, seed, include_self):
    """Eq. (8): D[k] is row-stochastic with a positive diagonal, and xi[k+1] = D[k] xi[k]."""
    rng = np.random.default_rng(seed)
    P, xi, G = rng.uniform(1e-3, 5, n), rng.standard_normal(n), _random_graph(rng, n, 0.5)
    omega = rng.uniform(0.0, 1.0)
    D = cs.consensus_matrix(P, G, 0.1, omega, include_self=include_self)
    np.testing.assert_allclose(D.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(D >= -1e-15) and np.all(np.diag(D) > 0)
    assert np.all((D - np.diag(np.diag(D)) > 0) == (G > 0))  # the graph of D is the topology
    xi_next, _ = cs.kalman_consensus_step(xi, P, G, 0.1, omega, include_self=include_self)
    np.testing.assert_allclose(D @ xi, xi_next, atol=1e-12)


def test_block_consensus_matrix_vector_state():
    rng = np.random.default_rng(4)
    n, m = 4, 2
    xi, P, G = rng.standard_normal((n, m)), _random_spd(rng, n, m), _random_graph(rng, n, 0.6)
    D = cs.consensus_matrix(P, G, 0.1 * np.eye(m), 0.3 * np.eye(m))
    assert D.shape == (n * m, n * m)
    blocks = D.reshape(n, m, n, m).sum(axis=2)
    np.testing.assert_allclose(blocks, np.broadcast_to(np.eye(m), (n, m, m)), atol=1e-12)
    xi_next, _ = cs.kalman_consensus_step(xi, P, G, 0.1 * np.eye(m), 0.3 * np.eye(m))
    np.testing.assert_allclose(D @ xi.ravel(), xi_next.ravel(), atol=1e-12)


def test_discrete_steady_state_variance_under_pairings():
    """Paired every step: 1/P = 1/(P+Q) + 2/(P+Omega) -> P = 0.05 for Q = Omega = 0.1."""
    G = cs.random_pairings(10, 60, np.random.default_rng(5), max_duration=3)
    res = cs.kalman_consensus_discrete(np.arange(10.0), np.ones(10), G, 0.1, 0.1)
    np.testing.assert_allclose(res.P[-1], 0.05, rtol=1e-10)
    P = res.P[-1, 0]
    assert 1 / P == pytest.approx(1 / (P + 0.1) + 2 / (P + 0.1))


def test_isolated_agent_with_self_term_stays_bounded_and_still():
    """g_ii = 1: an agent that hears nobody keeps its value and its variance tends to Omega (Q = Omega)."""
    res = cs.kalman_consensus_discrete([1.0, 2.0], [0.01, 5.0], np.zeros((2, 2)), 0.1, 0.1, n_steps=50)
    np.testing.assert_array_equal(res.xi[-1], [1.0, 2.0])
    np.testing.assert_allclose(res.P[-1], 0.1, rtol=1e-8)
    grow = cs.kalman_consensus_discrete([1.0], [1.0], np.zeros((1, 1)), 0.1, 0.1, n_steps=10, include_self=False)
    np.testing.assert_allclose(grow.P[-1], 1.0 + 10 * 0.1)  # without the self term P only grows


def test_equal_variances_on_pairings_preserve_the_average():
    rng = np.random.default_rng(6)
    xi0 = rng.uniform(0, 10, 10)
    G = cs.random_pairings(10, 150, rng)
    kal = cs.kalman_consensus_discrete(xi0, np.full(10, 0.7), G, 0.1, 0.1)
    avg = cs.average_consensus(xi0, G)
    np.testing.assert_allclose(kal.xi.sum(axis=-1), xi0.sum(), rtol=1e-12)
    np.testing.assert_allclose(avg.xi.sum(axis=-1), xi0.sum(), rtol=1e-12)
    assert kal.spread[-1] < 1e-6 and avg.spread[-1] < 1e-6
    assert kal.final_value == pytest.approx(xi0.mean(), abs=1e-6)


def test_communication_noise_statistics():
    """nu_ij ~ N(0, Omega): one noisy step has mean = noise-free step, covariance P+ (sum S Omega S) P+."""
    n, R = 4, 40_000
    rng = np.random.default_rng(7)
    xi, P = np.array([0.0, 1.0, 2.0, 3.0]), np.array([0.5, 0.2, 1.0, 0.3])
    G = adjacency_from_edges(n, [(1, 0), (2, 0), (3, 2)], directed=True)
    Om = 0.4
    ref, P_next = cs.kalman_consensus_step(xi, P, G, 0.1, Om)
    noisy, _ = cs.kalman_consensus_step(np.broadcast_to(xi, (R, n)), np.broadcast_to(P, (R, n)), G, 0.1, Om, rng=rng)
    S = 1.0 / (P[None, :] + Om)
    var = P_next**2 * (G * S**2 * Om).sum(axis=1)
    err = noisy - ref
    se = np.sqrt(var / R) + 1e-15
    assert np.all(np.abs(err.mean(axis=0)) < 4.5 * se)
    np.testing.assert_allclose(err.var(axis=0), var, rtol=0.05, atol=1e-15)
    assert np.all(err[:, 1] == 0)  # agent 2 hears nobody: no noise


def test_same_seed_same_numbers():
    G = cs.random_pairings(10, 40, 11)
    a = cs.kalman_consensus_discrete(np.arange(10.0), np.ones(10), G, 0.1, 0.1, rng=3)
    b = cs.kalman_consensus_discrete(np.arange(10.0), np.ones(10), cs.random_pairings(10, 40, 11), 0.1, 0.1, rng=3)
    assert a.xi.tobytes() == b.xi.tobytes()


# --------------------------------------------------------------------------- continuous time


def _naive_rhs(t, y, n, G, Q, Om):
    """Eqs. (1)-(3), scalar, written agent by agent (independent of the vectorised code)."""
    xi, P = y[:n], y[n:]
    dxi, dP = np.zeros(n), np.zeros(n)
    for i in range(n):
        acc = 1.0 / (P[i] + Om)  # j = i, g_ii = 1
        for j in range(n):
            if G[i, j] > 0:
                acc += 1.0 / (P[j] + Om)
                dxi[i] += P[i] / (P[j] + Om) * (xi[j] - xi[i])
        dP[i] = -P[i] ** 2 * acc + Q
    return np.concatenate([dxi, dP])


def test_continuous_matches_naive_implementation():
    rng = np.random.default_rng(8)
    n = 5
    xi0, P0 = rng.uniform(0, 5, n), rng.uniform(0.01, 2, n)
    G1, G2 = _random_graph(rng, n), _random_graph(rng, n)
    topo = cs.SwitchingTopology([0.0, 0.7], [G1, G2])
    t_eval = np.linspace(0, 2.0, 11)
    res = cs.kalman_consensus_continuous(xi0, P0, topo, 2.0, 0.1, 0.2, t_eval=t_eval)
    y = np.concatenate([xi0, P0])
    a = solve_ivp(_naive_rhs, (0, 0.7), y, args=(n, G1, 0.1, 0.2), method="LSODA", rtol=1e-10, atol=1e-12)
    b = solve_ivp(_naive_rhs, (0.7, 2.0), a.y[:, -1], args=(n, G2, 0.1, 0.2), method="LSODA",
                  rtol=1e-10, atol=1e-12, t_eval=[2.0])
    np.testing.assert_allclose(res.xi[-1], b.y[:n, -1], atol=1e-6)
    np.testing.assert_allclose(res.P[-1], b.y[n:, -1], atol=1e-6)
    # the callable form with explicit switching times gives the same run
    fun = cs.kalman_consensus_continuous(xi0, P0, lambda t: G1 if t < 0.7 else G2, 2.0, 0.1, 0.2,
                                         t_eval=t_eval, switch_times=[0.7])
    np.testing.assert_allclose(fun.xi, res.xi, atol=1e-12)


def test_continuous_vector_matches_naive_matrix_implementation():
    """Eqs. (1)-(3) with full (m, m) covariances and per-link Omega_ij, written agent by agent."""
    rng = np.random.default_rng(15)
    n, m = 4, 2
    xi0, P0 = rng.standard_normal((n, m)), _random_spd(rng, n, m)
    Om = 0.1 * _random_spd(rng, n * n, m).reshape(n, n, m, m)
    Q = np.array([[0.1, 0.03], [0.03, 0.05]])
    G = _random_graph(rng, n, 0.6)

    def rhs(_t, y):
        xi, P = y[: n * m].reshape(n, m), y[n * m:].reshape(n, m, m)
        dxi, dP = np.zeros((n, m)), np.zeros((n, m, m))
        for i in range(n):
            info = np.linalg.inv(P[i] + Om[i, i])  # g_ii = 1
            for j in range(n):
                if G[i, j] > 0:
                    Sij = np.linalg.inv(P[j] + Om[i, j])
                    info += Sij
                    dxi[i] += P[i] @ Sij @ (xi[j] - xi[i])  # K_ij (xi_j - xi_i), eqs. (2)-(3)
            dP[i] = -P[i] @ info @ P[i] + Q  # eq. (1)
        return np.concatenate([dxi.ravel(), dP.ravel()])

    ref = solve_ivp(rhs, (0, 1.5), np.concatenate([xi0.ravel(), P0.ravel()]), method="LSODA", rtol=1e-10,
                    atol=1e-12, t_eval=[1.5])
    res = cs.kalman_consensus_continuous(xi0, P0, G, 1.5, Q, Om, t_eval=[0.0, 1.5])
    np.testing.assert_allclose(res.xi[-1], ref.y[: n * m, -1].reshape(n, m), atol=1e-6)
    np.testing.assert_allclose(res.P[-1], ref.y[n * m:, -1].reshape(n, m, m), atol=1e-6)


def test_continuous_steady_state_and_vector_form():
    """Paired for ever: dP = -2 P^2 / (P + Omega) + Q = 0 -> P = 0.1 for Q = Omega = 0.1."""
    G = adjacency_from_edges(2, [(0, 1)])
    res = cs.kalman_consensus_continuous([0.0, 4.0], [1.0, 0.01], G, 60.0, 0.1, 0.1)
    np.testing.assert_allclose(res.P[-1], 0.1, rtol=1e-6)
    assert res.spread[-1] < 1e-8
    vec = cs.kalman_consensus_continuous([[0.0, 0.0], [4.0, -4.0]], [np.eye(2), 0.01 * np.eye(2)], G, 60.0,
                                         0.1 * np.eye(2), 0.1 * np.eye(2))
    np.testing.assert_allclose(vec.xi[..., 0], res.xi, atol=1e-7)
    np.testing.assert_allclose(vec.xi[..., 1], -res.xi, atol=1e-7)


def test_euler_maruyama_mean_follows_the_ode():
    """P does not depend on xi, so xi is a linear SDE: its mean is the noise-free ODE solution (up to O(dt))."""
    G = cs.SwitchingTopology.periodic([adjacency_from_edges(3, [(0, 1)]), adjacency_from_edges(3, [(1, 2)])],
                                      0.25, 1.0)
    xi0, P0, R = np.array([0.0, 1.0, 3.0]), np.array([1.0, 0.5, 0.2]), 2000
    t_eval = np.array([0.0, 0.5, 1.0])
    ode = cs.kalman_consensus_continuous(xi0, P0, G, 1.0, 0.1, 0.1, t_eval=t_eval)
    em = cs.kalman_consensus_continuous(np.broadcast_to(xi0, (R, 3)), np.broadcast_to(P0, (R, 3)), G, 1.0, 0.1,
                                        0.1, t_eval=t_eval, rng=10, dt=5e-3)
    assert em.xi.shape == (3, R, 3)
    np.testing.assert_allclose(em.P[:, 0], ode.P, atol=5e-3)  # Euler on eq. (1), O(dt)
    runs = em.xi[-1]
    se = runs.std(axis=0) / np.sqrt(R)
    assert np.all(runs.std(axis=0) > 0.01)  # noise is really injected (agent 3 only via the mean of 1, 2)
    assert np.all(np.abs(runs.mean(axis=0) - ode.xi[-1]) < 4 * se + 2e-3)
    one = cs.kalman_consensus_continuous(xi0, P0, G, 1.0, 0.1, 0.1, t_eval=t_eval, rng=10, dt=5e-3)
    assert one.xi.shape == (3, 3) and np.all(one.xi[-1] != ode.xi[-1])


def test_euler_maruyama_first_step_variance():
    """One EM step from equal states: Var(dxi_i) = h sum_{j != i} g_ij K_ij^2 Omega (white noise of intensity Omega)."""
    G = adjacency_from_edges(3, [(1, 0), (2, 0), (2, 1)], directed=True)  # 1 hears 2, 3; 2 hears 3
    P0, h, R, om = np.array([0.5, 1.0, 2.0]), 1e-2, 20_000, 0.3
    res = cs.kalman_consensus_continuous(np.zeros((R, 3)), np.broadcast_to(P0, (R, 3)), G, h, 0.1, om,
                                         t_eval=[0.0, h], rng=11, dt=h)
    K = P0[:, None] / (P0[None, :] + om)
    var = h * (G * K**2 * om).sum(axis=1)
    np.testing.assert_allclose(res.xi[-1].var(axis=0), var, rtol=0.05, atol=1e-15)
    assert np.all(res.xi[-1][:, 2] == 0.0)  # agent 3 hears nobody: no noise


def test_continuous_batch_equals_separate_runs():
    rng = np.random.default_rng(12)
    n, R = 4, 3
    xi, P = rng.standard_normal((R, n)), rng.uniform(0.1, 2, (R, n))
    topo = cs.SwitchingTopology([0.0, 0.4], [_random_graph(rng, n), _random_graph(rng, n)])
    batch = cs.kalman_consensus_continuous(xi, P, topo, 1.0, 0.1, 0.2, t_eval=[0.0, 0.5, 1.0], rtol=1e-10,
                                           atol=1e-12)
    for r in range(R):
        one = cs.kalman_consensus_continuous(xi[r], P[r], topo, 1.0, 0.1, 0.2, t_eval=[0.0, 0.5, 1.0],
                                             rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(batch.xi[:, r], one.xi, atol=1e-8)
        np.testing.assert_allclose(batch.P[:, r], one.P, atol=1e-8)


# --------------------------------------------------------------------------- tools


def test_random_pairings_structure():
    G = cs.random_pairings(10, 200, 0, max_duration=4)
    assert G.shape == (200, 10, 10)
    np.testing.assert_array_equal(G, np.swapaxes(G, 1, 2))
    np.testing.assert_array_equal(G.sum(axis=2), 1.0)  # each agent talks to exactly one other
    changes = np.flatnonzero(np.any(G[1:] != G[:-1], axis=(1, 2))) + 1
    runs = np.diff(np.concatenate([[0], changes, [200]]))
    assert runs.max() <= 4 * 2  # an epoch lasts at most 4 steps (two epochs may draw the same pairing rarely)
    assert len(changes) > 200 / 4 - 5
    odd = cs.random_pairings(5, 10, 1, size=3)
    assert odd.shape == (10, 3, 5, 5)
    np.testing.assert_array_equal(odd.sum(axis=(2, 3)), 4.0)  # two pairs, one agent waits
    np.testing.assert_array_equal(cs.random_pairings(6, 30, 9), cs.random_pairings(6, 30, 9))


def test_union_condition_on_known_sequences():
    a = adjacency_from_edges(3, [(0, 1)], directed=True)
    b = adjacency_from_edges(3, [(1, 2)], directed=True)
    seq = cs.periodic_sequence(np.stack([a, b]), 2, 12)
    assert seq.shape == (12, 3, 3)
    np.testing.assert_array_equal(cs.spanning_tree_windows(seq, 2), [False] * 6)
    np.testing.assert_array_equal(cs.spanning_tree_windows(seq, 4), [True] * 3)
    assert cs.union_condition_holds(seq, 4) and not cs.union_condition_holds(seq, 3 - 1)
    never = cs.periodic_sequence(np.stack([a, a]), 1, 10)
    assert not any(cs.spanning_tree_windows(never, 10))


def test_central_fusion_formula():
    xi, P = np.array([1.0, 2.0, 4.0]), np.array([1.0, 0.5, 0.25])
    val, var = cs.central_fusion(xi, P)
    assert var == pytest.approx(1 / 7)
    assert val == pytest.approx((1 + 4 + 16) / 7)
    v2, P2 = cs.central_fusion(xi[:, None], P[:, None, None])
    assert v2.shape == (1,) and P2.shape == (1, 1) and v2[0] == pytest.approx(val)


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(P0=[1.0, -1.0, 1.0]), "positive"),
        (dict(P0=[[[1.0, 0.5], [0.0, 1.0]]] * 3, xi0=np.zeros((3, 2))), "symmetric"),
        (dict(P0=[[[1.0, 0.0], [0.0, -1.0]]] * 3, xi0=np.zeros((3, 2))), "positive definite"),
        (dict(P0=[1.0, 1.0]), "shape"),
        (dict(topologies=np.zeros((4, 4, 4))), "4 agents; expected 3"),
        (dict(topologies=np.ones((5, 3, 3))), "zero diagonal"),
        (dict(topologies=-np.ones((5, 3, 3)) + np.eye(3)), "non-negative"),
        (dict(topologies=np.zeros((3, 4))), "square"),
        (dict(topologies=np.zeros((3, 3))), "n_steps is required"),
        (dict(n_steps=9), "holds 5 graphs"),
        (dict(Q=-0.1), "Q"),
        (dict(Omega=np.ones((2, 2))), "Omega"),
        (dict(Omega=-1.0), "Omega"),
    ],
)
def test_discrete_rejects_bad_input(kwargs, match):
    args = dict(xi0=np.zeros(3), P0=np.ones(3), topologies=np.zeros((5, 3, 3)), Q=0.1, Omega=0.1)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        cs.kalman_consensus_discrete(**args)


def test_other_bad_input():
    with pytest.raises(TypeError, match="rng"):
        cs.kalman_consensus_discrete(np.zeros(3), np.ones(3), np.zeros((2, 3, 3)), 0.1, 0.1, rng="seed")
    with pytest.raises(ValueError, match="graph on 2 agents"):
        cs.kalman_consensus_continuous(np.zeros(3), np.ones(3), np.zeros((2, 2)), 1.0, 0.1, 0.1)
    with pytest.raises(ValueError, match="times must be 1-D"):
        cs.SwitchingTopology([0.0], np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match="strictly increasing"):
        cs.SwitchingTopology([0.0, 0.0], np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match="switching sequence"):
        cs.spanning_tree_windows(np.zeros((3, 3)), 2)
    with pytest.raises(ValueError, match="t_final"):
        cs.kalman_consensus_continuous(np.zeros(3), np.ones(3), np.zeros((3, 3)), -1.0, 0.1, 0.1)
    with pytest.raises(ValueError, match="n_agents"):
        cs.random_pairings(1, 10, 0)
    with pytest.raises(ValueError, match="max_duration"):
        cs.random_pairings(4, 10, 0, max_duration=0)
    with pytest.raises(ValueError, match="dwell"):
        cs.periodic_sequence(np.zeros((2, 3, 3)), 0, 10)
    with pytest.raises(ValueError, match="switch_times is only used"):
        cs.kalman_consensus_continuous(np.zeros(3), np.ones(3), np.zeros((3, 3)), 1.0, 0.1, 0.1, switch_times=[0.5])
    with pytest.raises(ValueError, match="batch axes"):  # one schedule per run, but 4 schedules for 3 runs
        cs.kalman_consensus_discrete(np.zeros((3, 5)), np.ones((3, 5)), cs.random_pairings(5, 10, 0, size=4),
                                     0.1, 0.1)
    with pytest.raises(ValueError, match="G has batch axes"):
        cs.kalman_consensus_step(np.zeros((3, 5)), np.ones((3, 5)), np.zeros((2, 5, 5)), 0.1, 0.1)
    with pytest.raises(ValueError, match="Q must be symmetric"):
        cs.kalman_consensus_discrete(np.zeros((3, 2)), np.broadcast_to(np.eye(2), (3, 2, 2)), np.zeros((4, 3, 3)),
                                     [[0.1, 0.05], [0.0, 0.1]], 0.1)
    with pytest.raises(ValueError, match="Omega must be symmetric"):
        cs.kalman_consensus_continuous(np.zeros((3, 2)), np.broadcast_to(np.eye(2), (3, 2, 2)), np.zeros((3, 3)),
                                       1.0, 0.1, [[0.1, 0.05], [0.0, 0.1]])
    with pytest.raises(ValueError, match="Omega"):  # per-link Omega of the wrong team size
        cs.kalman_consensus_step(np.zeros(3), np.ones(3), np.zeros((3, 3)), 0.1, np.full((4, 4, 1, 1), 0.1))
    with pytest.raises(ValueError, match="graph on 4 agents"):
        cs.consensus_matrix(np.ones(3), np.zeros((4, 4)), 0.1, 0.1)
    with pytest.raises(ValueError, match="topology\\(t\\) is a graph on 2 agents"):
        cs.kalman_consensus_continuous(np.zeros(3), np.ones(3), lambda t: np.zeros((2, 2)), 1.0, 0.1, 0.1)
    with pytest.raises(ValueError, match="topologies\\(0\\) must have a zero diagonal"):
        cs.kalman_consensus_discrete(np.zeros(3), np.ones(3), lambda k: np.ones((3, 3)), 0.1, 0.1, n_steps=2)
    with pytest.raises(ValueError, match="topology has 2 agents; the states have 3"):
        cs.kalman_consensus_continuous(np.zeros(3), np.ones(3), cs.SwitchingTopology([0.0], np.zeros((1, 2, 2))),
                                       1.0, 0.1, 0.1)
    with pytest.raises(ValueError, match="graphs must be a switching sequence"):
        cs.SwitchingTopology([0.0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="dwell must be a finite number > 0"):
        cs.SwitchingTopology.periodic(np.zeros((2, 3, 3)), 0.0, 10.0)
    with pytest.raises(ValueError, match="t_eval"):
        cs.kalman_consensus_continuous(np.zeros(3), np.ones(3), np.zeros((3, 3)), 1.0, 0.1, 0.1, t_eval=[0.0, 2.0])
    big = cs.SwitchingTopology([0.0], [np.ones((3, 3)) - np.eye(3)])
    with pytest.raises(RuntimeError, match="dt"):  # explicit Euler on eq. (1): P(1 - 3 h) < 0 for h = 0.5
        cs.kalman_consensus_continuous(np.zeros(3), np.full(3, 100.0), big, 1.0, 0.1, 0.1, rng=0, dt=0.5)


# --------------------------------------------------------------------------- cost of the independence assumption


def test_error_covariance_matches_monte_carlo():
    """Actual covariance Phi P0 Phi^T against independent runs with random initial errors (constant xi*)."""
    rng = np.random.default_rng(13)
    n, R, K = 5, 20_000, 12
    P0 = rng.uniform(0.1, 2.0, n)
    G = cs.random_pairings(n, K, rng)
    actual, believed = cs.error_covariance(P0, G, 0.1, 0.2)
    assert actual.shape == believed.shape == (K + 1, n)
    np.testing.assert_allclose(actual[0], P0)
    xi_star = 3.0
    xi0 = xi_star + rng.standard_normal((R, n)) * np.sqrt(P0)
    runs = cs.kalman_consensus_discrete(xi0, np.broadcast_to(P0, (R, n)), G, 0.1, 0.2)
    np.testing.assert_allclose(runs.P[:, 0], believed, atol=1e-14)
    np.testing.assert_allclose(((runs.xi - xi_star) ** 2).mean(axis=1), actual, rtol=0.05)


def test_error_covariance_identities():
    """First meeting of two independent agents is an exact Kalman update; no schedule beats central fusion."""
    P0 = np.array([0.5, 2.0, 1.0])
    G = adjacency_from_edges(3, [(0, 1)])[None]
    actual, believed = cs.error_covariance(P0, G, 0.0, 0.0, include_self=False)
    fused = 1 / (1 / 0.5 + 1 / 2.0)
    np.testing.assert_allclose(actual[1], [fused, fused, 1.0], rtol=1e-12)
    np.testing.assert_allclose(believed[1], actual[1], rtol=1e-12)  # the assumption is still true here
    rng = np.random.default_rng(14)
    P0 = rng.uniform(0.01, 3.0, 8)
    G = cs.random_pairings(8, 60, rng)
    actual, believed = cs.error_covariance(P0, G, 0.0, 1e-6, include_self=False)
    P_f = cs.central_fusion(np.zeros(8), P0)[1]
    assert np.all(actual >= P_f * (1 - 1e-9))  # Cauchy-Schwarz: rows of Phi sum to 1
    assert np.all(believed[-1] < 1e-2 * P_f)  # shared information counted again: overconfident
    vec_a, vec_b = cs.error_covariance(P0[:, None, None] * np.eye(2), G, 0.0, 1e-6 * np.eye(2), include_self=False)
    np.testing.assert_allclose(vec_a[..., 1, 1], actual, rtol=1e-9)
    np.testing.assert_allclose(vec_a[..., 0, 1], 0.0, atol=1e-15)


def test_continuous_run_refuses_a_graph_stack_and_names_switching_topology():
    """A (K, n, n) stack is one graph per step in discrete time; continuous time needs the switching times."""
    from mascore import graphs

    stack = np.stack([graphs.ring_graph(4), graphs.path_graph(4)])
    with pytest.raises(ValueError, match="SwitchingTopology"):
        cs.kalman_consensus_continuous(np.arange(4.0), np.ones(4), stack, 2.0, 0.1, 0.1)
