"""Tests of mascore.distributed_ekf: per-agent EKFs of Song et al. (2023), eqs. (35)-(40)."""

import numpy as np
import pytest

from mascore import distributed_ekf as dekf
from mascore import flocking, kalman, sensing
from mascore.flocking import FlockingGains

GAINS = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)


def _spd(rng, M, scale=1.0):
    G = rng.standard_normal((M, M))
    return scale * (G @ G.T / M + np.eye(M))


def _team(rng, shape, N):
    return np.concatenate([100 * rng.standard_normal((*shape, N, 2)), 2 * rng.standard_normal((*shape, N, 2))], -1)


def test_masked_update_equals_update_with_selection_matrix():
    """Fixed-size masked update == mascore.kalman.update with the paper's H_i (eq. (3)) and z_i."""
    rng = np.random.default_rng(0)
    N, m = 5, 4
    M = N * m
    A = np.array([[0, 1, 0, 0, 1], [1, 0, 1, 0, 0], [0, 1, 0, 1, 0], [0, 0, 1, 0, 0], [1, 0, 0, 0, 0]], float)
    X = _team(rng, (), N)
    Z, S = sensing.measure(rng, X, A, 2.0 * np.eye(m))
    R = sensing.team_noise_covariance(2.0 * np.eye(m), N, m)
    X_pred = _team(rng, (N,), N)  # one prior per agent
    Sigma = np.stack([_spd(rng, M, 5.0) for _ in range(N)])
    X_post, Sigma_post = dekf.masked_update(X_pred, Sigma, Z, S, R, agent=np.arange(N))
    for i, H in enumerate(sensing.selection_matrices(A, m)):
        z_i = sensing.stacked_measurement(Z, S, i)
        x_ref, P_ref = kalman.update(X_pred[i].ravel(), Sigma[i], z_i, H, H @ R @ H.T)
        np.testing.assert_allclose(X_post[i].ravel(), x_ref, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(Sigma_post[i], P_ref, rtol=1e-9, atol=1e-9)


def test_masked_update_with_correlated_R_equals_selection_form():
    """The equivalence also holds for a full (non-block-diagonal) R of nu_i."""
    rng = np.random.default_rng(1)
    N, m = 3, 4
    M = N * m
    R = _spd(rng, M)
    observed = np.array([True, False, True])
    H = sensing.selection_matrix(np.flatnonzero(observed), N, m)
    x, P, z = rng.standard_normal((N, m)), _spd(rng, M, 3.0), rng.standard_normal((N, m))
    X_post, P_post = dekf.masked_update(x, P, z, observed, R, agent=0)
    x_ref, P_ref = kalman.update(x.ravel(), P, H @ z.ravel(), H, H @ R @ H.T)
    np.testing.assert_allclose(X_post.ravel(), x_ref, atol=1e-10)
    np.testing.assert_allclose(P_post, P_ref, atol=1e-10)


def test_unobserved_rows_of_z_are_ignored_and_unobserved_everything_is_identity():
    rng = np.random.default_rng(2)
    N, m = 4, 4
    M = N * m
    x, P, z = rng.standard_normal((N, m)), _spd(rng, M), rng.standard_normal((N, m))
    observed = np.array([True, True, False, False])
    z2 = z.copy()
    z2[2:] = 1e6
    a = dekf.masked_update(x, P, z, observed, np.eye(M), agent=1)
    b = dekf.masked_update(x, P, z2, observed, np.eye(M), agent=1)
    np.testing.assert_allclose(a[0], b[0])
    np.testing.assert_allclose(a[1], b[1])
    with pytest.raises(ValueError, match="observed must hold the agent itself"):
        dekf.masked_update(x, P, z, np.zeros(N, bool), np.eye(M), agent=0)


def test_masked_update_refuses_a_mask_without_the_agent_itself():
    """Regression: N_i bar always contains i; a mask that leaves the agent out is refused (keyword `agent`)."""
    rng = np.random.default_rng(4)
    N, m = 3, 4
    M = N * m
    x, P, z = rng.standard_normal((N, m)), _spd(rng, M), rng.standard_normal((N, m))
    observed = np.array([False, True, True])
    with pytest.raises(ValueError, match="observed must hold the agent itself"):
        dekf.masked_update(x, P, z, observed, np.eye(M), agent=0)
    dekf.masked_update(x, P, z, observed, np.eye(M), agent=1)
    with pytest.raises(TypeError, match="agent"):
        dekf.masked_update(x, P, z, observed, np.eye(M))
    with pytest.raises(ValueError, match="agent must index"):
        dekf.masked_update(x, P, z, observed, np.eye(M), agent=3)
    S = np.ones((N, N), bool)
    S[2, 2] = False  # one filter per agent: agent 2's row leaves agent 2 out
    with pytest.raises(ValueError, match=r"batch index \(2,\)"):
        dekf.masked_update(np.broadcast_to(x, (N, N, m)), np.broadcast_to(P, (N, M, M)), z, S, np.eye(M),
                           agent=np.arange(N))


def test_batched_update_equals_loop():
    """Runs x agents in one call == one call per filter."""
    rng = np.random.default_rng(3)
    N, m = 3, 4
    M = N * m
    x = rng.standard_normal((2, N, N, m))
    P = np.stack([[_spd(rng, M) for _ in range(N)] for _ in range(2)])
    z = rng.standard_normal((2, N, N, m))
    obs = rng.random((2, N, N)) < 0.5
    obs[:, np.arange(N), np.arange(N)] = True  # row i is agent i's closed neighbourhood
    X_b, P_b = dekf.masked_update(x, P, z, obs, np.eye(M), agent=np.arange(N))
    for r in range(2):
        for i in range(N):
            X_l, P_l = dekf.masked_update(x[r, i], P[r, i], z[r, i], obs[r, i], np.eye(M), agent=i)
            np.testing.assert_allclose(X_b[r, i], X_l, atol=1e-12)
            np.testing.assert_allclose(P_b[r, i], P_l, atol=1e-12)


def test_predict_is_f_prime_and_jacobian_propagation():
    """Eqs. (38), (40): mean through f', covariance F Sigma F^T + Q with the analytic Jacobian."""
    rng = np.random.default_rng(4)
    N = 4
    M = 4 * N
    X = _team(rng, (3,), N)
    Sigma = np.stack([_spd(rng, M) for _ in range(3)])
    Q = np.kron(np.eye(N), np.diag([1.0, 1.0, 0.5, 0.5]))
    X_pred, S_pred = dekf.ekf_predict(X, Sigma, 0.1, GAINS, Q)
    np.testing.assert_allclose(X_pred, flocking.closed_loop_step(X, 0.1, GAINS))
    F = flocking.closed_loop_jacobian(X, 0.1, GAINS)
    for b in range(3):
        x_ref, P_ref = kalman.predict(np.zeros(M), Sigma[b], F[b], Q)
        np.testing.assert_allclose(S_pred[b], P_ref, rtol=1e-12, atol=1e-12)


def test_ekf_consistent_on_model_matched_system():
    """NEES check: when the truth really follows f' (eq. (40)), the EKF of one agent is consistent.

    Agent 1 of 3 observes itself and agent 2 only; 300 runs, 40 steps; the run-averaged NEES of the
    12-dimensional team state lies in its 99 % chi-square interval (Bar-Shalom et al. 2001, Sec. 5.4).
    """
    rng = np.random.default_rng(5)
    N, m, runs, dt = 3, 4, 300, 0.1
    M = N * m
    Q_agent = np.diag([0.5, 0.5, 0.2, 0.2])
    Q = np.kron(np.eye(N), Q_agent)
    R = np.kron(np.eye(N), np.eye(m))
    base = np.array([[0.0, 0, 1, 0], [100.0, 0, 1, 0], [50.0, 90, 1, 0]])
    Sigma0 = np.kron(np.eye(N), np.diag([25.0, 25, 1, 1]))
    X = base + rng.multivariate_normal(np.zeros(M), Sigma0, runs).reshape(runs, N, m)
    X_hat = np.broadcast_to(base, (runs, N, m)).copy()
    Sigma = np.broadcast_to(Sigma0, (runs, M, M)).copy()
    observed = np.array([True, True, False])
    for _ in range(40):
        z = X + rng.standard_normal((runs, N, m))
        X_hat, Sigma = dekf.masked_update(X_hat, Sigma, z, observed, R, agent=1)
        X = flocking.closed_loop_step(X, dt, GAINS) + rng.multivariate_normal(np.zeros(M), Q, runs).reshape(runs, N, m)
        X_hat, Sigma = dekf.ekf_predict(X_hat, Sigma, dt, GAINS, Q)
    avg = kalman.nees((X - X_hat).reshape(runs, M), Sigma).mean()
    low, high = kalman.nees_interval(M, runs, confidence=0.99)
    assert low <= avg <= high


def test_simulation_shapes_determinism_and_observer_records():
    rng = np.random.default_rng(6)
    N = 4
    X0 = np.concatenate([rng.uniform(0, 200, (2, N, 2)), rng.uniform(-2, 2, (2, N, 2))], -1)
    Sigma0 = np.kron(np.eye(N), np.diag([4.0, 4, 1, 1]))
    X_hat0 = X0[:, None] + rng.standard_normal((2, N, N, 4))
    kw = dict(n_steps=15, dt=0.1, gains=GAINS, Q=np.eye(4), R=np.eye(4), sensing_range=150.0, observer=2)
    a = dekf.simulate_estimation_based_flocking(X0, X_hat0, Sigma0, rng=3, **kw)
    b = dekf.simulate_estimation_based_flocking(X0, X_hat0, Sigma0, rng=3, **kw)
    assert a.X.shape == (2, 16, N, 4) and a.X_hat.shape == (2, 16, N, 4)
    assert a.position_variance.shape == (2, 16, N) and a.rms_error.shape == (2, 16)
    assert a.X_hat.tobytes() == b.X_hat.tobytes() and a.X.tobytes() == b.X.tobytes()
    np.testing.assert_array_equal(a.X[:, 0], X0)
    assert np.all(a.position_variance > 0)
    # the observer's own position is measured at every step, so its variance is below R's trace
    assert np.all(a.position_variance[:, :, 2] < 2.0)


def test_observed_agents_have_smaller_statistical_error():
    """The covariance of an agent in range is bounded by the measurement noise, unlike one out of range."""
    rng = np.random.default_rng(7)
    X0 = np.array([[0.0, 0, 0, 0], [100.0, 0, 0, 0], [200.0, 0, 0, 0], [300.0, 0, 0, 0]])
    Sigma0 = np.kron(np.eye(4), np.diag([4.0, 4, 1, 1]))
    X_hat0 = np.broadcast_to(X0, (4, 4, 4)).copy()
    run = dekf.simulate_estimation_based_flocking(X0, X_hat0, Sigma0, 5, 0.1, GAINS, np.eye(4), np.eye(4), rng,
                                                  150.0, observer=0)
    far = ~run.adjacency[-1, 0]
    far[0] = False
    assert far.any()
    assert run.position_variance[-1, far].min() > run.position_variance[-1, ~far].max()


def test_bad_inputs_raise():
    N, m = 3, 4
    M = N * m
    x, P, z = np.zeros((N, m)), np.eye(M), np.zeros((N, m))
    with pytest.raises(ValueError, match="observed must be a boolean"):
        dekf.masked_update(x, P, z, np.ones(N), np.eye(M), agent=0)
    with pytest.raises(ValueError, match="Sigma_pred"):
        dekf.masked_update(x, np.eye(M - 1), z, np.ones(N, bool), np.eye(M), agent=0)
    with pytest.raises(ValueError, match="R must be positive definite"):
        dekf.masked_update(x, P, z, np.ones(N, bool), np.zeros((M, M)), agent=0)
    with pytest.raises(ValueError, match="Q_team"):
        dekf.ekf_predict(x, P, 0.1, GAINS, np.eye(4))
    with pytest.raises(ValueError, match="X_hat0 must be finite"):
        dekf.simulate_estimation_based_flocking(x, np.zeros((N, m)), P, 3, 0.1, GAINS, np.eye(4), np.eye(4), 0, 150.0)
    with pytest.raises(ValueError, match="observer must be in"):
        dekf.simulate_estimation_based_flocking(x, np.zeros((N, N, m)), P, 3, 0.1, GAINS, np.eye(4), np.eye(4), 0,
                                                150.0, observer=5)


def test_ekf_flocking_step_equals_its_parts():
    """ekf_flocking_step == masked_update, then control_from_views (eq. (39)), then ekf_predict."""
    rng = np.random.default_rng(8)
    N, m = 4, 4
    M = N * m
    X = _team(rng, (), N)
    A = np.array([[0, 1, 0, 0], [1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0]], float)
    Z, S = sensing.measure(rng, X, A, np.eye(m))
    X_pred = X[None] + rng.standard_normal((N, N, m))
    Sigma = np.broadcast_to(4 * np.eye(M), (N, M, M)).copy()
    Q = np.eye(M)
    X_post, S_post, U, X_next, S_next = dekf.ekf_flocking_step(X_pred, Sigma, Z, S, np.eye(M), 0.1, GAINS, Q)
    ref_X, ref_S = dekf.masked_update(X_pred, Sigma, Z, S, np.eye(M), agent=np.arange(N))
    np.testing.assert_allclose(X_post, ref_X)
    np.testing.assert_allclose(U, flocking.control_from_views(ref_X, GAINS))
    for i in range(N):  # agent i's own control from its own estimate, fully connected
        np.testing.assert_allclose(U[i], flocking.flocking_control(ref_X[i], GAINS)[i], atol=1e-12)
    np.testing.assert_allclose(X_next, flocking.closed_loop_step(ref_X, 0.1, GAINS))
    np.testing.assert_allclose(S_next, dekf.ekf_predict(ref_X, ref_S, 0.1, GAINS, Q)[1])


# ----------------------------------------------------------------------------- checked model, owned filter


def _ekf_case(seed, N=4, runs=2):
    rng = np.random.default_rng(seed)
    M = 4 * N
    X = _team(rng, (runs,), N)
    X_hat = X[:, None] + rng.standard_normal((runs, N, N, 4))
    return rng, X, X_hat, M


def _run_ekf(seed, n_steps=20, N=4):
    """An independent filter bank: its own model, filter and measurements; every output of every step."""
    rng, X, X_hat, M = _ekf_case(seed, N)
    model = dekf.EKFModel(N, 0.1, GAINS, 0.01 * np.eye(M), np.eye(M))
    ekf = dekf.FlockingEKF(model, X_hat, 4.0 * np.eye(M))
    out = []
    for k in range(n_steps):
        observed = rng.random((2, N, N)) < 0.7
        observed[:, np.arange(N), np.arange(N)] = True  # row i is agent i's closed neighbourhood
        z = X[:, None] + rng.standard_normal((2, N, N, 4))
        step = ekf.step(z, observed, predict=k < n_steps - 1)
        out += [a.copy() for a in step if a is not None] + [ekf.Sigma.copy()]
    return out


def test_eight_threads_give_the_serial_results_byte_for_byte():
    """No hidden shared state: 8 threads, each with its own model and filter (20 steps), reproduce a serial run."""
    from concurrent.futures import ThreadPoolExecutor

    seeds = list(range(8))
    serial = [_run_ekf(s) for s in seeds]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(_run_ekf, seeds))
    for a, b in zip(serial, threaded):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert x.shape == y.shape and x.tobytes() == y.tobytes()


