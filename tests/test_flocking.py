"""Tests of mascore.flocking: the augmented Cucker-Smale law of Song et al. (2023), eq. (6)."""

import numpy as np
import pytest

from mascore import DivergenceError, flocking
from mascore.flocking import FlockingGains

# Table I of Song et al. (2023)
GAINS = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)


def _loop_control(X, gains, A):
    """Eq. (6) written term by term, one agent and one neighbour at a time."""
    N, m = X.shape
    n = m // 2
    U = np.zeros((N, n))
    for i in range(N):
        for j in range(N):
            if j == i or A[i, j] == 0:
                continue
            p_ij = X[i, :n] - X[j, :n]
            v_ij = X[i, n:] - X[j, n:]
            d = np.linalg.norm(p_ij)
            phi1 = 1 / (1 + d**2) ** gains.beta
            phi2 = gains.rho5 / (2 * d**2) * (v_ij @ p_ij) + gains.rho6 / (2 * d) * (d - gains.R)
            U[i] += gains.rho3 * A[i, j] * phi1 * (X[j, n:] - X[i, n:])
            U[i] += gains.rho4 * A[i, j] * phi2 * (X[j, :n] - X[i, :n])
    return U


def _random_team(rng, shape, N=6, scale=100.0):
    return np.concatenate([scale * rng.standard_normal((*shape, N, 2)), 3 * rng.standard_normal((*shape, N, 2))], -1)


def test_phi_values_by_hand():
    """phi1(3, 4) = 26^-0.33; phi2 of a pair 120 m apart at rest is 0 (spring rest length)."""
    assert flocking.phi1([3.0, 4.0], 0.33) == pytest.approx(26.0**-0.33)
    assert flocking.phi2([120.0, 0.0], [0.0, 0.0], GAINS) == pytest.approx(0.0, abs=1e-15)
    # d = 60, v along p: rho5 / (2 d^2) * (v.p) + rho6 / (2 d) (d - R)
    assert flocking.phi2([60.0, 0.0], [2.0, 0.0], GAINS) == pytest.approx(2 / (2 * 3600) * 120 + 1 / 120 * (60 - 120))


def test_spring_attracts_beyond_R_and_repels_inside():
    u_far = flocking.flocking_control(np.array([[0, 0, 0, 0], [200.0, 0, 0, 0]]), GAINS)
    u_near = flocking.flocking_control(np.array([[0, 0, 0, 0], [50.0, 0, 0, 0]]), GAINS)
    assert u_far[0, 0] > 0 and u_far[1, 0] < 0  # towards each other
    assert u_near[0, 0] < 0 and u_near[1, 0] > 0  # apart
    # magnitude rho4 rho6 / 2 (d - R)
    assert u_far[0, 0] == pytest.approx(0.5 * (200 - 120))


