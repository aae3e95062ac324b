"""Tests of the per-agent whole-team Kalman filters (Song et al. 2023, eqs. (8)-(34), Theorem 1)."""

import numpy as np
import pytest

from mascore import _kf_reference as ref
from mascore import _team_kernels, centralized_team_filter, team_model, team_observability
from mascore import distributed_kf as dk
from mascore.agents import double_integrator
from mascore.graphs import complete_graph, laplacian, path_graph, ring_graph, star_graph
from mascore.kalman import nees, nees_interval, update
from mascore.rendezvous import RendezvousModel, consensus_control, rendezvous_gain, simulate_rendezvous
from mascore.sensing import IsolatedAgentError, measure, selection_matrices, stacked_measurement

AGENT = double_integrator(2, 0.1)
K = rendezvous_gain(0.5, 1.5, 2)
BK = AGENT.B @ K



def _rv(**changes) -> RendezvousModel:
    """The rendezvous model of these tests (unit noise), with some entries changed."""
    args = dict(A=AGENT.A, B=AGENT.B, K=K, Q=np.eye(4), R=np.eye(4), dt=0.1)
    args.update(changes)
    return RendezvousModel(**args)

def _model(N, reduce=True, Q=None, R=None):
    Q = np.eye(4) if Q is None else Q
    R = 2.0 * np.eye(4) if R is None else R
    return team_model.team_filter_model(AGENT.A, AGENT.B, K, Q, R, N, reduce=reduce)


def _random_sigma(model, rng, B=1):
    """A generic SPD reduced augmented covariance (batch, N M_r, N M_r)."""
    n = model.n_agents * model.M_r
    G = rng.normal(size=(B, n, n)) / np.sqrt(n)
    return G @ np.swapaxes(G, -1, -2) + 0.5 * np.eye(n)


@pytest.mark.parametrize("reduce", [True, False])
@pytest.mark.parametrize("graph", [path_graph(4), star_graph(4)])
def test_structured_estimation_based_step_equals_plain_eqs_29_34(reduce, graph):
    """Sibling implementations: tensor/Kronecker recursion == eqs. (14), (29)-(34), (16)-(20) written out."""
    N = 4
    model = _model(N, reduce)
    rng = np.random.default_rng(0)
    Sig = _random_sigma(model, rng)
    Xh = rng.normal(size=(1, N, N, 4))
    Z, S = measure(1, rng.normal(size=(1, N, 4)), graph, 2.0 * np.eye(4))
    Xp, Sp = dk.eb_predict(model, Xh, Sig, laplacian(graph))
    Xn, Sn, _ = dk.eb_update(model, Xp, Sp, Z, S[0])
    z = [stacked_measurement(Z[0], S[0], i) for i in range(N)]
    Xn2, Sn2 = ref.plain_estimation_based_step(
        Xh[0].reshape(N, -1), team_model.expand_covariance(Sig[0], model.kron), AGENT.A, BK, np.eye(4), model.R, graph, z)
    np.testing.assert_allclose(Xn[0].reshape(N, -1), Xn2, atol=1e-10)
    np.testing.assert_allclose(team_model.expand_covariance(Sn[0], model.kron), Sn2, atol=1e-10)


@pytest.mark.parametrize("graph", [ring_graph(16), path_graph(14)])
def test_sparse_row_block_recursion_equals_plain_eqs_29_34(graph):
    """Large enough for the sparse F_1, F_2 and rank-q row-block path (N M_r > 384): still eqs. (29)-(34)."""
    N = graph.shape[0]
    model = _model(N)
    assert N * model.M_r > _team_kernels.DENSE_MAX
    rng = np.random.default_rng(5)
    Sig = _random_sigma(model, rng)
    Xh = rng.normal(size=(1, N, N, 4))
    Z, S = measure(1, rng.normal(size=(1, N, 4)), graph, 2.0 * np.eye(4))
    Xn, Sn, _ = dk.eb_update(model, *dk.eb_predict(model, Xh, Sig, laplacian(graph)), Z, S[0])
    z = [stacked_measurement(Z[0], S[0], i) for i in range(N)]
    Xn2, Sn2 = ref.plain_estimation_based_step(
        Xh[0].reshape(N, -1), team_model.expand_covariance(Sig[0], model.kron), AGENT.A, BK, np.eye(4), model.R, graph, z)
    np.testing.assert_allclose(Xn[0].reshape(N, -1), Xn2, atol=1e-9)
    np.testing.assert_allclose(team_model.expand_covariance(Sn[0], model.kron), Sn2, atol=1e-9)


def test_rank_q_gain_equals_masked_full_solve():
    """The gathered q x q form of G H (mascore._masked_gain) == Σ D (D (Σ + R) D + I - D)^{-1} D."""
    from mascore import _masked_gain as mg

    rng = np.random.default_rng(6)
    M = 60  # above the small-size shortcut
    G = rng.normal(size=(3, M, M))
    Sig = G @ np.swapaxes(G, -1, -2) / M + np.eye(M)
    H = rng.normal(size=(M, M))
    R = H @ H.T / M + np.eye(M)
    d = (rng.random((3, M)) < 0.3).astype(float)
    D = d[..., :, None] * d[..., None, :]
    full = np.linalg.solve(D * (Sig + R) + np.eye(M) * (1 - d[..., None]), d[..., :, None] * Sig)
    np.testing.assert_allclose(mg.masked_gain(Sig, d, R), np.swapaxes(full, -1, -2) * d[..., None, :], atol=1e-12)