def test_filter_object_equals_the_plain_array_functions():
    """FlockingEKF.update/predict/step give exactly what masked_update, ekf_predict and ekf_flocking_step give."""
    rng, X, X_hat, M = _ekf_case(1)
    N = 4
    Sigma = np.broadcast_to(_spd(rng, M), (2, N, M, M)).copy()
    observed = rng.random((2, N, N)) < 0.7
    observed[:, np.arange(N), np.arange(N)] = True  # row i is agent i's closed neighbourhood
    z = X[:, None] + rng.standard_normal((2, N, N, 4))
    model = dekf.EKFModel(N, 0.1, GAINS, 0.01 * np.eye(M), np.eye(M))
    ekf = dekf.FlockingEKF(model, X_hat, Sigma)
    X_post = ekf.update(z, observed)
    ref_X, ref_S = dekf.masked_update(X_hat, Sigma, z, observed, np.eye(M), agent=np.arange(N))
    np.testing.assert_array_equal(X_post, ref_X)
    np.testing.assert_array_equal(ekf.Sigma, ref_S)
    X_next, U = ekf.predict()
    ref = dekf.ekf_predict(ref_X, ref_S, 0.1, GAINS, 0.01 * np.eye(M))
    np.testing.assert_array_equal(X_next, ref[0])
    np.testing.assert_array_equal(ekf.Sigma, ref[1])
    assert U.shape == (2, N, N, 2)
    ekf2 = dekf.FlockingEKF(model, X_hat, Sigma)
    post = np.empty(ekf2.Sigma.shape)
    step = ekf2.step(z, observed, posterior_out=post)
    whole = dekf.ekf_flocking_step(X_hat, Sigma, z, observed, np.eye(M), 0.1, GAINS, 0.01 * np.eye(M))
    for got, want in zip((step.X_post, post, step.U, step.X_next, ekf2.Sigma), whole):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(step.variance, np.diagonal(post, axis1=-2, axis2=-1))


