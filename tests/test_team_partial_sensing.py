"""Song et al.'s whole-team filters with any linear sensing ``z_ij = C_j x_j + nu_ij`` (issue 31, item 2).

Checked against independent dense implementations written here from the equations: the
estimation-based filter against eqs. (14), (29)-(34), (16)-(20) with explicit ``F_1``, ``F_2``,
``H_i = E_i blockdiag(C_j)`` and ``G_i``; the centralized team filter against a textbook Kalman
filter on the stacked measurements of all observers.
"""

import numpy as np
import pytest

from mascore import agents, graphs, rendezvous, sensing, team_model, team_observability
from mascore import centralized_team_filter as ctf
from mascore import distributed_kf as dkf
from mascore.team_model import closed_loop_matrices, expand_covariance

DT, N = 0.1, 4
AGENT = agents.double_integrator(2, DT)  # planar: [px, py, vx, vy]
K = rendezvous.rendezvous_gain(0.5, 1.5, 2)
Q = np.diag([0.01, 0.01, 0.04, 0.04])
POSITIONS = np.hstack([np.eye(2), np.zeros((2, 2))])  # [I 0] = [1 0] ⊗ I_2
VELOCITIES = np.hstack([np.zeros((2, 2)), np.eye(2)])


def _model(C=None, R=None, reduce=True, n=N):
    R = 0.3 * np.eye(2) if R is None else R
    return team_model.team_filter_model(AGENT.A, AGENT.B, K, Q, R, n_agents=n, reduce=reduce, C=C)


def _team_C(C, n=N):
    C = np.asarray(C, float)
    return np.broadcast_to(C, (n, *C.shape[-2:])) if C.ndim == 2 else C


def _reference_eb(adjacency, C, R_team, P0, x0, Zs):
    """Eqs. (14), (29)-(34), (16)-(20) with dense matrices over the full augmented state (independent)."""
    n = adjacency.shape[0]
    m = AGENT.A.shape[0]
    M = n * m
    Cs = _team_C(C, n)
    p = Cs.shape[1]
    Hc = np.zeros((n * p, M))
    for j in range(n):
        Hc[j * p:(j + 1) * p, j * m:(j + 1) * m] = Cs[j]
    F1, F2 = closed_loop_matrices(AGENT.A, AGENT.B @ K, graphs.laplacian(adjacency))
    Phi = np.kron(np.eye(n), F1) + np.kron(np.ones((n, 1)), F2)
    Qt = np.kron(np.ones((n, n)), np.kron(np.eye(n), Q))
    Sig = np.kron(np.ones((n, n)), np.kron(np.eye(n), P0))
    X = np.tile(x0.ravel(), (n, 1))  # row i: agent i's estimate of the team
    S = sensing.sensing_mask(adjacency)
    for Z in Zs:
        Sig = Phi @ Sig @ Phi.T + Qt  # eqs. (32), (34)
        X = X @ F1.T  # eq. (14)
        Psi = np.zeros((n * M, n * M))
        GRG = np.zeros((n * M, n * M))
        for i in range(n):
            rows = np.flatnonzero(np.repeat(S[i], p))
            H, Ri = Hc[rows], R_team[np.ix_(rows, rows)]
            P = Sig[i * M:(i + 1) * M, i * M:(i + 1) * M]
            G = P @ H.T @ np.linalg.inv(H @ P @ H.T + Ri)  # eqs. (17), (19)
            X[i] = X[i] + G @ (Z[i][S[i]].ravel() - H @ X[i])  # eqs. (16), (18)
            Psi[i * M:(i + 1) * M, i * M:(i + 1) * M] = np.eye(M) - G @ H
            GRG[i * M:(i + 1) * M, i * M:(i + 1) * M] = G @ Ri @ G.T
        Sig = Psi @ Sig @ Psi.T + GRG  # eqs. (20), (33)
    return X, Sig