def test_structured_step_batched_over_topologies():
    """One covariance per run (Fig. 3): batch entry b equals the unbatched step with topology b."""
    N = 4
    model = _model(N)
    rng = np.random.default_rng(1)
    graphs = np.stack([path_graph(N), ring_graph(N)])
    Sig = _random_sigma(model, rng, B=2)
    Xh = rng.normal(size=(2, N, N, 4))
    Z, S = measure(2, rng.normal(size=(2, N, 4)), graphs, 2.0 * np.eye(4))
    Lb = np.stack([laplacian(g) for g in graphs])
    Xp, Sp = dk.eb_predict(model, Xh, Sig, Lb)
    Xn, Sn, _ = dk.eb_update(model, Xp, Sp, Z, S)
    for b in range(2):
        xp, sp = dk.eb_predict(model, Xh[b:b + 1], Sig[b:b + 1], Lb[b])
        xn, sn, _ = dk.eb_update(model, xp, sp, Z[b:b + 1], S[b])
        np.testing.assert_allclose(Xn[b], xn[0], atol=1e-12)
        np.testing.assert_allclose(Sn[b], sn[0], atol=1e-12)


@pytest.mark.parametrize("reduce", [True, False])
def test_measurement_based_step_equals_plain_eqs_14_20(reduce):
    N = 5
    model = _model(N, reduce)
    rng = np.random.default_rng(2)
    Si = dk.agent_covariances(model, _random_sigma(model, rng))
    Xh = rng.normal(size=(1, N, N, 4))
    A = path_graph(N)
    Z, S = measure(3, rng.normal(size=(1, N, 4)), A, 2.0 * np.eye(4))
    Xp, Sp = dk.mb_predict(model, Xh, Si, laplacian(A))
    Xn, Sn, _ = dk.mb_update(model, Xp, Sp, Z, S[0])
    z = [stacked_measurement(Z[0], S[0], i) for i in range(N)]
    Xn2, Sn2 = ref.plain_measurement_based_step(
        Xh[0].reshape(N, -1), team_model.expand_covariance(Si[0], model.kron), AGENT.A, BK, np.eye(4), model.R, A, z)
    np.testing.assert_allclose(Xn[0].reshape(N, -1), Xn2, atol=1e-10)
    np.testing.assert_allclose(team_model.expand_covariance(Sn[0], model.kron), Sn2, atol=1e-10)


def test_agent_update_equals_textbook_update_with_selection_matrices():
    """The masked batched update == mascore.kalman.update with H_i and stacked z_i (eq. (3))."""
    N, m = 4, 4
    rng = np.random.default_rng(4)
    A = path_graph(N)
    R_team = np.kron(np.eye(N), np.diag([1.0, 2.0, 0.5, 0.3]))
    G = rng.normal(size=(N, N * m, N * m))
    P = G @ np.swapaxes(G, -1, -2) + np.eye(N * m)
    X = rng.normal(size=(N, N, m))
    Z, S = measure(5, rng.normal(size=(N, m)), A, R_team)
    Xa, Pa, _ = dk.agent_update(X, P, Z, S, R_team)
    for i, H in enumerate(selection_matrices(A, m)):
        x_ref, P_ref = update(X[i].reshape(-1), P[i], stacked_measurement(Z, S, i), H, H @ R_team @ H.T)
        np.testing.assert_allclose(Xa[i].reshape(-1), x_ref, atol=1e-10)
        np.testing.assert_allclose(Pa[i], P_ref, atol=1e-10)