def test_model_and_filter_arrays_are_read_only_copies():
    """Changing the caller's arrays after construction cannot reach the filter; the stored ones refuse writes."""
    rng, X, X_hat, M = _ekf_case(2)
    N = 4
    Q, R, Sigma0 = 0.01 * np.eye(M), np.eye(M), 4.0 * np.eye(M)
    model = dekf.EKFModel(N, 0.1, GAINS, Q, R)
    ekf = dekf.FlockingEKF(model, X_hat, Sigma0)
    ref = dekf.FlockingEKF(dekf.EKFModel(N, 0.1, GAINS, Q.copy(), R.copy()), X_hat.copy(), Sigma0.copy())
    Q[0, 0] = R[0, 0] = -5.0  # the caller's arrays, spoiled after the check
    Sigma0[:] = np.nan
    X_hat[:] = np.nan
    for arr in (model.Q_team, model.R, ekf.view("X_hat"), ekf.view("Sigma")):
        assert not arr.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            arr[..., 0, 0] = 1.0
    ekf.X_hat[..., 0, 0] = ekf.Sigma[..., 0, 0] = 1.0  # copies: writing into them cannot reach the filter
    with pytest.raises(AttributeError):
        model.dt = 1.0
    observed = np.ones((2, N, N), bool)
    z = X[:, None] + rng.standard_normal((2, N, N, 4))
    got, want = ekf.step(z, observed), ref.step(z, observed)
    for a, b in zip(got, want):
        np.testing.assert_array_equal(a, b)
    for arr in (got.X_post, got.X_next):
        assert not arr.flags.writeable


