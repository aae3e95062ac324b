"""Olfati-Saber's Kalman-consensus filter and the set-membership filter on forwarded measurements.

The KCF (:class:`mascore.fusion_forwarding.KalmanConsensusNetworkFilter`) against the statements of its paper
(Olfati-Saber 2007, Algorithm 1 and Theorem 2); the set-membership filter
(:class:`mascore.fusion_forwarding.SetMembershipForwardingFilter`) against the public set-membership steps
it reuses (a sibling computation) and the guarantee of a set-membership filter (the true state
stays in the set while every noise stays in its bound).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from mascore import compare, ellipsoids, fusion, fusion_forwarding, graphs, sensor_network
from mascore.set_membership import SetMembershipModel

DT = 0.5
F = np.array([[1.0, DT], [0.0, 1.0]])
Q = 0.05 * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]])
#: Heterogeneous sensing on 5 agents: position, both, nothing, velocity, position.
H5 = [np.array([[1.0, 0.0]]), np.eye(2), np.zeros((0, 2)), np.array([[0.0, 1.0]]), np.array([[1.0, 0.0]])]
R5 = [np.array([[0.4]]), np.array([[1.0, 0.3], [0.3, 0.5]]), None, np.array([[0.2]]), np.array([[2.0]])]
P0 = np.diag([4.0, 1.0])
X0 = np.array([10.0, 1.0])


def _model() -> sensor_network.SensorNetworkModel:
    return sensor_network.SensorNetworkModel(F, Q, H5, R5, graphs.ring_graph(5))


def _noise_free(model, K: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A noise-free path of K steps from a random start, its exact measurements, and the agents' wrong starts."""
    rng = np.random.default_rng(seed)
    n = model.n_states
    x = np.empty((K + 1, n))
    x[0] = rng.standard_normal(n)
    for k in range(K):
        x[k + 1] = model.F @ x[k]
    return x, x[1:] @ model.H_stacked.T, x[0] + rng.standard_normal((model.n_agents, n))


# --------------------------------------------------------------------------------------------
# the Kalman-consensus filter


def test_kcf_with_zero_gain_is_the_local_filter_on_neighbour_measurements_bit_for_bit():
    """Olfati-Saber (2007), Algorithm 1: with gamma = 0 (eps = 0) each node is a Kalman filter on the data of N_i ∪ {i}.

    That filter is :class:`~mascore.fusion.MeasurementForwardingFilter`: the same numbers to the last bit.
    """
    model = _model()
    _, z = model.simulate(X0, P0, 30, rng=4, n_runs=7)
    x_kcf, P_kcf = fusion_forwarding.KalmanConsensusNetworkFilter(model, eps=0.0).run(X0, P0, z)
    x_fwd, P_fwd = fusion.MeasurementForwardingFilter(model).run(X0, P0, z)
    np.testing.assert_array_equal(x_kcf, x_fwd)
    np.testing.assert_array_equal(P_kcf, P_fwd)
    x_eps, _ = fusion_forwarding.KalmanConsensusNetworkFilter(model, eps=0.3).run(X0, P0, z)
    assert np.abs(x_eps - x_fwd).max() > 1e-3  # the consensus term is not idle


@pytest.mark.parametrize("eps", [0.1, 0.5])
def test_kcf_noise_free_errors_vanish_where_forwarding_alone_cannot(eps):
    """Olfati-Saber (2007), Theorem 2: without noise the estimation errors of every node tend to zero.

    Cooperative localization on a ring of 6: an agent's neighbourhood does not observe the far agents'
    positions, so forwarding alone (eps = 0) keeps their initial error; the consensus term carries them.
    """
    model = compare.localization_model(6)
    x, z, starts = _noise_free(model, 300, seed=1)
    n = model.n_states
    errors = {}
    for gain in (0.0, eps):
        xs, _ = fusion_forwarding.KalmanConsensusNetworkFilter(model, gain).run(starts, np.eye(n), z)
        errors[gain] = np.linalg.norm(xs - x[1:, None], axis=-1).max(axis=-1)  # worst agent, per step
    assert errors[eps][-1] < 1e-6 * errors[eps][0]
    assert errors[0.0][-1] > 0.1 * errors[0.0][0]  # forwarding's unobserved directions keep their error