def test_centralized_update_equals_stacked_kalman_update_and_bounds_every_agent():
    N = 4
    model = _model(N)
    rng = np.random.default_rng(6)
    A = path_graph(N)
    Pr = dk.agent_covariances(model, _random_sigma(model, rng))[:, 0]  # (1, Mr, Mr)
    x = rng.normal(size=(1, N, 4))
    Z, S = measure(7, rng.normal(size=(1, N, 4)), A, 2.0 * np.eye(4))
    xc, Pc = centralized_team_filter.centralized_update(model, x, Pr, Z, S[0])
    Hs = selection_matrices(A, 4)
    H = np.vstack(Hs)
    z = np.concatenate([stacked_measurement(Z[0], S[0], i) for i in range(N)])
    Rbig = np.kron(np.eye(H.shape[0] // 4), 2.0 * np.eye(4))
    x_ref, P_ref = update(x[0].reshape(-1), team_model.expand_covariance(Pr[0], 2), z, H, Rbig)
    np.testing.assert_allclose(xc[0].reshape(-1), x_ref, atol=1e-10)
    np.testing.assert_allclose(team_model.expand_covariance(Pc[0], 2), P_ref, atol=1e-10)
    # every agent alone (same prior) is less certain: P_i - P_c is PSD
    Xh = np.broadcast_to(x[:, None], (1, N, N, 4)).copy()
    _, Pi, _ = dk.mb_update(model, Xh, np.broadcast_to(Pr[:, None], (1, N, *Pr.shape[1:])), Z, S[0])
    assert np.all(np.linalg.eigvalsh(Pi[0] - Pc[0]) > -1e-10)


def test_lyapunov_v_is_nees():
    rng = np.random.default_rng(8)
    G = rng.normal(size=(6, 6))
    P_r = G @ G.T + np.eye(6)
    e = rng.normal(size=12)
    np.testing.assert_allclose(team_observability.lyapunov_v(e, P_r, kron=2), nees(e, team_model.expand_covariance(P_r, 2)))


def test_lemma1_initial_map_gives_F_i1_equal_I_kron_A():
    """With a common initial estimate, C_i[0] = 1 ⊗ I and F_2 C_i = L ⊗ BK, so F_i,1 = I ⊗ A."""
    N = 4
    model = _model(N)
    A = path_graph(N)
    Sig0 = dk.eb_initial_covariance(model, np.diag([9.0, 9.0, 1.0, 1.0]), common=True)
    F2C = dk.f2_cross(model, Sig0, laplacian(A))[0] @ np.linalg.inv(dk.agent_covariances(model, Sig0)[0])
    for i in range(N):
        np.testing.assert_allclose(F2C[i], np.kron(laplacian(A), model.BK_r), atol=1e-12)


def test_closed_loop_matrices_reproduce_the_control_laws():
    """F_1 X = (I⊗A)X + (I⊗B)U(X) (eq. (11)) and F_2 e = (I⊗B)(U(X̂) - U(X)) (eqs. (26)-(28))."""
    N = 4
    rng = np.random.default_rng(9)
    Adj = ring_graph(N)
    L = laplacian(Adj)
    F1, F2 = team_model.closed_loop_matrices(AGENT.A, BK, L)
    x = rng.normal(size=(N, 4))
    Xh = rng.normal(size=(N, N, 4))
    U_true = consensus_control(np.broadcast_to(x, (N, N, 4)), L, K)
    U_est = consensus_control(Xh, L, K)
    np.testing.assert_allclose(F1 @ x.reshape(-1), (x @ AGENT.A.T + U_true @ AGENT.B.T).reshape(-1), atol=1e-12)
    e = (x[None] - Xh).reshape(-1)
    np.testing.assert_allclose(F2 @ e, ((U_est - U_true) @ AGENT.B.T).reshape(-1), atol=1e-12)
    # u_i = K sum_{j in N_i} (x_j - x_i), eq. (4), written as a loop
    for i in range(N):
        ref = sum(K @ (x[j] - x[i]) for j in np.flatnonzero(Adj[i]))
        np.testing.assert_allclose(U_true[i], ref, atol=1e-12)


def test_observability_of_system_43():
    """Star seen from a leaf hides the antisymmetric modes of the other leaves; paths and rings do not."""
    assert team_observability.observable_agents(AGENT.A, BK, star_graph(5)).tolist() == [True, False, False, False, False]
    assert team_observability.observable_agents(AGENT.A, BK, path_graph(6)).all()
    assert team_observability.observable_agents(AGENT.A, BK, ring_graph(6)).all()
    assert team_observability.observable_agents(AGENT.A, BK, complete_graph(4)).all()


def test_graph_observability_agrees_with_observability_matrix():
    """The Laplacian PBH shortcut and the observability-matrix rank agree on small graphs."""
    rng = np.random.default_rng(10)
    Ar, BKr = AGENT.A[::2, ::2], BK[::2, ::2]
    for _ in range(20):
        A = np.triu((rng.random((5, 5)) < 0.5).astype(float), 1)
        A = A + A.T
        if np.any(A.sum(1) == 0):
            continue
        fast = team_observability.observable_agents(AGENT.A, BK, A)
        F1, _ = team_model.closed_loop_matrices(Ar, BKr, laplacian(A))
        for i in range(5):
            row = A[i] > 0
            row[i] = True
            H = np.kron(np.eye(5)[row], np.eye(2))
            assert team_observability._observable(F1, H, 1e-9) == fast[i]


def test_require_observable_and_simulation_refuse_unobservable_graph():
    with pytest.raises(ValueError, match=r"not observable for agent\(s\) \[1, 2, 3\]"):
        team_observability.require_observable(AGENT.A, BK, star_graph(4))
    x0 = np.zeros((1, 4, 4))
    with pytest.raises(ValueError, match="system \\(43\\)"):
        simulate_rendezvous(0, _rv(), x0, star_graph(4), 5, "estimation", x_hat0=np.zeros((1, 16)), P0=np.eye(4))
    # the measurement-based loop does not need (43)
    simulate_rendezvous(0, _rv(), x0, star_graph(4), 2, "measurement")


def test_isolated_agent_raises():
    A = path_graph(4)
    A[3, 2] = A[2, 3] = 0
    with pytest.raises(IsolatedAgentError, match="agent 3"):
        simulate_rendezvous(0, _rv(), np.zeros((1, 4, 4)), A, 2, "measurement")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(Q=-np.eye(4)), "Q must be positive semidefinite"),
        (dict(Q=np.eye(3)), "Incompatible dimensions of Q"),
        (dict(R=np.zeros((4, 4))), "R must be positive definite"),
        (dict(R=np.eye(5)), "Incompatible dimensions of R"),
        (dict(K=np.ones((2, 3))), "Incompatible dimensions of K"),
        (dict(n_agents=1), "n_agents"),
    ],
)
def test_bad_model_input(kwargs, match):
    args = dict(A=AGENT.A, B=AGENT.B, K=K, Q=np.eye(4), R=np.eye(4), n_agents=4)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        team_model.team_filter_model(**args)


