"""Tests of mascore.synchronization: eq. (16), Lemmas 1-2, eq. (15), Corollary 1."""

import numpy as np
import pytest

from mascore import graphs, riccati
from mascore import synchronization as sync

A_EX = np.array([[0.0, -1.0], [1.0, 0.0]])
ADJ_EX = np.array([[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], dtype=float)
PIN_EX = np.array([1.0, 0.0, 0.0, 0.0])


def riccati_fixed_point(A, B, Q, iters=20000):
    """Independent computation: the Riccati difference iteration from P = Q."""
    P = Q.copy()
    for _ in range(iters):
        P = A.T @ P @ A + Q - A.T @ P @ B @ np.linalg.solve(B.T @ P @ B, B.T @ P @ A)
    return P


def test_example_riccati_lemma2_values():
    """Bhattacharjee and Subbarao (2021), Sec. 5: B = I gives P = Q, K = A, r = 1, c = 1/c0 = 1.5."""
    d = sync.design_synchronization(A_EX, np.eye(2), 0.1 * np.eye(2), ADJ_EX, PIN_EX, 2 / 3, 0.6)
    assert np.allclose(d.P, 0.1 * np.eye(2), atol=1e-12)
    assert np.allclose(d.K, A_EX)
    assert d.r == pytest.approx(1.0, abs=1e-12)
    assert d.c == pytest.approx(1.5)
    assert np.all(d.in_circle) and d.rho < 1


def test_bound_eq21_published_value():
    """Sec. 5: with p0 = 2, q_bar = 0.1 the bound of eq. (21) equals 2.462."""
    d = sync.design_synchronization(A_EX, np.eye(2), 0.1 * np.eye(2), ADJ_EX, PIN_EX, 2 / 3, 0.6)
    assert sync.bound_eq21(d.B_c, np.eye(2), 2.0, 0.1) == pytest.approx(2.462, abs=5e-4)


def test_fig2c_exponential_bound():
    """Fig. 2(c): |A_c^k| <= 1.1 * 0.9^k; the fitted alpha for mu = 0.9 is below 1.1 and tight."""
    d = sync.design_synchronization(A_EX, np.eye(2), 0.1 * np.eye(2), ADJ_EX, PIN_EX, 2 / 3, 0.6)
    assert sync.exponential_bound_ratio(d.A_c, 1.1, 0.9, 400) <= 1.0
    alpha = sync.fit_alpha(d.A_c, 0.9)
    assert alpha <= 1.1
    assert sync.exponential_bound_ratio(d.A_c, alpha, 0.9, 400) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="rho"):
        sync.fit_alpha(d.A_c, 0.5)


@pytest.mark.parametrize(
    "A,B",
    [
        (np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[0.0], [1.0]])),  # double integrator
        (np.array([[1.1, 0.3, 0.0], [0.0, 0.9, 1.0], [0.2, 0.0, 1.05]]), np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])),
    ],
)
def test_riccati_general_B_residual_and_fixed_point(A, B):
    Q = np.eye(A.shape[0])
    P = sync.riccati_like(A, B, Q)
    assert sync.riccati_like_residual(A, B, Q, P) < 1e-9
    assert np.all(np.linalg.eigvalsh(P) > 0)
    assert np.allclose(P, riccati_fixed_point(A, B, Q), rtol=1e-8)


@pytest.mark.parametrize(
    "A,B",
    [
        (np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[0.0], [1.0]])),  # double integrator, r < 1
        (np.array([[1.1, 0.3, 0.0], [0.0, 0.9, 1.0], [0.2, 0.0, 1.05]]), np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])),
    ],
)
def test_lemma2_conclusion_for_general_B(A, B):
    """Lemma 2 beyond B = I: K and c from eq. (16) make rho(A_c) < 1 (checked per mode, Lemma 1, and on A_c)."""
    # pinned directed path 1 -> 2 -> 3 -> 4: Gamma is triangular with all eigenvalues 1/2
    adj = graphs.adjacency_from_edges(4, [(0, 1), (1, 2), (2, 3)], directed=True)
    pin = [1.0, 0.0, 0.0, 0.0]
    Q = np.eye(A.shape[0])
    d = sync.design_synchronization(A, B, Q, adj, pin, 0.5, 0.05)
    assert d.residual < 1e-9 and d.r < 1 and 0.05 / 0.5 < d.r
    assert np.allclose(d.eigs, 0.5)
    # K is the minimizer of the one-step cost (A x + B u)^T P (A x + B u) over u = -K x: stationarity
    # B^T P (A - B K) = 0 (the defining property, not the formula of riccati_gain), and the
    # discrete LQR gain with a vanishing input weight tends to it (an independent solver).
    np.testing.assert_allclose(B.T @ d.P @ (A - B @ d.K), 0.0, atol=1e-8 * max(1.0, np.abs(d.P).max()))
    K_small_r, _, _ = riccati.dare(A, B, Q, 1e-9 * np.eye(B.shape[1]))
    np.testing.assert_allclose(K_small_r, d.K, rtol=1e-4, atol=1e-6)
    assert d.rho < 1
    # Gamma is one Jordan block here, so eig(A_c) is only accurate to ~eps^(1/4)
    assert d.rho == pytest.approx(sync.spectral_radius(A - d.c * 0.5 * B @ d.K), rel=1e-3)
    alpha = sync.fit_alpha(d.A_c, 0.5 * (1 + d.rho))
    assert sync.exponential_bound_ratio(d.A_c, alpha, 0.5 * (1 + d.rho), 300) == pytest.approx(1.0)