def test_kcf_consensus_term_shrinks_the_disagreement_between_agents():
    """Olfati-Saber (2007), Theorem 2: the nodes' estimates reach a consensus; the larger eps, the less they disagree.

    Disagreement: the squared distance of the agents' estimates to their average, summed over agents and steps.
    Noise-free on the common target, and under noise on cooperative localization (steady window).
    """
    model = compare.target_model(8)
    _, z, starts = _noise_free(model, 200, seed=2)
    spread = []
    for eps in (0.0, 0.1, 0.5):
        xs, _ = fusion_forwarding.KalmanConsensusNetworkFilter(model, eps).run(starts, np.eye(4), z)
        spread.append(float(((xs - xs.mean(axis=1, keepdims=True)) ** 2).sum()))
    assert spread[0] > spread[1] > spread[2]
    assert spread[2] < 0.5 * spread[0]

    model = compare.localization_model(6)
    n = model.n_states
    _, z = model.simulate(np.zeros(n), np.eye(n), 120, rng=3, n_runs=10)
    steady = {}
    for eps in (0.0, 0.5):
        xs, _ = fusion_forwarding.KalmanConsensusNetworkFilter(model, eps).run(np.zeros(n), np.eye(n), z)
        steady[eps] = float(((xs[60:] - xs[60:].mean(axis=-2, keepdims=True)) ** 2).sum(axis=(-2, -1)).mean())
    assert steady[0.5] < 0.01 * steady[0.0]