@pytest.mark.parametrize("kwargs, exc, name", [
    (dict(n_agents=0), ValueError, "n_agents"),
    (dict(dt=-0.1), ValueError, "dt"),
    (dict(gains={"rho3": 1.0}), TypeError, "gains"),
    (dict(Q_team=np.eye(12)), ValueError, "Q_team"),
    (dict(Q_team=-np.eye(16)), ValueError, "Q_team"),
    (dict(R=np.zeros((16, 16))), ValueError, "R"),
    (dict(R="R"), TypeError, "R"),
    (dict(R=np.full((16, 16), np.nan)), ValueError, "R"),
    (dict(Q_team=None), TypeError, "Q_team"),
    (dict(state_dim=3), ValueError, "state_dim"),
    (dict(Q_team=np.eye(12), R=None), ValueError, "Q_team"),
])
def test_bad_model_arguments_are_refused_by_name(kwargs, exc, name):
    args = dict(n_agents=4, dt=0.1, gains=GAINS, Q_team=0.01 * np.eye(16), R=np.eye(16))
    args.update(kwargs)
    with pytest.raises(exc, match=name):
        dekf.EKFModel(**args)


def test_filter_checks_its_prior_once_and_each_call_its_measurements():
    rng, X, X_hat, M = _ekf_case(3)
    N = 4
    model = dekf.EKFModel(N, 0.1, GAINS, 0.01 * np.eye(M), np.eye(M))
    with pytest.raises(ValueError, match="Sigma"):
        dekf.FlockingEKF(model, X_hat, -np.eye(M))
    with pytest.raises(ValueError, match="X_hat"):
        dekf.FlockingEKF(model, X_hat[..., :3, :], np.eye(M))
    with pytest.raises(TypeError, match="model"):
        dekf.FlockingEKF("model", X_hat, np.eye(M))
    ekf = dekf.FlockingEKF(model, X_hat, np.eye(M))
    z = X[:, None] + np.zeros((2, N, N, 4))
    with pytest.raises(ValueError, match="z contains NaN"):
        ekf.step(np.full_like(z, np.nan), np.ones((2, N, N), bool))
    with pytest.raises(ValueError, match="observed"):
        ekf.step(z, np.ones((2, N, N)))
    with pytest.raises(ValueError, match="z has batch axes"):
        ekf.step(np.broadcast_to(z, (3, 2, N, N, 4)), np.ones((2, N, N), bool))
    no_R = dekf.FlockingEKF(dekf.EKFModel(N, 0.1, GAINS, 0.01 * np.eye(M)), X_hat, np.eye(M))
    with pytest.raises(ValueError, match="needs a model with R"):
        no_R.update(z, np.ones((2, N, N), bool))


