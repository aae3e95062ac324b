"""Tests of mascore.fusion: each filter against a property its paper proves, on the same sensing.

The error covariance of a linear filter is computed exactly, not by Monte Carlo: the
filters' covariances do not depend on the data, so each estimate is linear in the noise
sources (initial error, process noise, measurement noise). Running the filter once per
source direction (a batch of ``n + K (n + sum q)`` runs, scaled by the square roots of
the covariances) and summing the outer products of the errors gives ``E[e e^T]`` to
rounding (:func:`_exact_error_covariance`).
"""

from __future__ import annotations

import pickle
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from mascore import fusion, fusion_cost, graphs, kalman, sensor_network

DT = 0.5
F = np.array([[1.0, DT], [0.0, 1.0]])
Q = 0.05 * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]])
#: Heterogeneous sensing on 5 agents: position, both, nothing, velocity, position.
H5 = [np.array([[1.0, 0.0]]), np.eye(2), np.zeros((0, 2)), np.array([[0.0, 1.0]]), np.array([[1.0, 0.0]])]
R5 = [np.array([[0.4]]), np.array([[1.0, 0.3], [0.3, 0.5]]), None, np.array([[0.2]]), np.array([[2.0]])]
P0 = np.diag([4.0, 1.0])
X0 = np.array([10.0, 1.0])
K_STEPS = 15


def _model(adjacency=None, R=R5):
    return sensor_network.SensorNetworkModel(F, Q, H5, R, graphs.ring_graph(5) if adjacency is None else adjacency)


def _sqrt(M):
    lam, V = np.linalg.eigh(M)
    return V * np.sqrt(np.clip(lam, 0, None))


def _exact_error_covariance(filt, model, n_steps=K_STEPS):
    """Exact ``E[e_i e_i^T]`` of every agent at steps 1..K, and the filter's P (from x0 = 0: zero-mean errors)."""
    n, q = model.n_states, model.n_measurements
    D = n + n_steps * (n + q)
    x = np.zeros((n_steps + 1, D, n))
    z = np.zeros((n_steps, D, q))
    x[0, :n] = _sqrt(P0).T  # source d: the d-th column of the square root
    sQ, sR = _sqrt(Q), _sqrt(model.R_stacked)
    row = n
    for k in range(n_steps):
        w = np.zeros((D, n))
        w[row:row + n] = sQ.T
        row += n
        v = np.zeros((D, q))
        v[row:row + q] = sR.T
        row += q
        x[k + 1] = x[k] @ F.T + w
        z[k] = x[k + 1] @ model.H_stacked.T + v
    xs, Ps = filt.run(np.zeros(n), P0, z)
    truth = x[1:, :, None, :] if xs.ndim == 4 else x[1:]
    e = truth - xs
    sub = "kdia,kdib->kiab" if xs.ndim == 4 else "kda,kdb->kab"
    return np.einsum(sub, e, e), Ps


def _min_margin(P, C):
    """Smallest eigenvalue of P - C over every step and agent, relative to the size of P."""
    return float(np.linalg.eigvalsh(P - C).min() / np.abs(P).max())


# ---------------------------------------------------------------------------- the exact baseline


def test_centralized_filter_is_the_kalman_filter_on_the_stacked_model():
    model = _model()
    x_true, z = model.simulate(X0, P0, 20, rng=3)
    xs, Ps = fusion.CentralizedFilter(model).run(X0, P0, z)
    ref_x, ref_P = kalman.run_filter(X0, P0, z, kalman.LinearGaussianModel(F, Q, model.H_stacked, model.R_stacked))
    assert xs.shape == (20, 2) and Ps.shape == (20, 2, 2)
    np.testing.assert_array_equal(xs, ref_x)
    np.testing.assert_array_equal(Ps, ref_P)