def test_bad_shapes_in_steps():
    model = _model(3)
    Sig = dk.eb_initial_covariance(model, np.eye(4))
    with pytest.raises(ValueError, match="X_hat"):
        dk.eb_predict(model, np.zeros((1, 3, 4)), Sig, laplacian(path_graph(3)))
    with pytest.raises(ValueError, match="Sigma"):
        dk.eb_predict(model, np.zeros((1, 3, 3, 4)), Sig[:, :5, :5], laplacian(path_graph(3)))
    with pytest.raises(ValueError, match="laplacian"):
        dk.eb_predict(model, np.zeros((1, 3, 3, 4)), Sig, np.ones((3, 3)))
    with pytest.raises(ValueError, match="P0 is not of the form"):
        dk.eb_initial_covariance(model, np.array([[1.0, 0.5, 0, 0], [0.5, 1.0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    with pytest.raises(ValueError, match="mode must be one of"):
        simulate_rendezvous(0, _rv(), np.zeros((1, 3, 4)), path_graph(3), 2, "magic")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(x0=np.full((1, 3, 4), np.nan)), "x0 contains NaN"),
        (dict(x_hat0=np.full((1, 12), np.inf)), "x_hat0 contains NaN"),
        (dict(x_hat0=np.zeros((1, 3, 5))), "Incompatible dimensions of x_hat0"),
        (dict(P0=np.eye(3)), "Incompatible dimensions of P0"),
        (dict(P0=-np.eye(4)), "P0 must be positive semidefinite"),
        (dict(x0=np.zeros((1, 3, 3))), "x0 must hold states of the model's size m = 4"),
        (dict(model=dict(R=np.diag([1.0, 1.0, 1.0, 0.0]))), "R must be positive definite"),
        (dict(adjacency=ring_graph(4)), r"adjacency must be \(3, 3\)"),
        (dict(n_steps=0), "n_steps must be an integer >= 1"),
    ],
)
def test_bad_simulation_input_is_named(kwargs, match):
    """Every bad argument of the estimation-based loop fails early, naming the argument."""
    model = _rv(**kwargs.pop("model", {}))
    args = dict(rng=0, model=model, x0=np.zeros((1, 3, 4)), adjacency=path_graph(3), n_steps=2, mode="estimation",
                x_hat0=np.zeros((1, 12)), P0=np.eye(4))
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        simulate_rendezvous(**args)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(A=np.ones((3, 2))), "A must be square"),
        (dict(B=np.ones((3, 2))), "Incompatible dimensions of B"),
        (dict(K=np.ones((2, 3))), "Incompatible dimensions of K"),
        (dict(Q=np.diag([1.0, 1.0, 1.0, -1.0])), "Q must be positive semidefinite"),
        (dict(Q=np.eye(3)), "Incompatible dimensions of Q"),
        (dict(R=np.eye(5)), "R must be"),
        (dict(dt=-0.1), "dt must be a positive sampling time"),
    ],
)
def test_bad_rendezvous_model_is_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        _rv(**kwargs)


def test_rendezvous_model_must_be_a_model():
    with pytest.raises(TypeError, match="model must be a RendezvousModel"):
        simulate_rendezvous(0, (AGENT.A, AGENT.B), np.zeros((3, 4)), path_graph(3), 2, "true")


def test_reduced_and_unreduced_simulations_agree():
    """The Kronecker reduction changes nothing but the cost."""
    x0 = np.random.default_rng(11).normal(scale=20, size=(2, 3, 4))
    xh0 = (x0 + 3.0).reshape(2, -1)
    a = simulate_rendezvous(12, _rv(), x0, path_graph(3), 20, "estimation", x_hat0=xh0, P0=9 * np.eye(4))
    Q = np.diag([1.0, 1.0, 1.0, 1.0 + 1e-9])  # breaks the I_2 factor -> unreduced model
    b = simulate_rendezvous(12, _rv(Q=Q), x0, path_graph(3), 20, "estimation", x_hat0=xh0, P0=9 * np.eye(4))
    assert a.model.kron == 2 and b.model.kron == 1
    np.testing.assert_allclose(a.states, b.states, atol=1e-6)
    np.testing.assert_allclose(a.nees, b.nees, rtol=1e-6)