def test_an_overflowing_step_raises_naming_its_inputs():
    rng, X, X_hat, M = _ekf_case(4)
    N = 4
    ekf = dekf.FlockingEKF(dekf.EKFModel(N, 10.0, GAINS, 0.01 * np.eye(M), np.eye(M)), X_hat, 1e307 * np.eye(M))
    with pytest.raises(ValueError, match=r"EKF step \(inputs X_hat, Sigma, z\) produced NaN or inf"):
        ekf.step(X[:, None] + np.zeros((2, N, N, 4)), np.broadcast_to(np.eye(N, dtype=bool), (2, N, N)))


def test_tiled_kernels_equal_the_textbook_filter_where_tiles_and_blocks_are_needed():
    """A team large enough that the step's products are tiled (M = 140: the inner dimension in pieces, ragged
    tiles) and the innovation covariance factored by blocks (q = 80 > 64): the update equals
    mascore.kalman.update with H_i, the prediction mascore.kalman.predict with the analytic F."""
    rng = np.random.default_rng(11)
    N, m = 35, 4
    M = N * m
    observed = np.arange(N) < 20
    x, P, R = _team(rng, (), N), _spd(rng, M, 4.0), _spd(rng, M)
    z = x + rng.standard_normal((N, m))
    X_post, P_post = dekf.masked_update(x, P, z, observed, R, agent=0)
    H = sensing.selection_matrix(np.flatnonzero(observed), N, m)
    x_ref, P_ref = kalman.update(x.ravel(), P, H @ z.ravel(), H, H @ R @ H.T)
    np.testing.assert_allclose(X_post.ravel(), x_ref, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(P_post, P_ref, rtol=1e-10, atol=1e-10)
    Q = np.kron(np.eye(N), np.diag([1.0, 1.0, 0.5, 0.5]))
    _, S_pred = dekf.ekf_predict(X_post, P_post, 0.1, GAINS, Q)
    _, S_ref = kalman.predict(np.zeros(M), P_post, flocking.closed_loop_jacobian(X_post, 0.1, GAINS), Q)
    np.testing.assert_allclose(S_pred, S_ref, rtol=1e-12, atol=1e-12 * np.abs(S_ref).max())


@pytest.mark.parametrize("m, k", [(5, 3), (68, 136), (130, 520)])
def test_tiled_symmetric_product_equals_the_full_product(m, k):
    """The prediction's G Sigma G^T from its tiles on and above the diagonal (row blocks of TILE_ROWS / 2, the
    blocks left of them mirrored; k = 520: the inner dimension summed over pieces) equals numpy's full product,
    and so does the general tiled product Y = G Sigma (rows, columns and inner dimension in ragged tiles)."""
    from mascore import _ekf_kernels as kernels

    rng = np.random.default_rng(5)
    G = rng.standard_normal((2, m, k))
    S = rng.standard_normal((2, k, k))
    S = S + np.swapaxes(S, -1, -2)
    acc = np.empty(2 * max(m, k) ** 2)
    Y = kernels.tiled_matmul(G, S, np.empty((2, m, k)), acc)
    np.testing.assert_allclose(Y, G @ S, rtol=1e-12, atol=1e-12 * np.abs(Y).max())
    Z = kernels.tiled_matmul(Y, np.swapaxes(G, -1, -2), np.full((2, m, m), np.nan), acc, symmetric=True)
    np.testing.assert_allclose(Z, Y @ np.swapaxes(G, -1, -2), rtol=1e-12, atol=1e-12 * np.abs(Z).max())


# ----------------------------------------------------------------------------- the fast step against a plain one


def _plain_jacobian(X, dt, gains):
    """``F = I kron A + (I kron B) dU/dX`` written out from the pair Jacobian alone (no shared kernel)."""
    N, m = X.shape
    n = m // 2
    i, j = np.nonzero(~np.eye(N, dtype=bool))  # every pair i != j, by i then j
    J = flocking.pair_term_jacobian(X[i, :n] - X[j, :n], X[i, n:] - X[j, n:], gains)  # (N (N - 1), n, m)
    dU = np.zeros((N, n, N, m))
    dU[i, :, j, :] = -J                                                 # d u_i / d x_j
    dU[np.arange(N), :, np.arange(N), :] = J.reshape(N, N - 1, n, m).sum(1)  # d u_i / d x_i: the sum over j
    A = np.block([[np.eye(n), dt * np.eye(n)], [np.zeros((n, n)), np.eye(n)]])
    B = np.vstack([0.5 * dt**2 * np.eye(n), dt * np.eye(n)])
    F = np.kron(np.eye(N), A)
    for i in range(N):
        F[i * m:(i + 1) * m] += B @ dU[i].reshape(n, N * m)
    return F


def _plain_step(x, P, z, observed, R, dt, gains, Q, agent):
    """Textbook EKF step of one agent's filter: update with H, own control, dense F P F^T + Q."""
    N, m = x.shape
    n = m // 2
    H = sensing.selection_matrix(np.flatnonzero(observed), N, m)
    S = H @ P @ H.T + H @ R @ H.T
    K = np.linalg.solve(S, H @ P).T  # P H^T S^-1 (S symmetric)
    x_post = x.ravel() + K @ (H @ z.ravel() - H @ x.ravel())
    P_post = (np.eye(N * m) - K @ H) @ P
    X_post = x_post.reshape(N, m)
    U = flocking.flocking_control(X_post, gains)
    X_next = np.concatenate([X_post[:, :n] + dt * X_post[:, n:] + 0.5 * dt**2 * U, X_post[:, n:] + dt * U], -1)
    F = _plain_jacobian(X_post, dt, gains)
    return X_post, P_post, U[agent], X_next, F @ P_post @ F.T + Q


@pytest.mark.parametrize("N, n_steps", [(5, 3), (34, 1)])
def test_fast_step_equals_a_plainly_written_textbook_step(N, n_steps):
    """FlockingEKF.step (gathered rank-q update, low-rank structured prediction, tiled products, mirrored
    symmetric blocks) equals the textbook EKF written plainly: K = P H^T S^-1, (I - K H) P, and a dense
    F P F^T + Q with F assembled from the pair Jacobian, step after step. N = 34: products cut in tiles,
    a symmetric product mirrored across row blocks (2N = 68 > 64 rows) and innovation covariances above
    order 64 factored by blocks."""
    rng = np.random.default_rng(21)
    m, M, dt = 4, 4 * N, 0.1
    X = _team(rng, (), N)
    R = sensing.team_noise_covariance(2.0 * np.eye(m), N, m)
    Q = np.kron(np.eye(N), np.diag([0.5, 0.5, 0.1, 0.1]))
    X_hat = X[None] + rng.standard_normal((N, N, m))
    P = np.stack([_spd(rng, M, 4.0) for _ in range(N)])
    ekf = dekf.FlockingEKF(dekf.EKFModel(N, dt, GAINS, Q, R), X_hat, P)
    for _ in range(n_steps):
        observed = rng.random((N, N)) < 0.5
        observed[np.arange(N), np.arange(N)] = True
        observed[0, :20] = True  # agent 0 observes 20 agents when N = 34: q = 80 > 64
        z = X[None] + rng.standard_normal((N, N, m))
        post = np.empty((N, M, M))
        out = ekf.step(z, observed, posterior_out=post)
        for i in range(N):
            X_post, P_post, u, X_next, P_next = _plain_step(X_hat[i], P[i], z[i], observed[i], R, dt, GAINS, Q, i)
            scale = np.abs(P_next).max()
            np.testing.assert_allclose(out.X_post[i], X_post, rtol=1e-10, atol=1e-9)
            np.testing.assert_allclose(post[i], P_post, rtol=1e-9, atol=1e-10 * np.abs(P_post).max())
            np.testing.assert_allclose(out.variance[i], np.diag(P_post), rtol=1e-9)
            np.testing.assert_allclose(out.U[i], u, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(out.X_next[i], X_next, rtol=1e-10, atol=1e-9)
            np.testing.assert_allclose(ekf.view("Sigma")[i], P_next, rtol=1e-9, atol=1e-11 * scale)
        Sigma = ekf.view("Sigma")
        assert np.array_equal(Sigma, np.swapaxes(Sigma, -1, -2))  # exactly symmetric
        X_hat, P = ekf.X_hat, ekf.Sigma