def test_exact_error_covariance_of_kalman_filters_equals_their_P():
    """The harness is right: a Kalman filter's P *is* its error covariance (centralized, and forwarding)."""
    model = _model()
    for filt in (fusion.CentralizedFilter(model), fusion.MeasurementForwardingFilter(model)):
        C, P = _exact_error_covariance(filt, model)
        np.testing.assert_allclose(P, C, rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------------------- consensus on information


@pytest.mark.parametrize("L", [0, 1, 2, 3, 5, 20])
def test_consensus_on_information_is_consistent_for_any_number_of_steps(L):
    """Battistelli and Chisci (2014), Theorem 1: P_i >= E[e_i e_i^T] (PSD) for every L, every agent and step.

    On a ring with a non-sensing agent and agents that see only position or only velocity
    (locally unobservable), from a consistent common prior.
    """
    model = _model()
    C, P = _exact_error_covariance(fusion.ConsensusOnInformationFilter(model, L), model)
    assert _min_margin(P, C) >= -1e-10
    if L >= 1:  # and the bound is not slack everywhere: some direction is nearly tight
        assert not np.allclose(P, C, rtol=1e-3)


def test_the_consistency_check_can_fail():
    """The same check refuses filters that are not consistent: ICF with few iterations, HCMCI (w = N) with L = 1."""
    model = _model()
    for filt in (fusion.InformationConsensusFilter(model, 1), fusion.ConsensusOnInformationFilter(model, 1, "N")):
        C, P = _exact_error_covariance(filt, model)
        assert _min_margin(P, C) < -1e-3


@pytest.mark.parametrize("L", [1, 3])
def test_hcmci_is_consistent_with_the_largest_safe_novelty_weight(L):
    """``w max_j [W^L]_ij <= 1`` (the measurement half of the CI argument) keeps HCMCI consistent."""
    model = _model()
    WL = np.linalg.matrix_power(model.weights, L)
    sensing = np.array(model.measurement_sizes) > 0
    w = 1.0 / WL[:, sensing].max()
    assert w > 1
    C, P = _exact_error_covariance(fusion.ConsensusOnInformationFilter(model, L, w), model)
    assert _min_margin(P, C) >= -1e-10


def test_many_consensus_steps_give_the_centralized_filter_with_n_times_the_noise():
    """CI (w = 1), L -> inf: every agent holds the centralized filter of R_i -> N R_i; HCMCI (w = N): the centralized."""
    model = _model()
    N = model.n_agents
    _, z = model.simulate(X0, P0, 20, rng=7)
    scaled = _model(R=[None if r is None else N * r for r in R5])
    xc, Pc = fusion.CentralizedFilter(scaled).run(X0, P0, z)
    x, P = fusion.ConsensusOnInformationFilter(model, 400).run(X0, P0, z)
    np.testing.assert_allclose(x, np.broadcast_to(xc[:, None], x.shape), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(P, np.broadcast_to(Pc[:, None], P.shape), rtol=1e-9, atol=1e-12)
    xc, Pc = fusion.CentralizedFilter(model).run(X0, P0, z)
    x, P = fusion.ConsensusOnInformationFilter(model, 400, "N").run(X0, P0, z)
    np.testing.assert_allclose(x, np.broadcast_to(xc[:, None], x.shape), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(P, np.broadcast_to(Pc[:, None], P.shape), rtol=1e-9, atol=1e-12)


def _gap(x, P, xc, Pc):
    return max(float(np.abs(x - xc[:, None]).max()), float(np.abs(P - Pc[:, None]).max()))


def test_ci_and_hcmci_approach_their_limits_as_l_grows():
    model = _model()
    N = model.n_agents
    _, z = model.simulate(X0, P0, 20, rng=8)
    xc, Pc = fusion.CentralizedFilter(model).run(X0, P0, z)
    xs, Ps = fusion.CentralizedFilter(_model(R=[None if r is None else N * r for r in R5])).run(X0, P0, z)
    ci = [_gap(*fusion.ConsensusOnInformationFilter(model, L).run(X0, P0, z), xs, Ps) for L in (1, 3, 10, 30, 100)]
    hc = [_gap(*fusion.ConsensusOnInformationFilter(model, L, "N").run(X0, P0, z), xc, Pc)
          for L in (1, 3, 10, 30, 100)]
    for gaps in (ci, hc):
        assert all(b < a for a, b in zip(gaps, gaps[1:])), gaps
        assert gaps[-1] < 1e-9


# ---------------------------------------------------------------------------- ICF


def test_information_consensus_filter_approaches_the_centralized_filter():
    """Kamal, Farrell and Roy-Chowdhury (2013): K -> inf iterations, common prior -> centralized; gap shrinks with K."""
    model = _model()
    _, z = model.simulate(X0, P0, 20, rng=11)
    xc, Pc = fusion.CentralizedFilter(model).run(X0, P0, z)
    iterations = (0, 2, 5, 10, 20, 50, 200)
    gaps = [_gap(*fusion.InformationConsensusFilter(model, K).run(X0, P0, z), xc, Pc) for K in iterations]
    assert all(b < a for a, b in zip(gaps, gaps[1:])), gaps
    assert gaps[-1] < 1e-9


# ---------------------------------------------------------------------------- diffusion KF


def test_diffusion_kf_is_unbiased_and_its_p_is_not_the_error_covariance():
    """Cattivelli and Sayed (2010): the diffused estimate is unbiased (Monte Carlo mean error within 4.5 sigma/sqrt(M)).

    Its P (the incremental step's) differs from the exact error covariance of the diffused estimate.
    """
    model = _model()
    dkf = fusion.DiffusionKalmanFilter(model)
    M = 4000
    x_true, z = model.simulate(X0, P0, K_STEPS, rng=5, n_runs=M)
    xs, _ = dkf.run(X0, P0, z)
    e = x_true[1:, :, None, :] - xs  # (K, M, N, n)
    mean, sd = e.mean(axis=1), e.std(axis=1)
    assert np.all(np.abs(mean) <= 4.5 * sd / np.sqrt(M))
    C, P = _exact_error_covariance(dkf, model)
    assert np.abs(P - C).max() > 1e-2 * np.abs(P).max()
    np.testing.assert_allclose(np.einsum("kiaa->kia", C), np.einsum("kmia,kmia->kia", e, e) / M, rtol=0.15)


# ---------------------------------------------------------------------------- complete graph


def test_on_a_complete_graph_every_filter_equals_the_centralized_one():
    """Complete graph, common prior; tolerance 1e-9 (relative) on means and covariances.

    Forwarding and diffusion hear every measurement; Metropolis weights are 11^T / N so one
    HCMCI step is exact; ICF with rate 1/N in one iteration likewise; CI (w = 1) with one step
    is the centralized filter of N R_i.
    """
    model = _model(graphs.complete_graph(5))
    N = model.n_agents
    _, z = model.simulate(X0, P0, 20, rng=2)
    xc, Pc = fusion.CentralizedFilter(model).run(X0, P0, z)
    filters = [fusion.MeasurementForwardingFilter(model), fusion.DiffusionKalmanFilter(model),
               fusion.ConsensusOnInformationFilter(model, 1, "N"), fusion.InformationConsensusFilter(model, 1, 1 / N)]
    for filt in filters:
        x, P = filt.run(X0, P0, z)
        np.testing.assert_allclose(x, np.broadcast_to(xc[:, None], x.shape), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(P, np.broadcast_to(Pc[:, None], P.shape), rtol=1e-9, atol=1e-12)
    xs, Ps = fusion.CentralizedFilter(_model(graphs.complete_graph(5), [None if r is None else N * r for r in R5])
                                      ).run(X0, P0, z)
    x, P = fusion.ConsensusOnInformationFilter(model, 1).run(X0, P0, z)
    np.testing.assert_allclose(x, np.broadcast_to(xs[:, None], x.shape), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(P, np.broadcast_to(Ps[:, None], P.shape), rtol=1e-9, atol=1e-12)


def test_measurement_forwarding_sums_the_neighbourhood_information():
    model = _model()
    x, P = fusion.MeasurementForwardingFilter(model).update(np.zeros((5, 2)), np.broadcast_to(P0, (5, 2, 2)),
                                                             np.zeros(model.n_measurements))
    S = model.information_matrices
    for i in range(5):
        hood = [i, (i - 1) % 5, (i + 1) % 5]
        np.testing.assert_allclose(np.linalg.inv(P[i]), np.linalg.inv(P0) + S[hood].sum(0), rtol=1e-12)


# ---------------------------------------------------------------------------- covariance intersection


def _random_spd(rng, n):
    G = rng.standard_normal((n, n))
    return G @ G.T + 0.1 * np.eye(n)


def _joint(rng, covs):
    """A joint covariance with the given marginals and random cross-covariances P_i^{1/2} K P_j^{1/2 T}, ||K|| <= 1.

    Built as the Gram matrix of unit-norm-bounded factors: e_i = P_i^{1/2} U_i g with U_i U_i^T = I.
    """
    n = covs.shape[-1]
    k = covs.shape[0]
    dim = rng.integers(n, k * n + 1)  # the shared randomness: from fully correlated (dim n) to independent
    factors = []
    for P in covs:
        U, _ = np.linalg.qr(rng.standard_normal((dim, n)))  # orthonormal columns: U^T U = I
        factors.append(np.linalg.cholesky(P) @ U.T)
    B = np.concatenate(factors)  # (k n, dim)
    return B @ B.T


@pytest.mark.parametrize("weights", ["trace", "det", None, "random"])
@pytest.mark.parametrize("k", [2, 3, 4])
def test_covariance_intersection_is_consistent_under_any_correlation(k, weights):
    """Julier and Uhlmann (1997): P_CI >= E[e e^T] for every joint covariance with the given marginals (exact)."""
    rng = np.random.default_rng(100 + k)
    n = 3
    for trial in range(25):
        covs = np.stack([_random_spd(rng, n) for _ in range(k)])
        joint = _joint(rng, covs)
        np.testing.assert_allclose(np.stack([joint[i * n:(i + 1) * n, i * n:(i + 1) * n] for i in range(k)]), covs,
                                   rtol=1e-10, atol=1e-12)
        w = rng.dirichlet(np.ones(k)) if weights == "random" else weights
        _, P, w = fusion.covariance_intersection(rng.standard_normal((k, n)), covs, w)
        gains = np.concatenate([w[i] * P @ np.linalg.inv(covs[i]) for i in range(k)], axis=1)  # e = sum A_i e_i
        true = gains @ joint @ gains.T
        assert np.linalg.eigvalsh(P - true).min() >= -1e-10 * np.abs(P).max(), trial


def test_covariance_intersection_is_tight_for_identical_errors():
    """Two copies of one estimate (fully correlated): CI returns it unchanged; a naive Kalman fusion would halve P."""
    P = np.array([[2.0, 0.5], [0.5, 1.0]])
    x, Pf, _ = fusion.covariance_intersection([[1.0, 2.0], [1.0, 2.0]], [P, P])
    np.testing.assert_allclose(Pf, P, rtol=1e-12)
    np.testing.assert_allclose(x, [1.0, 2.0], rtol=1e-12)


@pytest.mark.parametrize("criterion", ["trace", "det"])
def test_covariance_intersection_weights_minimize_the_criterion(criterion):
    """The optimal w against a grid search: 1-D (k = 2, 20001 points) and on the 2-simplex (k = 3, step 1/200)."""
    rng = np.random.default_rng(9)
    crit = np.trace if criterion == "trace" else np.linalg.det
    batched = (lambda P: np.einsum("...ii->...", P)) if criterion == "trace" else np.linalg.det
    for k, grid in ((2, np.linspace(0, 1, 20001)[:, None] * [1, -1] + [0, 1]),
                    (3, np.array([[a, b, 1 - a - b] for a in np.linspace(0, 1, 201) for b in np.linspace(0, 1, 201)
                                  if a + b <= 1 + 1e-12]))):
        for _ in range(10):
            covs = np.stack([_random_spd(rng, 3) for _ in range(k)])
            infos = np.linalg.inv(covs)
            values = batched(np.linalg.inv(np.einsum("gk,kij->gij", np.clip(grid, 0, 1), infos)))  # every grid point
            _, P, w = fusion.covariance_intersection(np.zeros((k, 3)), covs, criterion)
            assert np.all(w >= 0) and abs(w.sum() - 1) < 1e-12
            assert crit(P) <= values.min() * (1 + 1e-9)
            if k == 2:
                assert abs(w[0] - grid[values.argmin(), 0]) <= 2e-3 or crit(P) <= values.min() * (1 - 1e-12)


# ---------------------------------------------------------------------------- threads, seeds


def _filters(model):
    return [fusion.CentralizedFilter(model), fusion.MeasurementForwardingFilter(model),
            fusion.ConsensusOnInformationFilter(model, 3), fusion.ConsensusOnInformationFilter(model, 3, "N"),
            fusion.InformationConsensusFilter(model, 4), fusion.DiffusionKalmanFilter(model),
            fusion.CovarianceIntersectionFilter(model)]


def _run_all(seed):
    model = _model()
    x_true, z = model.simulate(X0, P0, 30, rng=np.random.default_rng(seed), n_runs=3)
    out = [x_true, z]
    for filt in _filters(model):
        out += list(filt.run(X0, P0, z))
    return out


def test_eight_threads_give_the_serial_results_byte_for_byte():
    seeds = list(range(8))
    serial = [_run_all(s) for s in seeds]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(_run_all, seeds))
    for a, b in zip(serial, threaded):
        assert len(a) == len(b)
        for u, v in zip(a, b):
            assert u.shape == v.shape and u.tobytes() == v.tobytes()


def test_a_seed_gives_byte_identical_results_and_another_seed_differs():
    a, b, c = _run_all(42), _run_all(42), _run_all(43)
    assert all(u.tobytes() == v.tobytes() for u, v in zip(a, b))
    assert a[1].tobytes() != c[1].tobytes()


def test_filters_share_one_filter_object_across_threads():
    """One filter object, used by 8 threads at once on different data: the serial results."""
    model = _model()
    filt = fusion.ConsensusOnInformationFilter(model, 2)
    data = [model.simulate(X0, P0, 20, rng=s)[1] for s in range(8)]
    serial = [filt.run(X0, P0, z)[0] for z in data]
    with ThreadPoolExecutor(max_workers=8) as pool:
        threaded = list(pool.map(lambda z: filt.run(X0, P0, z)[0], data))
    assert all(u.tobytes() == v.tobytes() for u, v in zip(serial, threaded))


# ---------------------------------------------------------------------------- the model, checked once


def test_model_is_frozen_and_keeps_copies():
    H = [h.copy() for h in H5]
    model = sensor_network.SensorNetworkModel(F, Q, H, R5, graphs.ring_graph(5))
    H[0][0, 0] = 99.0
    assert model.H[0][0, 0] == 1.0
    with pytest.raises(ValueError, match="read-only"):
        model.F[0, 0] = 2.0
    with pytest.raises(AttributeError, match="frozen"):
        model.F = np.eye(2)
    with pytest.raises(AttributeError, match="frozen"):
        fusion.DiffusionKalmanFilter(model).weights = np.eye(5)
    again = pickle.loads(pickle.dumps(model))
    assert repr(again) == repr(model) and np.array_equal(again.information_matrices, model.information_matrices)


def test_an_agent_that_does_not_sense_contributes_nothing():
    model = _model()
    assert model.measurement_sizes == (1, 2, 0, 1, 1)
    i = model.information_vectors(np.arange(1.0, 6.0))
    np.testing.assert_array_equal(i[2], 0.0)
    np.testing.assert_array_equal(model.information_matrices[2], 0.0)
    np.testing.assert_allclose(i[1], np.linalg.solve(R5[1], [2.0, 3.0]))
    np.testing.assert_array_equal(model.agent_measurement(np.arange(1.0, 6.0), 3), [4.0])


_GOOD = dict(F=F, Q=Q, H=H5, R=R5, adjacency=graphs.ring_graph(5))


def _with(**changes):
    return lambda: sensor_network.SensorNetworkModel(**{**_GOOD, **changes})


def _bad_H():
    H = list(H5)
    H[3] = np.ones((1, 3))
    return H


def _bad_R(value):
    R = list(R5)
    R[1] = value
    return R


_MODEL = _model()
_X, _P = _MODEL.check_state(X0, P0)
_Z = np.zeros(_MODEL.n_measurements)


@pytest.mark.parametrize("call, error, match", [
    (_with(F=np.ones((2, 3))), ValueError, "F must be square"),
    (_with(Q=-np.eye(2)), ValueError, "Q must be positive semidefinite"),
    (_with(Q=[[1.0, 0.5], [0.0, 1.0]]), ValueError, "Q must be symmetric"),
    (_with(H=_bad_H()), ValueError, r"H\[3\]"),
    (_with(R=_bad_R(np.array([[1.0, 2.0], [2.0, 1.0]]))), ValueError, r"R\[1\] must be positive definite"),
    (_with(R=_bad_R(np.array([[np.nan, 0.0], [0.0, 1.0]]))), ValueError, r"R\[1\] contains NaN"),
    (_with(R=_bad_R(None)), TypeError, r"R\[1\]"),
    (_with(R=R5[:4]), ValueError, "R must hold one matrix per agent"),
    (_with(adjacency=graphs.adjacency_from_edges(5, [(0, 1)], directed=True)), ValueError,
     "adjacency must be symmetric"),
    (_with(adjacency=graphs.laplacian(graphs.ring_graph(5))), ValueError, "adjacency looks like a Laplacian"),
    (_with(H=[np.zeros((0, 2))] * 5, R=[None] * 5), ValueError, "no agent senses"),
    (lambda: fusion.ConsensusOnInformationFilter(_MODEL, -1), ValueError, "n_consensus"),
    (lambda: fusion.ConsensusOnInformationFilter(_MODEL, 2.5), TypeError, "n_consensus"),
    (lambda: fusion.ConsensusOnInformationFilter(_MODEL, 2, 0.5), ValueError, "novelty_weight"),
    (lambda: fusion.ConsensusOnInformationFilter(_MODEL, 2, "M"), ValueError, "novelty_weight"),
    (lambda: fusion.InformationConsensusFilter(_MODEL, 2, rate=0.6), ValueError, r"rate must lie in \(0, 1 / d_max\)"),
    (lambda: fusion.DiffusionKalmanFilter(_MODEL, np.ones((5, 5)) / 5), ValueError, "weights must be zero where"),
    (lambda: fusion.DiffusionKalmanFilter(_MODEL, 2 * _MODEL.weights), ValueError, "rows summing to 1"),
    (lambda: fusion.DiffusionKalmanFilter("model"), TypeError, "model must be a SensorNetworkModel"),
    (lambda: fusion.CovarianceIntersectionFilter(_MODEL, "max"), ValueError, "criterion must be"),
    (lambda: fusion.CovarianceIntersectionFilter(_MODEL, measurements="all"), ValueError, "measurements must be"),
    (lambda: fusion.MeasurementForwardingFilter(_MODEL).update(_X[:4], _P, _Z), ValueError, "dimensions of x"),
    (lambda: fusion.MeasurementForwardingFilter(_MODEL).update(_X, _P[..., :1], _Z), ValueError, "dimensions of P"),
    (lambda: fusion.MeasurementForwardingFilter(_MODEL).update(_X, _P, np.zeros(4)), ValueError, "dimensions of z"),
    (lambda: fusion.MeasurementForwardingFilter(_MODEL).update(_X, _P, np.full(5, np.nan)), ValueError,
     "z contains NaN"),
    (lambda: fusion.ConsensusOnInformationFilter(_MODEL, 2).update(np.where(_X > 0, np.inf, _X), _P, _Z),
     ValueError, "x contains NaN"),
    (lambda: fusion.InformationConsensusFilter(_MODEL, 2).update(_X, np.zeros_like(_P), _Z), ValueError,
     "singular"),
    (lambda: fusion.ConsensusOnInformationFilter(_MODEL, 2).update(_X, np.full_like(_P, np.nan), _Z), ValueError,
     "P contains NaN"),
    (lambda: fusion.DiffusionKalmanFilter(_MODEL).update(_X, _P, [1e308] * 5), ValueError, "overflow"),
    (lambda: fusion.MeasurementForwardingFilter(_MODEL).predict(_X, _P[0]), ValueError, "dimensions of P"),
    (lambda: fusion.CentralizedFilter(_MODEL).run(X0, -P0, np.zeros((3, 5))), ValueError,
     "P0 must be positive definite"),
    (lambda: fusion.CentralizedFilter(_MODEL).run(X0, P0, np.zeros(5)), ValueError, r"z must be \(K, \.\.\., 5\)"),
    (lambda: _MODEL.simulate(X0, P0, 5, rng=np.random.RandomState(0)), TypeError, "rng must be"),
    (lambda: _MODEL.simulate(X0, P0, 0, rng=1), ValueError, "n_steps"),
    (lambda: fusion.covariance_intersection([[0.0]], [[[-1.0]]]), ValueError, "covs must be positive definite"),
    (lambda: fusion.covariance_intersection([[0.0], [1.0]], [[[1.0]]]), ValueError, "dimensions of covs"),
    (lambda: fusion.covariance_intersection([[0.0], [1.0]], [[[1.0]], [[1.0]]], [0.7, 0.7]), ValueError,
     "weights must be non-negative and sum to 1"),
    (lambda: fusion.covariance_intersection([[0.0], [1.0]], [[[1.0]], [[1.0]]], "max"), ValueError, "weights must be"),
    (lambda: fusion.covariance_intersection([[np.nan], [1.0]], [[[1.0]], [[1.0]]]), ValueError, "means contains NaN"),
    (lambda: fusion_cost.filter_cost("kalman", 2, 1, 2), ValueError, "method must be one of"),
    (lambda: fusion_cost.filter_cost("hcmci", 2, -1, 2), ValueError, "q must be"),
    (lambda: sensor_network.metropolis_weights(graphs.adjacency_from_edges(3, [(0, 1)], directed=True)), ValueError,
     "adjacency must be symmetric"),
])
def test_bad_input_is_refused_by_name(call, error, match):
    with pytest.raises(error, match=match):
        call()


# ---------------------------------------------------------------------------- cost model


def test_cost_model_counts():
    n, q, d, L = 4, 2, 3, 5
    costs = {m: fusion_cost.filter_cost(m, n, q, d, L, n_agents=10) for m in fusion_cost._COST_METHODS}
    assert costs["measurement-forwarding"].floats_sent == q
    assert costs["diffusion-kf"].floats_sent == q + n
    assert costs["consensus-on-information"].floats_sent == L * (n * (n + 1) / 2 + n)
    assert costs["hcmci"].floats_sent == 2 * costs["consensus-on-information"].floats_sent
    assert costs["information-consensus"].floats_sent == costs["consensus-on-information"].floats_sent
    for m in ("consensus-on-information", "hcmci", "information-consensus"):
        more = fusion_cost.filter_cost(m, n, q, d, L + 1)
        assert more.floats_sent > costs[m].floats_sent and more.flops > costs[m].flops
        assert fusion_cost.filter_cost(m, n, q, d + 1, L).flops > costs[m].flops
    assert all(c.flops > 0 and c.floats_formula and c.flops_formula for c in costs.values())


def _evaluate(formula, **values):
    """A formula string of :class:`FilterCost` as Python: juxtaposition is a product, ^ a power."""
    import re

    expr = re.sub(r"(?<=[\w)])\s+(?=[\w(])", "*", formula.replace("^", "**"))
    return eval(expr, {}, values)  # noqa: S307 (our own formula strings)


@pytest.mark.parametrize("method", fusion_cost._COST_METHODS)
def test_cost_formulas_give_the_counted_numbers(method):
    for n, q, d, L, N in ((4, 2, 3, 5, 10), (1, 0, 0, 0, 1), (6, 3, 7, 2, 20)):
        c = fusion_cost.filter_cost(method, n, q, d, L, n_agents=N)
        values = dict(n=n, q=q, d=d, L=L, N=N)
        assert _evaluate(c.floats_formula, **values) == pytest.approx(c.floats_sent, rel=1e-12)
        assert _evaluate(c.flops_formula, **values) == pytest.approx(c.flops, rel=1e-12)


@pytest.mark.parametrize("criterion", ["trace", "det", None])
@pytest.mark.parametrize("measurements", ["neighbourhood", "own"])
def test_covariance_intersection_filter_is_consistent(criterion, measurements):
    """Hu, Xie and Zhang (2012): CI diffusion keeps every P_i >= E[e_i e_i^T] (exact), whatever the weights."""
    model = _model()
    filt = fusion.CovarianceIntersectionFilter(model, criterion, measurements)
    C, P = _exact_error_covariance(filt, model, n_steps=8)
    assert _min_margin(P, C) >= -1e-10


def test_covariance_intersection_filter_batches_equal_single_runs():
    """Weights from covariances with batch axes (a search per element) = the shared-covariance path."""
    model = _model()
    filt = fusion.CovarianceIntersectionFilter(model)
    _, z = model.simulate(X0, P0, 5, rng=4, n_runs=2)
    x1, P1 = filt.run(X0, P0, z)
    x2, P2 = filt.run(np.broadcast_to(X0, (2, 5, 2)), np.broadcast_to(P0, (2, 5, 2, 2)), z)
    assert P2.shape == (5, 2, 5, 2, 2)
    np.testing.assert_allclose(x2, x1, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P2, np.broadcast_to(P1[:, None], P2.shape), rtol=1e-12, atol=1e-14)


def test_filters_pickle_to_equal_filters():
    """Filters go to worker processes (Dask sweeps) and back: same class, same parameters, same results."""
    model = _model()
    _, z = model.simulate(X0, P0, 5, rng=6)
    for filt in _filters(model):
        again = pickle.loads(pickle.dumps(filt))
        assert type(again) is type(filt) and repr(again) == repr(filt)
        a, b = filt.run(X0, P0, z), again.run(X0, P0, z)
        assert all(u.tobytes() == v.tobytes() for u, v in zip(a, b))


def test_error_covariance_equals_the_independent_computation_and_monte_carlo():
    """fusion.error_covariance (stepwise) = the harness above (whole runs) for every filter; = Monte Carlo within 10%."""
    model = _model()
    for filt in _filters(model):
        C, P = fusion.error_covariance(filt, P0, 8)
        C_ref, P_ref = _exact_error_covariance(filt, model, n_steps=8)
        np.testing.assert_allclose(C, C_ref, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(P, np.broadcast_to(P_ref, P.shape), rtol=1e-12, atol=1e-15)
    filt = fusion.ConsensusOnInformationFilter(model, 2)
    x_true, z = model.simulate(np.zeros(2), P0, 8, rng=12, n_runs=20000)
    x, _ = filt.run(np.zeros(2), P0, z)
    e = x_true[1:, :, None, :] - x
    C, _ = fusion.error_covariance(filt, P0, 8)
    np.testing.assert_allclose(np.einsum("kmia,kmia->kia", e, e) / e.shape[1], np.einsum("kiaa->kia", C), rtol=0.1)


def test_error_covariance_with_a_conservative_initial_covariance():
    """P0 larger than the true initial error covariance: the filter stays consistent (CI), P0_true is used."""
    model = _model()
    C, P = fusion.error_covariance(fusion.ConsensusOnInformationFilter(model, 1), 4 * P0, 10, P0_true=P0)
    C1, _ = fusion.error_covariance(fusion.ConsensusOnInformationFilter(model, 1), 4 * P0, 10)
    assert _min_margin(P, C) > _min_margin(P, C1) >= -1e-10
    with pytest.raises(ValueError, match="P0_true"):
        fusion.error_covariance(fusion.ConsensusOnInformationFilter(model, 1), np.broadcast_to(P0, (5, 2, 2)), 3)
    with pytest.raises(TypeError, match="filt must be a filter"):
        fusion.error_covariance(model, P0, 3)


def test_one_agent_and_a_graph_without_links():
    """N = 1: every filter is the centralized one. No links: forwarding, CI, diffusion and CI-diffusion are the
    local filter (CI with L = 0); HCMCI and ICF are not (they count their own measurement N times)."""
    one = sensor_network.SensorNetworkModel(F, Q, [np.eye(2)], [np.eye(2)], np.zeros((1, 1)))
    _, z = one.simulate(X0, P0, 10, rng=1)
    xc, Pc = fusion.CentralizedFilter(one).run(X0, P0, z)
    for filt in _filters(one):
        x, P = filt.run(X0, P0, z)
        np.testing.assert_allclose(x.reshape(xc.shape), xc, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(P.reshape(Pc.shape), Pc, rtol=1e-10, atol=1e-12)
    apart = _model(np.zeros((5, 5)))
    _, z = apart.simulate(X0, P0, 10, rng=1)
    local = fusion.ConsensusOnInformationFilter(apart, 0).run(X0, P0, z)
    for filt in _filters(apart)[1:]:
        again = pickle.loads(pickle.dumps(filt))
        assert repr(again) == repr(filt)
        x, P = filt.run(X0, P0, z)
        if isinstance(filt, fusion.InformationConsensusFilter) or getattr(filt, "novelty_weight", 1) > 1:
            np.testing.assert_allclose(np.linalg.inv(P[0]), np.linalg.inv(F @ P0 @ F.T + Q) + 5 * apart.information_matrices,
                                       rtol=1e-10)
            continue
        np.testing.assert_allclose(x, local[0], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(P, local[1], rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("criterion", ["trace", "det"])
def test_batched_ci_weights_meet_the_kkt_conditions_and_equal_single_searches(criterion):
    """The weight search of many problems at once (padded to a common k): each problem's weights equal its own
    search, satisfy the optimality conditions on the simplex (gradient + lambda = 0 where w_j > 0, >= 0 where
    w_j = 0), and equal estimates keep equal weights (the optimum is flat between them)."""
    from mascore._fusion_kernels import ci_objective, ci_weights

    rng = np.random.default_rng(12)
    infos = np.linalg.inv(np.stack([[_random_spd(rng, 3) for _ in range(5)] for _ in range(30)]))
    infos[::3, 1] = infos[::3, 0]  # every third problem: two equal estimates
    infos[1::3, 2] = 0.05 * infos[1::3, 3]  # a dominated estimate: an optimum on a face of the simplex
    valid = np.arange(5) < rng.integers(2, 6, 30)[:, None]
    W = ci_weights(infos, criterion, valid)
    assert np.all(W[~valid] == 0) and np.allclose(W.sum(axis=1), 1, atol=1e-14) and np.all(W >= 0)
    for b in range(30):
        k = int(valid[b].sum())
        w = ci_weights(infos[b, :k], criterion)
        np.testing.assert_allclose(W[b, :k], w, atol=1e-12)
        g = ci_objective(infos[b, :k], criterion)[1](w)
        lam = -g[w > 1e-9].mean()
        scale = np.abs(g).max()
        assert np.all(np.abs(g[w > 1e-9] + lam) <= 1e-7 * scale) and np.all(g + lam >= -1e-7 * scale)
        if b % 3 == 0:
            assert abs(w[0] - w[1]) <= 1e-12