def test_kcf_step_is_algorithm_1_written_out():
    """One step against Algorithm 1 written out per node with explicit inverses (an independent computation)."""
    model = _model()
    rng = np.random.default_rng(7)
    xbar = X0 + rng.standard_normal((5, 2))
    P = np.stack([P0 * (1 + 0.2 * i) for i in range(5)])
    z = rng.standard_normal(model.n_measurements)
    eps = 0.4
    x_new, M_new = fusion_forwarding.KalmanConsensusNetworkFilter(model, eps).update(xbar, P, z)
    A = graphs.ring_graph(5)
    for i in range(5):
        J = [j for j in range(5) if j == i or A[i, j]]
        y = sum((H5[j].T @ np.linalg.inv(R5[j]) @ model.agent_measurement(z, j)) for j in J if H5[j].shape[0])
        S = sum((H5[j].T @ np.linalg.inv(R5[j]) @ H5[j]) for j in J if H5[j].shape[0])
        M = np.linalg.inv(np.linalg.inv(P[i]) + S)
        gamma = eps / (1 + np.sqrt(np.trace(M.T @ M)))
        xi = xbar[i] + M @ (y - S @ xbar[i]) + gamma * M @ sum(xbar[j] - xbar[i] for j in J if j != i)
        np.testing.assert_allclose(x_new[i], xi, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(M_new[i], M, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("eps", [-0.1, float("nan"), float("inf")])
def test_kcf_refuses_a_bad_gain(eps):
    with pytest.raises(ValueError, match="eps"):
        fusion_forwarding.KalmanConsensusNetworkFilter(_model(), eps)
    with pytest.raises(TypeError, match="eps"):
        fusion_forwarding.KalmanConsensusNetworkFilter(_model(), "0.1")


# --------------------------------------------------------------------------------------------
# the set-membership filter on forwarded measurements


def test_set_update_is_the_set_membership_correction_of_each_agent():
    """The team-wide update against :meth:`SetMembershipModel.correct` called agent by agent (the public steps).

    Agent i: C = its neighbourhood's stacked H_j, the bound chi2_p(c) blockdiag(R_j) of its p stacked numbers.
    """
    model = _model()
    smf = fusion_forwarding.SetMembershipForwardingFilter(model, confidence=0.99)
    rng = np.random.default_rng(3)
    x = X0 + rng.standard_normal((4, 5, 2))                                   # 4 runs
    E = np.stack([smf.initial_shape(P0 * (1 + 0.3 * i)) for i in range(5)])   # one shape per agent, shared
    z = rng.standard_normal((4, model.n_measurements))
    xc, Ec = smf.update(x, E, z)
    A = graphs.ring_graph(5)
    for i in range(5):
        J = [j for j in range(5) if (j == i or A[i, j]) and H5[j].shape[0]]
        C = np.vstack([H5[j] for j in J])
        R = np.zeros((C.shape[0], C.shape[0]))
        at = 0
        for j in J:
            q = H5[j].shape[0]
            R[at:at + q, at:at + q] = R5[j]
            at += q
        sm = SetMembershipModel(C=C, D=np.eye(C.shape[0]), R=chi2.ppf(0.99, C.shape[0]) * R)
        y = np.concatenate([model.agent_measurement(z, j) for j in J], axis=-1)
        c_ref, E_ref, _ = sm.correct(x[:, i], E[i], y, check_consistency=False)
        np.testing.assert_allclose(xc[:, i], c_ref, rtol=1e-11, atol=1e-11)
        np.testing.assert_allclose(np.broadcast_to(Ec[i], E_ref.shape), E_ref, rtol=1e-11, atol=1e-13)


def test_set_membership_forwarding_holds_the_true_state_under_noise_within_its_bounds():
    """The guarantee of a set-membership filter: with every noise inside its set, the true state is in every agent's set.

    The initial error, the process noise and each agent's measurement noise are drawn inside the
    filter's bounds (a measurement's share of its neighbourhood's bound); the sets also stay small.
    """
    model = _model()
    c = 0.9
    smf = fusion_forwarding.SetMembershipForwardingFilter(model, confidence=c)
    rng = np.random.default_rng(11)
    K, runs = 40, 20
    s_n = chi2.ppf(c, 2)
    hoods = [[j for j in range(5) if (j == i or graphs.ring_graph(5)[i, j]) and H5[j].shape[0]] for i in range(5)]
    share = min(chi2.ppf(c, sum(H5[j].shape[0] for j in h)) for h in hoods) / max(len(h) for h in hoods)
    x = np.empty((K + 1, runs, 2))
    x[0] = ellipsoids.sample_interior(rng, X0, s_n * P0, runs)
    z = np.empty((K, runs, model.n_measurements))
    for k in range(K):
        x[k + 1] = x[k] @ F.T + ellipsoids.sample_interior(rng, np.zeros(2), s_n * Q, runs)
        z[k] = x[k + 1] @ model.H_stacked.T
        for j in range(5):
            if H5[j].shape[0]:
                q = H5[j].shape[0]
                v = ellipsoids.sample_interior(rng, np.zeros(q), share * R5[j], runs)
                z[k][:, model.agent_measurement(np.arange(model.n_measurements, dtype=float), j).astype(int)] += v
    centres, shapes = smf.run(X0, smf.initial_shape(P0), z)
    inside = ellipsoids.contains(x[1:, :, None, :], centres, shapes[:, None])
    assert inside.all()
    assert np.trace(shapes[-1], axis1=-2, axis2=-1).max() < 0.5 * np.trace(s_n * P0)


def test_simulate_target_scores_the_set_by_its_containment():
    """The comparison scores the set-membership filter by containment and set size, not by a NEES."""
    m = compare.simulate_target("sm-forwarding", 8, 0, runs=5)
    assert np.isnan(m["nees_own"]).all()
    assert ((m["containment"] >= 0) & (m["containment"] <= 1)).all()
    assert (m["set_size"] > 0).all()
    rows = compare.run_cell({"study": "target", "task": "target", "method": "sm-forwarding", "n_agents": 8,
                             "noise": "gaussian", "dropout": 0.0, "q_scale": 1.0, "block": 0})
    assert np.isfinite(rows[0]["containment"]) and np.isnan(rows[0]["nees_own"])
    kcf = compare.run_cell({"study": "target", "task": "target", "method": "kcf", "n_agents": 8,
                            "noise": "gaussian", "dropout": 0.0, "q_scale": 1.0, "block": 0})
    assert np.isnan(kcf[0]["containment"]) and np.isfinite(kcf[0]["nees_own"])
    assert list(rows[0]) == list(kcf[0])  # every row of a sweep has the same columns, in one order


@pytest.mark.parametrize("confidence", [0.0, 1.0, 1.5, float("nan")])
def test_set_membership_forwarding_refuses_a_bad_confidence(confidence):
    with pytest.raises(ValueError, match="confidence"):
        fusion_forwarding.SetMembershipForwardingFilter(_model(), confidence)


def test_set_membership_forwarding_needs_a_process_noise_bound():
    model = sensor_network.SensorNetworkModel(F, np.zeros((2, 2)), H5, R5, graphs.ring_graph(5))
    with pytest.raises(ValueError, match="Q must be positive definite"):
        fusion_forwarding.SetMembershipForwardingFilter(model)