def _run_eb(model, adjacency, P0, x0, Zs, S):
    filt = dkf.TeamFilter(model, graphs.laplacian(adjacency), x0.reshape(1, -1), P0=P0)
    for Z in Zs:
        filt.predict()
        filt.update(Z[None], S)
    return filt


def _measurements(adjacency, C, R, steps, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((adjacency.shape[0], 4))
    Zs = []
    for _ in range(steps):
        x = x @ AGENT.A.T + 0.1 * rng.standard_normal(x.shape)
        Z, S = sensing.measure(rng, x, adjacency, R, C=C)
        Zs.append(Z)
    return x, Zs, S


@pytest.mark.parametrize("reduce", [True, False])
def test_positions_only_equals_dense_reference(reduce):
    """Positions only on a ring: the structured filter equals eqs. (29)-(34) written out densely, to 1e-10."""
    adjacency = graphs.ring_graph(N)
    R = 0.3 * np.eye(2)
    model = _model(POSITIONS, R, reduce=reduce)
    assert model.kron == (2 if reduce else 1) and model.p == 2
    _, Zs, S = _measurements(adjacency, POSITIONS, R, 6)
    P0 = np.eye(4)
    x0 = np.zeros((N, 4))
    filt = _run_eb(model, adjacency, P0, x0, Zs, S)
    X_ref, Sig_ref = _reference_eb(adjacency, POSITIONS, np.kron(np.eye(N), R), P0, x0, Zs)
    np.testing.assert_allclose(filt.X_hat[0].reshape(N, -1), X_ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(expand_covariance(filt.Sigma[0], model.kron), Sig_ref, rtol=0,
                               atol=1e-10 * np.abs(Sig_ref).max())
    eig = np.linalg.eigvalsh(filt.Sigma[0])
    assert eig.min() > 0 and np.array_equal(filt.Sigma[0], filt.Sigma[0].T)  # SPD, exactly symmetric


@pytest.mark.parametrize("graph", [graphs.ring_graph(14), graphs.path_graph(15)])
def test_positions_only_row_block_path_equals_dense_reference(graph):
    """A team large enough for the row-block update (N M_r > 384): the same numbers as the dense equations."""
    from mascore import _team_kernels

    n = graph.shape[0]
    R = 0.3 * np.eye(2)
    model = _model(POSITIONS, R, n=n)
    assert n * model.M_r > _team_kernels.DENSE_MAX
    _, Zs, S = _measurements(graph, POSITIONS, R, 3, seed=7)
    x0 = np.zeros((n, 4))
    filt = _run_eb(model, graph, np.eye(4), x0, Zs, S)
    X_ref, Sig_ref = _reference_eb(graph, POSITIONS, np.kron(np.eye(n), R), np.eye(4), x0, Zs)
    np.testing.assert_allclose(filt.X_hat[0].reshape(n, -1), X_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(expand_covariance(filt.Sigma[0], model.kron), Sig_ref, rtol=0,
                               atol=1e-10 * np.abs(Sig_ref).max())


def test_per_agent_outputs_fall_back_to_the_full_form():
    """An output matrix per agent that is not C_r ⊗ I_2 (x axis of one, y axis of others): kron 1, still exact."""
    C = np.stack([np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])] + [np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])] * (N - 1))
    adjacency = graphs.complete_graph(N)
    R = np.diag([0.3, 0.5])
    model = _model(C, R)
    assert model.kron == 1 and model.C.shape == (N, 2, 4)
    _, Zs, S = _measurements(adjacency, C, R, 5, seed=3)
    x0 = np.ones((N, 4))
    filt = _run_eb(model, adjacency, 2 * np.eye(4), x0, Zs, S)
    X_ref, Sig_ref = _reference_eb(adjacency, C, np.kron(np.eye(N), R), 2 * np.eye(4), x0, Zs)
    np.testing.assert_allclose(filt.X_hat[0].reshape(N, -1), X_ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(filt.Sigma[0], Sig_ref, rtol=0, atol=1e-10 * np.abs(Sig_ref).max())


def test_identity_output_matrix_is_the_full_state_path_bit_for_bit():
    """C = I builds the very model of full-state sensing; the general output path agrees with it to rounding."""
    adjacency = graphs.ring_graph(N)
    R = 0.3 * np.eye(4)
    old, new = _model(None, R), _model(np.eye(4), R)
    assert new.C is None and new.full_state and new == old
    rng = np.random.default_rng(1)
    x = rng.standard_normal((2, N, 4))
    runs = []
    for mode in ("eb", "mb"):
        for model in (old, new):
            filt = dkf.TeamFilter(model, graphs.laplacian(adjacency), x.reshape(2, -1), P0=np.eye(4), mode=mode)
            r = np.random.default_rng(2)
            for _ in range(4):
                filt.predict()
                Z, S = sensing.measure(r, x, adjacency, R)
                filt.update(Z, S[0])
            runs.append((filt.X_hat, filt.Sigma))
    for a, b in (runs[0], runs[1]), (runs[2], runs[3]):
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    # the general output-matrix update with H = blockdiag(I): the same numbers to rounding
    general = team_model.TeamFilterModel(A=old.A, BK=old.BK, Q=old.Q, R=old.R, n_agents=N, kron=old.kron,
                                         C=np.broadcast_to(np.eye(4), (N, 4, 4)))
    assert not general.full_state
    filt_g = dkf.TeamFilter(general, graphs.laplacian(adjacency), x.reshape(2, -1), P0=np.eye(4))
    r = np.random.default_rng(2)
    for _ in range(4):
        filt_g.predict()
        Z, S = sensing.measure(r, x, adjacency, R)
        filt_g.update(Z, S[0])
    np.testing.assert_allclose(filt_g.X_hat, runs[0][0], rtol=0, atol=1e-10)
    np.testing.assert_allclose(filt_g.Sigma, runs[0][1], rtol=0, atol=1e-10 * np.abs(runs[0][1]).max())


def _textbook_centralized(adjacency, C, R_team, P0, x0, U, Zs):
    """A textbook Kalman filter on the team state with every observer's outputs stacked (independent)."""
    n, m = adjacency.shape[0], 4
    Cs = _team_C(C, n)
    p = Cs.shape[1]
    Hc = np.zeros((n * p, n * m))
    for j in range(n):
        Hc[j * p:(j + 1) * p, j * m:(j + 1) * m] = Cs[j]
    S = sensing.sensing_mask(adjacency)
    rows = [np.flatnonzero(np.repeat(S[i], p)) for i in range(n)]
    H = np.vstack([Hc[r] for r in rows])
    Rs = np.zeros((H.shape[0], H.shape[0]))
    o = 0
    for r in rows:
        Rs[o:o + r.size, o:o + r.size] = R_team[np.ix_(r, r)]
        o += r.size
    F, G = np.kron(np.eye(n), AGENT.A), np.kron(np.eye(n), AGENT.B)
    x, P = x0.ravel(), np.kron(np.eye(n), P0)
    for Z in Zs:
        x = F @ x + G @ U.ravel()
        P = F @ P @ F.T + np.kron(np.eye(n), Q)
        z = np.concatenate([Z[i][S[i]].ravel() for i in range(n)])
        Kg = P @ H.T @ np.linalg.inv(H @ P @ H.T + Rs)
        x = x + Kg @ (z - H @ x)
        P = (np.eye(n * m) - Kg @ H) @ P
    return x, P


@pytest.mark.parametrize("correlated", [False, True])
def test_centralized_with_outputs_equals_textbook_kf(correlated):
    """The centralized team filter (separable, and with noise correlated across agents) equals a textbook KF."""
    adjacency = graphs.ring_graph(N)
    if correlated:
        rng = np.random.default_rng(5)
        Wr = rng.standard_normal((N, N))
        R_team = np.kron(Wr @ Wr.T + N * np.eye(N), np.eye(2)) * 0.1  # (R_r ⊗ I_2): kron 2 survives
    else:
        R_team = np.kron(np.eye(N), 0.3 * np.eye(2))
    model = _model(POSITIONS, R_team)
    central = ctf.CentralizedTeamFilter(model, AGENT.B, np.zeros((1, N * 4)), np.eye(4))
    assert central.separable is not correlated and model.kron == 2
    _, Zs, S = _measurements(adjacency, POSITIONS, R_team, 5, seed=4)
    U = np.full((N, 2), 0.2)
    for Z in Zs:
        central.predict(U[None])
        central.update(Z[None], S)
    x_ref, P_ref = _textbook_centralized(adjacency, POSITIONS, R_team, np.eye(4), np.zeros((N, 4)), U, Zs)
    np.testing.assert_allclose(central.x_hat[0].ravel(), x_ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(expand_covariance(central.P[0], model.kron), P_ref, rtol=0, atol=1e-10)
    x2, P2 = ctf.centralized_update(model, np.zeros((1, N, 4)), np.eye(8)[None], Zs[0][None], S)  # plain function
    assert x2.shape == (1, N, 4) and np.linalg.eigvalsh(P2[0]).min() > 0


def _pbh_observable(adjacency, C):
    """Agents for which [F_1 - mu I; H_i] has full column rank at every eigenvalue mu of F_1 (dense, independent)."""
    n = adjacency.shape[0]
    Cs = _team_C(C, n)
    F1, _ = closed_loop_matrices(AGENT.A, AGENT.B @ K, graphs.laplacian(adjacency))
    M = F1.shape[0]
    mus = np.concatenate([np.linalg.eigvals(F1), [1.0]])  # 1: the Jordan block of the team's common motion
    S = sensing.sensing_mask(adjacency)
    out = []
    for i in range(n):
        H = np.zeros((0, M))
        for j in np.flatnonzero(S[i]):
            row = np.zeros((Cs.shape[1], M))
            row[:, j * 4:(j + 1) * 4] = Cs[j]
            H = np.vstack([H, row])
        smallest = [np.linalg.svd(np.vstack([F1 - mu * np.eye(M), H]), compute_uv=False)[-1] for mu in mus]
        out.append(min(smallest) > 1e-5)
    return np.array(out)


def test_observability_with_outputs():
    """Positions only: every agent of a ring observes the team; velocities only: no one (the common position)."""
    import networkx as nx

    A, BK = AGENT.A, AGENT.B @ K
    ring = graphs.ring_graph(5)
    assert team_observability.observable_agents(A, BK, ring, C=POSITIONS).all()
    assert not team_observability.observable_agents(A, BK, ring, C=VELOCITIES).any()
    # the Laplacian-eigenvector test equals a dense PBH test, with one C for all and with one C per agent
    geometric = nx.to_numpy_array(nx.random_geometric_graph(10, 0.45, seed=3), nodelist=range(10))
    mixed = np.stack([POSITIONS, VELOCITIES, POSITIONS, np.array([[1.0, 0, 0, 0], [0, 0, 0, 1.0]]), POSITIONS])
    for adjacency, C in ((ring, VELOCITIES), (graphs.star_graph(5), POSITIONS), (graphs.path_graph(5), POSITIONS),
                         (ring, mixed), (graphs.path_graph(5), mixed), (geometric, POSITIONS),
                         (geometric, np.stack([POSITIONS * (1.0 + 0.1 * j) for j in range(10)]))):
        got = team_observability.observable_agents(A, BK, adjacency, C=C)
        assert np.array_equal(got, _pbh_observable(adjacency, C)), (adjacency, C)
    assert not team_observability.observable_agents(A, BK, graphs.star_graph(5), C=POSITIONS).all()  # twin leaves
    # without coupling (K = 0, every block alike: the dense PBH fallback) an agent sees only whom it senses
    no_coupling = team_observability.observable_agents(A, np.zeros((4, 4)), graphs.path_graph(3), C=POSITIONS)
    assert no_coupling.tolist() == [False, True, False]


def test_unobservable_configuration_is_refused_by_name():
    model = _model(VELOCITIES, 0.3 * np.eye(2))
    with pytest.raises(ValueError, match=r"system \(43\) \(F_1, H_i\) is not observable .* output matrix C"):
        dkf.TeamFilter(model, graphs.laplacian(graphs.ring_graph(N)), np.zeros((1, N * 4)), P0=np.eye(4))


def test_measurement_based_loop_refuses_outputs_and_names_the_methods_that_take_them():
    model = _model(POSITIONS)
    with pytest.raises(ValueError, match=r"mode='mb' \(song-mb\) needs full-state.*mode='eb'.*CentralizedTeamFilter"):
        dkf.TeamFilter(model, graphs.laplacian(graphs.ring_graph(N)), np.zeros((1, N * 4)), P0=np.eye(4), mode="mb")


def test_bad_output_matrix_blames_C_and_R_says_p():
    with pytest.raises(ValueError, match=r"Incompatible dimensions of C; expected \(p, 4\)"):
        _model(np.eye(2, 3))
    with pytest.raises(ValueError, match=r"Incompatible dimensions of C"):
        _model(np.ones((N + 1, 2, 4)))
    with pytest.raises(ValueError, match=r"C contains NaN"):
        _model(np.full((2, 4), np.nan))
    with pytest.raises(ValueError, match=r"R.*p = 2: the rows of the output matrix C"):
        _model(POSITIONS, np.eye(4))
    with pytest.raises(ValueError, match=r"team_filter_model\(\.\.\., C=C\)"):  # partial R without C: says how
        _model(None, np.eye(2))
    filt = dkf.TeamFilter(_model(POSITIONS), graphs.laplacian(graphs.ring_graph(N)), np.zeros((1, N * 4)),
                          P0=np.eye(4))
    with pytest.raises(ValueError, match=r"Incompatible dimensions of Z; expected \(1, 4, 4, 2\)"):
        filt.update(np.zeros((1, N, N, 4)), graphs.ring_graph(N) + np.eye(N) > 0)


def test_measure_with_outputs():
    x = np.arange(N * 4, dtype=float).reshape(N, 4)
    Z, S = sensing.measure(0, x, graphs.ring_graph(N), 1e-30 * np.eye(2), C=POSITIONS)
    assert Z.shape == (N, N, 2)
    np.testing.assert_allclose(Z[S], np.broadcast_to(x[:, :2], (N, N, 2))[S], atol=1e-9)


def test_without_control_coupling_each_agent_is_a_textbook_kalman_filter():
    """K = 0 (F_2 = 0): agent i's filter is a plain Kalman filter of the team with its own outputs (complete graph)."""
    n = 3
    adjacency = graphs.complete_graph(n)
    R = np.diag([0.2, 0.4])
    model = team_model.team_filter_model(AGENT.A, AGENT.B, np.zeros((2, 4)), Q, R, n_agents=n, C=POSITIONS)
    rng = np.random.default_rng(11)
    x = rng.standard_normal((n, 4))
    filt = dkf.TeamFilter(model, graphs.laplacian(adjacency), np.zeros((1, n * 4)), P0=np.eye(4))
    F, Qt = np.kron(np.eye(n), AGENT.A), np.kron(np.eye(n), Q)
    H, Rt = np.kron(np.eye(n), POSITIONS), np.kron(np.eye(n), R)
    xs, P = np.zeros(n * 4), np.eye(n * 4)  # agent 0's block of Σ[0] = 1 1^T ⊗ (I_N ⊗ P0)
    for _ in range(8):
        x = x @ AGENT.A.T + 0.1 * rng.standard_normal(x.shape)
        Z, S = sensing.measure(rng, x, adjacency, R, C=POSITIONS)
        filt.predict()
        filt.update(Z[None], S)
        xs, P = F @ xs, F @ P @ F.T + Qt
        Kg = P @ H.T @ np.linalg.inv(H @ P @ H.T + Rt)
        xs, P = xs + Kg @ (Z[0].ravel() - H @ xs), (np.eye(n * 4) - Kg @ H) @ P
    np.testing.assert_allclose(filt.X_hat[0, 0].ravel(), xs, rtol=0, atol=1e-10)
    np.testing.assert_allclose(expand_covariance(filt.agent_covariances()[0, 0], model.kron), P, rtol=0, atol=1e-10)


def test_model_with_outputs_is_frozen_and_pickles():
    import pickle

    model = _model(POSITIONS)
    assert not model.C.flags.writeable and not model.C_r.flags.writeable
    with pytest.raises(AttributeError):
        model.C = None
    again = pickle.loads(pickle.dumps(model))
    assert again == model and np.array_equal(again.C_r, model.C_r) and again.kron == 2


def test_simulate_rendezvous_with_outputs_is_the_written_out_loop():
    """simulate_rendezvous with positions only (mode "estimation", central=True) == the loop of the public calls."""
    from mascore import centralized_team_filter as ctf_

    R = 0.04 * np.eye(2)
    model = rendezvous.RendezvousModel.from_agent(AGENT, K, Q, R, C=POSITIONS)
    x0 = np.random.default_rng(3).normal(scale=3.0, size=(N, 4))
    ring = graphs.ring_graph(N)
    run = rendezvous.simulate_rendezvous(9, model, x0, ring, 30, "estimation", x_hat0=x0.ravel(), P0=np.eye(4),
                                         central=True, return_estimates=True)
    proc_rng, meas_rng = np.random.default_rng(9).spawn(2)
    L = graphs.laplacian(ring)
    fm = team_model.team_filter_model(AGENT.A, AGENT.B, K, Q, R, N, C=POSITIONS)
    team = dkf.TeamFilter(fm, L, x0.reshape(1, -1), np.eye(4), mode="eb")
    central = ctf_.CentralizedTeamFilter(fm, AGENT.B, x0.reshape(1, -1), np.eye(4))
    x = x0[None]
    sensing.measure(meas_rng, x, ring, R, C=POSITIONS)  # step 0
    for _ in range(30):
        U = rendezvous.consensus_control(team.X_hat, L, K)
        x = rendezvous.propagate_team(proc_rng, x, U, AGENT.A, AGENT.B, Q)
        team.predict()
        central.predict(U)
        Z, S = sensing.measure(meas_rng, x, ring, R, C=POSITIONS)
        team.update(Z, S)
        central.update(Z, S)
    assert np.array_equal(run.states[-1], x[0]) and np.array_equal(run.estimates[-1], team.X_hat[0])
    assert run.model.C is not None and run.nees.shape == (31, N)
    assert np.mean(run.central_pos_error[10:]) < np.mean(run.pos_error[10:])  # the centre sees every measurement
    with pytest.raises(ValueError, match=r"mode 'measurement' steers with the raw measurements .*'estimation'"):
        rendezvous.simulate_rendezvous(0, model, x0, ring, 5, "measurement")
    with pytest.raises(ValueError, match=r"Incompatible dimensions of C"):
        rendezvous.RendezvousModel.from_agent(AGENT, K, Q, R, C=np.eye(2, 3))
    with pytest.raises(ValueError, match=r"p = 2: the rows of the output matrix C"):
        rendezvous.RendezvousModel.from_agent(AGENT, K, Q, np.eye(3) * 0.04, C=POSITIONS)
    full = rendezvous.RendezvousModel.from_agent(AGENT, K, Q, 0.04 * np.eye(4), C=np.eye(4))
    assert full.C is None  # the identity: full states