@pytest.mark.parametrize("mode", ["estimation", "measurement-filter"])
def test_nees_consistent_over_monte_carlo(mode):
    """Statistical honesty: run-averaged NEES of every agent lies in its 95 % interval (eqs. (15), (29)-(34))."""
    N, n_runs = 4, 200
    rng = np.random.default_rng(13)
    x0 = np.broadcast_to(rng.normal(scale=30, size=(N, 4)), (n_runs, N, 4)).copy()
    P0 = np.diag([25.0, 25.0, 1.0, 1.0])
    xh0 = (x0 + rng.standard_normal(x0.shape) * np.sqrt(np.diag(P0))).reshape(n_runs, -1)
    res = simulate_rendezvous(14, _rv(), x0, path_graph(N), 60, mode, x_hat0=xh0, P0=P0)
    avg = res.nees[1:].mean(axis=1)  # (T, N)
    lo, hi = nees_interval(4 * N, n_runs)
    grand_lo, grand_hi = nees_interval(4 * N, n_runs * avg.shape[0] // 10)  # ~10-step correlation allowance
    assert grand_lo < avg.mean() < grand_hi
    assert np.mean((avg > lo) & (avg < hi)) > 0.88


def test_estimation_based_covariance_needs_the_cross_terms():
    """Dropping the cross-covariances (treating the loop as measurement-based) underestimates the error."""
    N, n_runs = 4, 200
    rng = np.random.default_rng(15)
    x0 = np.broadcast_to(rng.normal(scale=30, size=(N, 4)), (n_runs, N, 4)).copy()
    P0 = np.diag([25.0, 25.0, 1.0, 1.0])
    xh0 = (x0 + rng.standard_normal(x0.shape) * np.sqrt(np.diag(P0))).reshape(n_runs, -1)
    res = simulate_rendezvous(16, _rv(R=4 * np.eye(4)), x0, path_graph(N), 40, "estimation", x_hat0=xh0, P0=P0)
    model = res.model
    # the naive covariance: eq. (15) recursion of every agent, ignoring F_2 e
    Si = dk.agent_covariances(model, dk.eb_initial_covariance(model, P0))
    L = laplacian(path_graph(N))
    S = np.ones((N, N), bool)
    S[np.abs(L) == 0] = False
    for _ in range(40):
        Tr = np.einsum("ab,ibc,dc->iad", np.kron(np.eye(N), model.A_r) - np.kron(L, model.BK_r), Si[0],
                       np.kron(np.eye(N), model.A_r) - np.kron(L, model.BK_r))
        Si = Tr[None] + np.kron(np.eye(N), model.Q_r)
        _, Si, _ = dk.mb_update(model, np.zeros((1, N, N, 4)), Si, np.zeros((1, N, N, 4)), S)
    ratio = np.trace(res.sigma_i[-1], axis1=-2, axis2=-1) / np.trace(Si[0], axis1=-2, axis2=-1)
    assert np.all(ratio > 1.01)


def test_theorem1_M_positive_along_run():
    """Eq. (49) with the regression map C_i: smallest eigenvalue of M_i[k+1] > 0 (Theorem 1)."""
    N = 5
    rng = np.random.default_rng(17)
    x0 = rng.normal(scale=30, size=(1, N, 4))
    res = simulate_rendezvous(18, _rv(), x0, path_graph(N), 80, "estimation", x_hat0=(x0 + 5).reshape(1, -1),
                              P0=25 * np.eye(4))
    th = team_observability.theorem1_min_eigenvalues(res.model, laplacian(path_graph(N)), res.gains, res.sigma_i, res.f2_cross)
    assert th["min_eig"].shape == (80, N)
    assert th["min_eig"].min() > 0
    assert np.all(th["min_eig_rel"] <= 1 + 1e-9)


def test_exact_control_noise_correlation_matches_monte_carlo_and_eq15_does_not():
    """Eq. (15) neglects E[e_i nu_bar^T] (agent i's own noise is in its posterior and its control).

    One prediction step sampled directly: the corrected covariance (mb_predict with KH_prev) matches the
    sample covariance of the true prediction error; the paper's eq. (15) is visibly off for R = 10 I.
    """
    N, Rv, n = 3, 10.0, 100_000
    model = team_model.team_filter_model(AGENT.A, AGENT.B, K, np.eye(4), Rv * np.eye(4), N, reduce=False)
    A = path_graph(N)
    L = laplacian(A)
    S = A > 0
    S[np.diag_indices(N)] = True
    rng = np.random.default_rng(20)
    M = 4 * N
    G = rng.normal(size=(N, M, M))
    Sp = G @ np.swapaxes(G, -1, -2) / M * 20 + np.eye(M)
    X0 = np.zeros((1, N, N, 4))
    _, Spost, KH = dk.mb_update(model, X0, Sp[None], X0, S)
    F1, _ = team_model.closed_loop_matrices(AGENT.A, model.BK, L)
    IBK = np.kron(np.eye(N), model.BK)
    nu = rng.normal(size=(n, N, M)) * np.sqrt(Rv)  # nu[:, j] = observer j's noise vector
    nubar = np.einsum("jl,njlm->njm", L, nu.reshape(n, N, N, 4)).reshape(n, M)
    omega = rng.normal(size=(n, M))
    _, P_paper = dk.mb_predict(model, X0, Spost, L)
    _, P_exact = dk.mb_predict(model, X0, Spost, L, KH)
    for i in range(N):
        e_prior = rng.normal(size=(n, M)) @ np.linalg.cholesky(Sp[i]).T
        e_post = e_prior @ (np.eye(M) - KH[0, i]).T - nu[:, i] @ KH[0, i].T
        e_next = e_post @ F1.T - nubar @ IBK.T + omega
        emp = e_next.T @ e_next / n
        scale = np.abs(emp).max()
        assert np.abs(P_exact[0, i] - emp).max() < 0.02 * scale
        if i == 1:  # the middle agent has two neighbours: the neglected term is largest
            assert np.abs(P_paper[0, i] - emp).max() > 0.04 * scale


def test_switching_with_a_constant_sequence_is_the_fixed_topology_run():
    x0 = np.random.default_rng(21).normal(scale=20, size=(3, 4, 4))
    xh0 = (x0 + 2.0).reshape(3, -1)
    fixed = simulate_rendezvous(22, _rv(), x0, ring_graph(4), 15, "estimation", x_hat0=xh0, P0=4 * np.eye(4))
    seq = np.broadcast_to(ring_graph(4), (16, 4, 4))
    switched = simulate_rendezvous(22, _rv(), x0, seq, 15, "estimation", x_hat0=xh0, P0=4 * np.eye(4),
                                   switching=True)
    np.testing.assert_array_equal(fixed.states, switched.states)
    np.testing.assert_array_equal(fixed.nees, switched.nees)


@pytest.mark.parametrize("mode", ["estimation", "measurement-filter"])
def test_nees_consistent_on_a_switching_topology(mode):
    """Graph k drives the control of step k and graph k+1 the next measurements: if the two were
    mixed up, the covariance would stop describing the actual errors."""
    N, n_runs, n_steps = 4, 200, 60
    rng = np.random.default_rng(23)
    x0 = np.broadcast_to(rng.normal(scale=30, size=(N, 4)), (n_runs, N, 4)).copy()
    P0 = np.diag([25.0, 25.0, 1.0, 1.0])
    xh0 = (x0 + rng.standard_normal(x0.shape) * np.sqrt(np.diag(P0))).reshape(n_runs, -1)
    graphs = np.array([path_graph(N), ring_graph(N), complete_graph(N)])
    seq = graphs[(np.arange(n_steps + 1) // 4) % 3]  # a new graph every 4 steps
    res = simulate_rendezvous(24, _rv(), x0, seq, n_steps, mode, x_hat0=xh0, P0=P0, switching=True)
    avg = res.nees[1:].mean(axis=1)  # (T, N)
    lo, hi = nees_interval(4 * N, n_runs)
    grand_lo, grand_hi = nees_interval(4 * N, n_runs * avg.shape[0] // 10)
    assert grand_lo < avg.mean() < grand_hi
    assert np.mean((avg > lo) & (avg < hi)) > 0.88


def test_switching_sequence_of_the_wrong_length_is_refused():
    with pytest.raises(ValueError, match="with switching=True, adjacency must be"):
        simulate_rendezvous(0, _rv(), np.zeros((1, 3, 4)), np.broadcast_to(path_graph(3), (4, 3, 3)), 5,
                            "measurement", switching=True)


def test_covariance_shape_errors_say_what_to_do():
    """A full covariance for a reduced model names reduce_covariance; a missing batch axis says to add it."""
    planar = double_integrator(2, 0.1)
    model = team_model.team_filter_model(planar.A, planar.B, rendezvous_gain(0.5, 1.5, 2), np.eye(4), np.eye(4), 3)
    Lap = laplacian(path_graph(3))
    X = np.zeros((1, 3, 3, 4))
    with pytest.raises(ValueError, match=r"reduce_covariance\(Sigma, 2\)"):
        dk.mb_predict(model, X, np.broadcast_to(np.eye(12), (1, 3, 12, 12)).copy(), Lap)
    with pytest.raises(ValueError, match=r"add the leading batch axis \(Sigma\[None\]\)"):
        dk.mb_predict(model, X, np.broadcast_to(np.eye(6), (3, 6, 6)).copy(), Lap)


# ---------------------------------------------------------------------------- checked models, filter objects


def _ring_filter(N, seed, mode="eb"):
    """A TeamFilter on a ring with random initial estimates, and `steps` of measurements for it."""
    model = _model(N)
    rng = np.random.default_rng(seed)
    ring = ring_graph(N)
    team = dk.TeamFilter(model, laplacian(ring), rng.normal(size=(2, N * 4)), np.diag([4.0, 4.0, 1.0, 1.0]),
                         mode=mode)
    meas = [measure(rng, rng.normal(size=(2, N, 4)), ring, 2.0 * np.eye(4)) for _ in range(20)]
    return team, meas


def _run(team, meas):
    for Z, S in meas:
        team.predict()
        team.update(Z, S[0])
    return team.X_hat.copy(), team.Sigma.copy(), team.KH.copy()


@pytest.mark.parametrize("mode", ["eb", "mb"])
def test_independent_filters_in_8_threads_equal_a_serial_run(mode):
    """Filters share no state (no module caches, pools or thread-local buffers): 8 threads, byte-identical."""
    from concurrent.futures import ThreadPoolExecutor

    N = 16  # the row-block path with its in-place updates and work arrays (N M_r = 512 > 384)
    serial = [_run(*_ring_filter(N, seed, mode)) for seed in range(8)]
    jobs = [_ring_filter(N, seed, mode) for seed in range(8)]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(lambda job: _run(*job), jobs))
    for a, b in zip(serial, threaded):
        for x, y in zip(a, b):
            assert x.tobytes() == y.tobytes()


@pytest.mark.parametrize("N", [4, 16])
def test_team_filter_equals_the_plain_array_functions(N):
    """One path: the object's steps and eb_predict/eb_update (checked in full) give the same bytes."""
    team, meas = _ring_filter(N, 3)
    X, Sig = team.X_hat.copy(), team.Sigma.copy()
    for Z, S in meas[:3]:
        X, Sig = dk.eb_predict(team.model, X, Sig, team.laplacian)
        X, Sig, KH = dk.eb_update(team.model, X, Sig, Z, S[0])
        team.predict()
        team.update(Z, S[0])
        assert team.X_hat.tobytes() == X.tobytes() and team.Sigma.tobytes() == Sig.tobytes()
        assert team.KH.tobytes() == KH.tobytes()


def test_measurement_based_filter_with_exact_control_noise_equals_mb_predict():
    N = 5
    model = _model(N)
    rng = np.random.default_rng(8)
    A = path_graph(N)
    team = dk.TeamFilter(model, laplacian(A), rng.normal(size=(1, N * 4)), np.eye(4), mode="mb",
                         exact_control_noise=True)
    Z, S = measure(rng, rng.normal(size=(1, N, 4)), A, 2.0 * np.eye(4))
    team.update(Z, S[0])
    X, Sig = dk.mb_predict(model, team.X_hat, team.Sigma, laplacian(A), team.KH)
    team.predict()
    assert team.X_hat.tobytes() == X.tobytes() and team.Sigma.tobytes() == Sig.tobytes()


def test_model_arrays_are_read_only_and_copied():
    """The hole of the value caches: R_r changed in place after the check. Now refused, and the arrays the
    model was built from are copied (changing them later cannot reach the model)."""
    R = 2.0 * np.eye(4)
    model = team_model.team_filter_model(AGENT.A, AGENT.B, K, np.eye(4), R, 4)
    for name in ("A", "BK", "Q", "R", "A_r", "BK_r", "Q_r", "R_r"):
        arr = getattr(model, name)
        with pytest.raises(ValueError, match="read-only"):
            arr[0, 0] = -5.0
        with pytest.raises(ValueError):
            arr.setflags(write=True)
    R[:] = -1.0  # the caller's array: the model keeps its checked copy
    assert model.R_r[0, 0] == 2.0
    team, meas = _ring_filter(4, 1)
    for Z, S in meas[:5]:
        team.predict()
        team.update(Z, S[0])
    assert np.linalg.eigvalsh(team.Sigma[0]).min() > 0
    kept = team.Sigma
    kept[0, 0, 0] = 0.0  # the state the filter hands out is a copy: writing into it cannot reach the filter
    assert team.Sigma[0, 0, 0] > 0
    with pytest.raises(ValueError, match="read-only"):
        team.view("Sigma")[0, 0, 0] = 0.0  # nor can its view, asked for by name


def test_model_constructor_checks_everything():
    A = AGENT.A
    with pytest.raises(ValueError, match="R must be positive definite"):
        team_model.TeamFilterModel(A, BK, np.eye(4), np.zeros((12, 12)), 3)
    with pytest.raises(ValueError, match="Q must be positive semidefinite"):
        team_model.TeamFilterModel(A, BK, -np.eye(4), np.eye(12), 3)
    with pytest.raises(ValueError, match="Incompatible dimensions of R"):
        team_model.TeamFilterModel(A, BK, np.eye(4), np.eye(8), 3)
    with pytest.raises(ValueError, match="BK contains NaN"):
        team_model.TeamFilterModel(A, np.full((4, 4), np.nan), np.eye(4), np.eye(12), 3)
    with pytest.raises(ValueError, match=r"Q is not of the form Q_r ⊗ I_2"):
        team_model.TeamFilterModel(A, BK, np.diag([1.0, 2.0, 1.0, 1.0]), np.eye(12), 3, kron=2)
    model = team_model.TeamFilterModel(A, BK, np.eye(4), np.eye(12), 3, kron=2)
    assert model.R_r.shape == (6, 6) and model.M_r == 6


def test_initial_covariance_checked_in_full_once_and_named():
    model = _model(3)
    L = laplacian(path_graph(3))
    with pytest.raises(ValueError, match="P0 must be positive semidefinite"):
        dk.TeamFilter(model, L, np.zeros((1, 12)), np.diag([1.0, 1.0, -1.0, -1.0]))
    bad = np.eye(18)[None]
    bad[0, 0, 0] = -1.0
    with pytest.raises(ValueError, match="Sigma0 must be positive semidefinite"):
        dk.TeamFilter(model, L, np.zeros((1, 12)), Sigma0=bad)
    with pytest.raises(ValueError, match="exactly one of P0"):
        dk.TeamFilter(model, L, np.zeros((1, 12)))
    with pytest.raises(ValueError, match="x_hat0 contains NaN"):
        dk.TeamFilter(model, L, np.full((1, 12), np.nan), np.eye(4))
    with pytest.raises(ValueError, match="laplacian looks like an adjacency"):
        dk.TeamFilter(model, path_graph(3), np.zeros((1, 12)), np.eye(4))


def test_a_step_checks_shapes_and_names_a_non_finite_input():
    team, meas = _ring_filter(4, 2)
    Z, S = meas[0]
    team.predict()
    with pytest.raises(ValueError, match="Incompatible dimensions of Z"):
        team.update(Z[:, :3], S[0])
    with pytest.raises(ValueError, match="mask must include every agent itself"):
        team.update(Z, np.zeros((4, 4), bool))
    bad = Z.copy()
    bad[0, 1, 1, 0] = np.nan
    with pytest.raises(ValueError, match="Z contains NaN"):
        team.update(bad, S[0])
    with pytest.raises(ValueError, match="laplacian looks like an adjacency"):
        team.predict(ring_graph(4))


def test_switching_laplacian_in_predict_equals_a_filter_built_on_it():
    team, meas = _ring_filter(4, 4)
    other, _ = _ring_filter(4, 4)
    L2 = laplacian(complete_graph(4))
    other.predict(L2)
    fresh = dk.TeamFilter(team.model, L2, team.X_hat, Sigma0=team.Sigma)
    fresh.predict()
    assert other.Sigma.tobytes() == fresh.Sigma.tobytes() and other.X_hat.tobytes() == fresh.X_hat.tobytes()
    np.testing.assert_array_equal(other.laplacian, L2)


def test_per_run_masks_give_every_run_its_own_covariance():
    """Dropped links: a mask per run splits the shared covariance; each run then equals its own filter."""
    team, meas = _ring_filter(4, 5)
    Z, S = meas[0]
    masks = np.stack([S[0], np.eye(4, dtype=bool) | S[0]])
    masks[1, 0, 1] = masks[1, 1, 0] = False
    single, _ = _ring_filter(4, 5)
    team.predict()
    team.update(Z, masks)
    single.predict()
    single.update(Z, masks[1])
    assert team.Sigma.shape[0] == 2
    assert team.Sigma[1].tobytes() == single.Sigma[0].tobytes()


def test_memory_held_after_a_run_is_small():
    """No module-level memory: after 20 steps at N = 26 (augmented covariance 14.6 MB) the package holds
    under 10 MB beyond the caller's results: the filter's work arrays while it lives, nothing once the
    caller drops it; the plain functions keep nothing either."""
    import gc
    import tracemalloc

    _run(*_ring_filter(16, 0))  # first use of the row-block path imports scipy.sparse and BLAS: not counted
    N = 26
    model = _model(N)
    rng = np.random.default_rng(9)
    ring = ring_graph(N)
    meas = [measure(rng, rng.normal(size=(1, N, 4)), ring, 2.0 * np.eye(4)) for _ in range(20)]
    gc.collect()
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        team = dk.TeamFilter(model, laplacian(ring), rng.normal(size=(1, N * 4)), np.eye(4))
        for Z, S in meas:
            team.predict()
            team.update(Z, S[0])
        gc.collect()
        alive = tracemalloc.get_traced_memory()[0] - base
        assert alive - team.Sigma.nbytes - team.X_hat.nbytes - team.KH.nbytes < 10e6  # the work arrays
        X, Sig = team.X_hat.copy(), team.Sigma.copy()
        del team
        for Z, S in meas[:2]:  # the plain functions too (slow: an eigenvalue check of Sigma per call)
            X, Sig, _ = dk.eb_update(model, *dk.eb_predict(model, X, Sig, laplacian(ring)), Z, S[0])
        gc.collect()
        held = tracemalloc.get_traced_memory()[0] - base - X.nbytes - Sig.nbytes
    finally:
        tracemalloc.stop()
    assert Sig.nbytes > 14e6
    assert held < 10e6


def test_no_module_level_memory_or_private_scipy():
    """Regression guard for the removed machinery (value caches, reference-count pool, thread-local pools)."""
    import inspect

    import mascore.rendezvous as rv

    modules = (dk, rv, team_model, centralized_team_filter, team_observability, _team_kernels)
    for module in modules:
        text = inspect.getsource(module)
        for banned in ("_sparsetools", "getrefcount", "threading", "_ValueMemo", "_RecentArrays", "cached_"):
            assert banned not in text, (module.__name__, banned)
    for module in modules[:1] + modules[2:]:
        assert not [k for k, v in vars(module).items() if isinstance(v, dict) and not k.startswith("__")]


def test_rendezvous_model_keeps_read_only_copies():
    Q = np.eye(4)
    model = _rv(Q=Q)
    Q[0, 0] = -1.0  # the caller's array, changed after the check
    assert model.Q[0, 0] == 1.0
    with pytest.raises(ValueError, match="read-only"):
        model.R[0, 0] = -1.0


def test_an_initial_covariance_of_any_memory_layout_gives_the_same_run():
    """The row-block steps work in place on a C-ordered copy: a Fortran-ordered Sigma0 changes nothing."""
    team, meas = _ring_filter(16, 6)
    runs = []
    for Sig in (team.Sigma.copy(), np.asfortranarray(team.Sigma)):
        f = dk.TeamFilter(team.model, team.laplacian, team.X_hat, Sigma0=Sig)
        runs.append(_run(f, meas[:3]))
    for x, y in zip(*runs):
        assert x.tobytes() == y.tobytes()


def test_pickled_and_copied_models_stay_checked_and_read_only():
    import copy
    import pickle

    for model in (_model(3), _rv()):
        for clone in (pickle.loads(pickle.dumps(model)), copy.deepcopy(model), copy.copy(model)):
            assert type(clone) is type(model) and clone is not model
            for name in ("A", "Q", "R"):
                assert not getattr(clone, name).flags.writeable
                np.testing.assert_array_equal(getattr(clone, name), getattr(model, name))