def test_lemma1_two_computations_of_rho():
    """rho(A_c) = max_i rho(A - c Lambda_i B K) (Lemma 1, the Kronecker structure of eq. (15))."""
    A = np.array([[1.0, 1.0], [0.0, 1.0]])
    B = np.array([[0.0], [1.0]])
    Q = np.eye(2)
    P = sync.riccati_like(A, B, Q)
    K = sync.riccati_gain(A, B, P)
    Gamma = sync.pinned_interaction_matrix(ADJ_EX, PIN_EX)
    c = 1.2
    Ac, Bc = sync.closed_loop_matrices(A, B, K, c, Gamma)
    per_mode = max(sync.spectral_radius(A - c * lam * B @ K) for lam in np.linalg.eigvals(Gamma))
    assert sync.spectral_radius(Ac) == pytest.approx(per_mode, rel=1e-8)
    assert np.allclose(Ac + Bc, np.kron(np.eye(4), A))


def test_local_control_matches_eq12():
    """u^(g) of eq. (12) (Kronecker form) equals the agent-by-agent law of Sec. 4.2."""
    rng = np.random.default_rng(0)
    K = rng.standard_normal((2, 2))
    c = 1.5
    xhat = rng.standard_normal((4, 2))
    x0 = rng.standard_normal(2)
    u = sync.local_control(xhat, x0, ADJ_EX, PIN_EX, K, c)
    L = graphs.laplacian(ADJ_EX)
    Dg = np.diag(ADJ_EX.sum(1))
    M = c * np.linalg.inv(np.eye(4) + Dg + np.diag(PIN_EX)) @ (L + np.diag(PIN_EX))
    ug = -np.kron(M, K) @ xhat.ravel() + np.kron(M, K) @ np.tile(x0, 4)
    assert np.allclose(u.ravel(), ug)
    # batched over runs
    ub = sync.local_control(np.stack([xhat, xhat]), np.stack([x0, x0]), ADJ_EX, PIN_EX, K, c)
    assert np.allclose(ub[1], u)


def test_circle_contains_is_open():
    assert sync.circle_contains(0.5 + 0.0j, 0.0, 0.6)
    assert not sync.circle_contains(0.6, 0.0, 0.6)


def test_mu_bar():
    assert sync.mu_bar(1.1, 0.9, 4) == pytest.approx(22.0)


# ------------------------------------------------------------------ bad input


def test_assumption4_no_spanning_tree():
    adj = np.zeros((4, 4))
    adj[1, 0] = adj[3, 2] = 1.0  # two separate pairs
    with pytest.raises(ValueError, match="Assumption 4 fails: the interaction graph has no directed spanning tree"):
        sync.pinned_interaction_matrix(adj, [1, 0, 1, 0])


def test_assumption4_root_not_pinned():
    adj = graphs.adjacency_from_edges(3, [(0, 1), (1, 2)], directed=True)  # path rooted at agent 1 (0-based 0)
    assert graphs.spanning_tree_roots(adj).tolist() == [0]
    with pytest.raises(ValueError, match="no root of a spanning tree .* is pinned"):
        sync.design_synchronization(A_EX, np.eye(2), 0.1 * np.eye(2), adj, [0, 1, 0], 2 / 3, 0.6)


def test_lemma2_conditions_checked():
    with pytest.raises(ValueError, match="outside C"):
        sync.design_synchronization(A_EX, np.eye(2), 0.1 * np.eye(2), ADJ_EX, PIN_EX, 2 / 3, 0.3)
    with pytest.raises(ValueError, match="is not below r"):
        sync.design_synchronization(A_EX, np.eye(2), 0.1 * np.eye(2), ADJ_EX, PIN_EX, 0.6, 0.7)


def test_assumption3_checked():
    with pytest.raises(ValueError, match="full column rank"):
        sync.riccati_like(A_EX, np.array([[1.0, 2.0], [2.0, 4.0]]), np.eye(2))
    with pytest.raises(ValueError, match="not stabilizable"):
        sync.riccati_like(np.diag([2.0, 0.5]), np.array([[0.0], [1.0]]), np.eye(2))


def test_synchronization_law_equals_the_plain_function_and_is_read_only():
    """The checked law gives the plain function's numbers; its arrays cannot be changed, nor through the caller's."""
    ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)
    pin = np.array([1.0, 0.0, 0.0, 0.0])
    K = np.array([[0.3, -0.2], [0.1, 0.4]])
    rng = np.random.default_rng(3)
    xhat, lead = rng.normal(size=(5, 4, 2)), rng.normal(size=2)
    law = sync.SynchronizationLaw(ring, pin, K, 1.5)
    expected = sync.local_control(xhat, lead, ring, pin, K, 1.5)
    K[0, 0] = 99.0  # the caller's array changes after construction: the law keeps its copy
    pin[1] = 5.0
    np.testing.assert_array_equal(law(xhat, lead), expected)
    with pytest.raises(ValueError):
        law.K[0, 0] = 1.0
    with pytest.raises(ValueError, match="c"):
        sync.SynchronizationLaw(ring, [1.0, 0, 0, 0], K, -1.0)


def test_synchronization_law_from_threads_equals_serial():
    """Eight threads sharing one law give the serial results bit for bit."""
    from concurrent.futures import ThreadPoolExecutor

    ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)
    law = sync.SynchronizationLaw(ring, [1.0, 0.0, 0.0, 0.0], np.eye(2), 1.5)
    inputs = [np.random.default_rng(s).normal(size=(200, 4, 2)) for s in range(8)]
    serial = [law(x, np.zeros(2)) for x in inputs]
    with ThreadPoolExecutor(8) as pool:
        threaded = list(pool.map(lambda x: law(x, np.zeros(2)), inputs))
    for a, b in zip(serial, threaded):
        assert a.tobytes() == b.tobytes()