def test_matches_term_by_term_loop_on_random_graphs():
    rng = np.random.default_rng(0)
    X = _random_team(rng, (4,))
    A = (rng.random((4, 6, 6)) < 0.5).astype(float)
    A = np.maximum(A, np.swapaxes(A, -1, -2))
    A[:, np.arange(6), np.arange(6)] = 0
    U = flocking.flocking_control(X, GAINS, A)
    for b in range(4):
        np.testing.assert_allclose(U[b], _loop_control(X[b], GAINS, A[b]), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(flocking.flocking_control(X[0], GAINS), _loop_control(X[0], GAINS, 1 - np.eye(6)),
                               rtol=1e-12, atol=1e-12)


def test_fully_connected_control_sums_to_zero():
    """The pair term is odd, so on a symmetric graph the team's accelerations cancel (momentum kept)."""
    rng = np.random.default_rng(1)
    U = flocking.flocking_control(_random_team(rng, (3,)), GAINS)
    np.testing.assert_allclose(U.sum(axis=-2), 0.0, atol=1e-10)


def test_views_equal_to_truth_give_eq6():
    """Eq. (7)/(39) with every view equal to the true state reduce to eq. (6)."""
    rng = np.random.default_rng(2)
    X = _random_team(rng, (2,))
    views = np.broadcast_to(X[:, None], (2, 6, 6, 4))
    A = np.ones((6, 6)) - np.eye(6)
    A[0, 3] = A[3, 0] = 0
    np.testing.assert_allclose(flocking.control_from_views(views, GAINS, A), flocking.flocking_control(X, GAINS, A))
    np.testing.assert_allclose(flocking.control_from_views(views, GAINS), flocking.flocking_control(X, GAINS))


def test_views_use_only_own_row():
    """Agent i's control depends on views[i] only (its own measurements / estimates)."""
    rng = np.random.default_rng(3)
    views = rng.standard_normal((5, 5, 4)) * 50
    U = flocking.control_from_views(views, GAINS)
    views2 = views.copy()
    views2[1] += 7.0  # change agent 2's view only
    U2 = flocking.control_from_views(views2, GAINS)
    np.testing.assert_allclose(np.delete(U2, 1, 0), np.delete(U, 1, 0))
    np.testing.assert_allclose(U2[1], U[1])  # a common shift of agent 2's whole view changes nothing
    for i in range(5):
        np.testing.assert_allclose(U[i], flocking.flocking_control(views[i], GAINS)[i], atol=1e-12)


def test_coincident_agents_give_finite_control_and_zero_pair_term():
    """Documented behaviour: the pair term of two coincident agents is exactly 0, never NaN."""
    X = np.array([[10.0, 5.0, 1.0, -2.0], [10.0, 5.0, 3.0, 0.5], [200.0, 0.0, 0.0, 0.0]])
    U = flocking.flocking_control(X, GAINS)
    assert np.all(np.isfinite(U))
    g01 = flocking.pair_term(X[0, :2] - X[1, :2], X[0, 2:] - X[1, 2:], GAINS)
    # only the velocity-alignment part remains at contact: -rho3 phi1(0) v_ij
    np.testing.assert_allclose(g01, -GAINS.rho3 * (X[0, 2:] - X[1, 2:]))
    J = flocking.closed_loop_jacobian(X, 0.1, GAINS)
    assert np.all(np.isfinite(J))


def test_pair_term_bounded_and_continuous_near_contact():
    """Below d_min the spring term shrinks linearly to 0; above it, it is the law as printed.

    Its size never exceeds rho4 (rho5 |v| + rho6 R) / 2 (the bound stated in the module docstring).
    """
    gains = FlockingGains(3, 1, 2, 1, 0.33, 120.0, min_distance=1.0)
    v = np.array([0.3, -0.4])
    d = np.array([1e-9, 0.5, 1.0 - 1e-12, 1.0, 1.0 + 1e-12, 2.0, 50.0])
    p = d[:, None] * np.array([0.6, 0.8])
    g = flocking.pair_term(p, np.broadcast_to(v, p.shape), gains)
    align = -gains.rho3 * flocking.phi1(p, gains.beta)[:, None] * v
    spring_and_damping = np.linalg.norm(g - align, axis=-1)
    assert np.all(spring_and_damping <= gains.rho4 * (gains.rho5 * np.linalg.norm(v) + gains.rho6 * gains.R) / 2 + 1e-9)
    assert spring_and_damping[0] < 1e-6  # vanishes at contact
    np.testing.assert_allclose(g[2], g[4], atol=1e-9)  # continuous across d_min
    far = flocking.pair_term(p[-1], v, FlockingGains(3, 1, 2, 1, 0.33, 120.0))
    np.testing.assert_allclose(g[-1], far)  # unchanged above d_min


@pytest.mark.parametrize("min_distance, scale", [(1e-6, 100.0), (5.0, 3.0)])
def test_jacobian_matches_finite_differences(min_distance, scale):
    """Analytic df'/dX of eq. (40) against central differences, far from and (case 2) inside d_min."""
    gains = FlockingGains(3, 1, 2, 1, 0.33, 120.0, min_distance=min_distance)
    rng = np.random.default_rng(4)
    X = _random_team(rng, (2,), N=5, scale=scale)
    F = flocking.closed_loop_jacobian(X, 0.1, gains)
    M = X.shape[-1] * X.shape[-2]
    flat = X.reshape(2, M)
    h = 1e-6
    F_fd = np.empty_like(F)
    for k in range(M):
        e = np.zeros(M)
        e[k] = h
        plus = flocking.closed_loop_step((flat + e).reshape(X.shape), 0.1, gains).reshape(2, M)
        minus = flocking.closed_loop_step((flat - e).reshape(X.shape), 0.1, gains).reshape(2, M)
        F_fd[..., k] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(F, F_fd, atol=1e-6 * max(1.0, np.abs(F).max()))
    if min_distance > 1:  # make sure some pair really was inside d_min
        d = np.linalg.norm(X[..., :, None, :2] - X[..., None, :, :2], axis=-1)
        assert np.any((d < min_distance) & (d > 0))


def test_jacobian_of_pair_term_is_even():
    rng = np.random.default_rng(5)
    p, v = 80 * rng.standard_normal((10, 2)), rng.standard_normal((10, 2))
    np.testing.assert_allclose(flocking.pair_term_jacobian(p, v, GAINS), flocking.pair_term_jacobian(-p, -v, GAINS))


def test_noiseless_fully_connected_flock_stays_within_bound():
    """Sec. II-D: fully connected, every agent ends within R (N-1)/N of the centre of mass; velocities agree."""
    rng = np.random.default_rng(6)
    X0 = np.concatenate([rng.uniform(0, 300, (8, 2)), rng.uniform(-5, 5, (8, 2))], -1)
    run = flocking.simulate_measured_flocking(X0, 1500, 0.1, GAINS, np.zeros((4, 4)), np.zeros((4, 4)), rng, None)
    _, std_v = flocking.flock_spread(run.X[-1])
    assert std_v < 1e-2  # the slowest (rotational) mode decays at only ~0.05 /s
    assert flocking.max_distance_from_centre(run.X[-1]) <= GAINS.R * 7 / 8 + 1e-6


def test_two_agents_settle_at_rest_length():
    """N = 2: R is the distance between the agents at rest (Sec. II-D)."""
    X0 = np.array([[0.0, 0, 1, 0], [30.0, 40, -1, 2]])
    run = flocking.simulate_measured_flocking(X0, 800, 0.1, GAINS, np.zeros((4, 4)), np.zeros((4, 4)), 0, None)
    assert np.linalg.norm(run.X[-1, 0, :2] - run.X[-1, 1, :2]) == pytest.approx(GAINS.R, rel=1e-6)


def test_simulation_is_deterministic_and_shaped():
    rng = np.random.default_rng(7)
    X0 = _random_team(rng, (3,), N=4)
    a = flocking.simulate_measured_flocking(X0, 20, 0.1, GAINS, np.eye(4), np.eye(4), 11, 150.0)
    b = flocking.simulate_measured_flocking(X0, 20, 0.1, GAINS, np.eye(4), np.eye(4), 11, 150.0)
    assert a.X.shape == (3, 21, 4, 4) and a.adjacency.shape == (3, 21, 4, 4) and a.t.shape == (21,)
    assert a.X.tobytes() == b.X.tobytes()
    np.testing.assert_array_equal(a.X[:, 0], X0)


def test_simulation_measures_as_the_public_sensing_does():
    """The loop's sensing (kernels, checked once) equals eq. (2) by :func:`mascore.sensing.measure` each step:
    the same draws from the same generator give the same trajectories, bit for bit (ranged and full graph)."""
    from mascore import graphs, sensing

    X0 = _random_team(np.random.default_rng(8), (3,), N=5)
    R, dt, steps = np.diag([4.0, 1.0, 0.5, 0.25]), 0.1, 15
    for sensing_range in (150.0, None):
        run = flocking.simulate_measured_flocking(X0, steps, dt, GAINS, np.zeros((4, 4)), R, 3, sensing_range)
        rng, X = np.random.default_rng(3), X0.copy()
        for k in range(steps):
            A = (np.ones((5, 5)) - np.eye(5) if sensing_range is None
                 else graphs.proximity_graph(X[..., :2], sensing_range))
            views, _ = sensing.measure(rng, X, A, R, allow_isolated=True)
            U = flocking.control_from_views(views, GAINS, A.astype(bool))
            p, v = X[..., :2], X[..., 2:]
            X = np.concatenate([p + dt * v + 0.5 * dt**2 * U, v + dt * U], axis=-1)
            X = X + rng.standard_normal(X.shape) @ np.zeros((4, 4))  # the process-noise draw (Q = 0)
            assert run.X[:, k + 1].tobytes() == X.tobytes(), (sensing_range, k)


def test_flock_spread_of_known_configuration():
    X = np.array([[1.0, 0, 2, 0], [-1.0, 0, -2, 0]])
    std_p, std_v = flocking.flock_spread(X)
    assert std_p == pytest.approx(1.0) and std_v == pytest.approx(2.0)
    assert flocking.max_distance_from_centre(X) == pytest.approx(1.0)


@pytest.mark.parametrize("field, value, match", [
    ("rho3", -1.0, "rho3 must be a positive"),
    ("R", 0.0, "R must be a positive"),
    ("beta", -0.1, "beta must be a non-negative"),
    ("min_distance", np.nan, "min_distance must be a positive"),
])
def test_bad_gains_raise(field, value, match):
    kwargs = dict(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
    kwargs[field] = value
    with pytest.raises(ValueError, match=match):
        FlockingGains(**kwargs)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="X must have shape"):
        flocking.flocking_control(np.zeros((3, 3)), GAINS)
    with pytest.raises(ValueError, match="X contains NaN"):
        flocking.flocking_control(np.array([[0, 0, 0, 0], [np.nan, 0, 0, 0]]), GAINS)
    with pytest.raises(ValueError, match="adjacency must have shape"):
        flocking.flocking_control(np.zeros((3, 4)), GAINS, np.ones((2, 2)))
    with pytest.raises(ValueError, match="views must have shape"):
        flocking.control_from_views(np.zeros((3, 2, 4)), GAINS)
    with pytest.raises(ValueError, match="n_steps must be an integer >= 1"):
        flocking.simulate_measured_flocking(np.zeros((2, 4)), 0, 0.1, GAINS, np.eye(4), np.eye(4), 0, None)
    with pytest.raises(ValueError, match="Q"):
        flocking.simulate_measured_flocking(np.zeros((2, 4)), 5, 0.1, GAINS, -np.eye(4), np.eye(4), 0, None)
    with pytest.raises(TypeError, match="rng"):
        flocking.simulate_measured_flocking(np.zeros((2, 4)), 5, 0.1, GAINS, np.eye(4), np.eye(4), "seed", None)


def test_large_fully_connected_team_diverges_with_clear_error():
    """Beyond the paper: with Table I gains and dt = 0.1 s the sampled fully-connected loop is unstable
    for N = 24 (N - 1 dampers per agent); the simulator raises instead of returning overflowed states."""
    rng = np.random.default_rng(8)
    X0 = np.concatenate([rng.uniform(0, 600, (24, 2)), np.zeros((24, 2))], -1)
    with pytest.raises(DivergenceError, match="diverged"):
        flocking.simulate_measured_flocking(X0, 600, 0.1, GAINS, np.zeros((4, 4)), np.zeros((4, 4)), 0, None)
    # the same team is stable with a ten times smaller step
    run = flocking.simulate_measured_flocking(X0, 300, 0.01, GAINS, np.zeros((4, 4)), np.zeros((4, 4)), 0, None)
    assert np.all(np.isfinite(run.X))


def test_agents_that_meet_separate_to_rest_length():
    """Documented behaviour at contact, in closed loop: two agents starting at the same point with
    different velocities get a finite control, fly apart and settle R apart; with identical states
    they stay together (the pair term is exactly 0 at contact, so that unstable equilibrium is kept)."""
    zero = np.zeros((4, 4))
    X0 = np.array([[50.0, 50.0, 1.0, 0.0], [50.0, 50.0, -1.0, 0.5]])
    run = flocking.simulate_measured_flocking(X0, 800, 0.1, GAINS, zero, zero, 0, None)
    assert np.all(np.isfinite(run.X))
    assert np.linalg.norm(run.X[-1, 0, :2] - run.X[-1, 1, :2]) == pytest.approx(GAINS.R, rel=1e-6)
    same = np.array([[50.0, 50.0, 1.0, 0.0], [50.0, 50.0, 1.0, 0.0]])
    still = flocking.simulate_measured_flocking(same, 50, 0.1, GAINS, zero, zero, 0, None)
    np.testing.assert_array_equal(still.X[:, 0], still.X[:, 1])
