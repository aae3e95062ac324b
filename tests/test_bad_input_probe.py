"""Findings of the whole-API hostile-input probe (benchmarks/hostile_probe.py), each refused by name.

One test per finding: a step's input of the wrong type, shape or with NaN/inf (the per-agent and
team-wide steps of the filters outside the paper modules), entries so large that squaring them
overflows, counts whose arrays cannot fit, and messages that did not name the argument.
"""

from __future__ import annotations

import numpy as np
import pytest

from mascore import (
    claims,
    compare,
    consensus_filters,
    estimation,
    formatting,
    graphs,
    kalman,
    lqr,
    network_observer,
    observers,
    own_state,
    plotting,
    rendezvous,
    sensor_network,
    set_membership,
    team_observability,
)

HUGE = 10**12
KCF = consensus_filters.KalmanConsensusFilter(0.1, 0.1)
AVG = consensus_filters.AverageConsensusFilter()
XI, P1, G3 = np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1)), graphs.path_graph(3)
OWN = own_state.OwnStateForwardingFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), np.eye(1))
CEN = own_state.CentralizedOutputFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), 1.0, 2)
X2, PO, S2 = np.zeros((1, 2, 1)), np.ones((1, 2, 1, 1)), np.ones((1, 2, 2), bool)
Z2 = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])
OBS = network_observer.DiscreteNetworkObserver([[0.5], [0.1]], 0.2, graphs.ring_graph(3), [[1, 0.1], [0, 1]],
                                               [[0.0], [0.1]], [[1.0, 0.0]])


def _nan(a, where=0):
    a = np.array(a, dtype=float)
    a.flat[where] = np.nan
    return a


@pytest.mark.parametrize("call, error, match", [
    # the consensus filters of the shared quantity: a step's inputs
    (lambda: KCF.predict(_nan(XI), P1), ValueError, r"\bxi contains NaN"),
    (lambda: KCF.agent_inputs(XI, P1, G3, "1"), TypeError, r"\bi must be an integer"),
    (lambda: KCF.agent_inputs(XI, P1[:2], G3, 1), ValueError, r"\bP must have shape \(N, m, m\)"),
    (lambda: KCF.messages(0, -1), ValueError, r"\bm must be an integer >= 1"),
    (lambda: AVG.update(XI, -G3), ValueError, r"\bG must hold non-negative link weights"),
    (lambda: AVG.update(XI[:2], G3), ValueError, r"\bG must have shape \(N, N\) = \(2, 2\)"),
    # the own-state filters of the position comparison
    (lambda: OWN.update(X2, np.full_like(PO, np.inf), Z2, S2), ValueError, r"\bP contains NaN or infinite"),
    (lambda: OWN.predict("x", PO, X2), TypeError, r"\bx must be an array of real numbers"),
    (lambda: OWN.update(X2[None], PO, Z2, S2), ValueError, r"\bx must have shape \(R, 2, 1\)"),
    (lambda: OWN.agent_inputs(X2[0], PO[0, :1], Z2[0], S2[0], np.zeros((2, 1)), 1), ValueError,
     r"\bP must have shape \(2, 1, 1\)"),
    (lambda: OWN.agent_inputs(X2[0], PO[0], Z2[0], S2[0], np.zeros((2, 1)), 2), ValueError, r"\bi must be an agent"),
    (lambda: own_state.OwnStateForwardingFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), [[1e300]], np.eye(1)),
     ValueError, r"\bH is too large"),
    (lambda: own_state.CentralizedOutputFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), 1.0, HUGE),
     ValueError, r"n_agents asks for too much"),
    (lambda: OWN.update(X2, np.zeros_like(PO), Z2, S2), ValueError, r"\bP must be positive definite"),
    (lambda: CEN.predict(X2, _nan(np.eye(2)[None]), X2), ValueError, r"\bP contains NaN"),
    # the network observer as a filter of the position comparison
    (lambda: OBS.update(_nan(np.zeros((1, 3, 2))), np.ones((1, 3, 3, 1)), np.ones((1, 3, 3))), ValueError,
     r"\bx_hat contains NaN"),
    (lambda: OBS.update(np.zeros((1, 3, 2)), np.ones((1, 1, 3, 3, 1)), np.ones((1, 3, 3))), ValueError,
     r"\bz must have shape \(R, 3, 3, 1\)"),
    (lambda: network_observer.DiscreteNetworkObserver([[0.5], [0.1]], "0.2", graphs.ring_graph(3),
                                                      [[1, 0.1], [0, 1]], [[0.0], [0.1]], [[1.0, 0.0]]),
     ValueError, r"\bcoupling must be a finite number"),
    # the agents' inputs of the other estimators
    (lambda: kalman.LinearGaussianModel(np.eye(1), 0.1 * np.eye(1), np.eye(1), np.eye(1)).agent_inputs(
        np.zeros((2, 1)), np.eye(1), np.zeros((2, 1)), None, 5), ValueError, r"\bi must be an agent 0..1"),
    (lambda: sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2), np.eye(1, 2)], [np.eye(2), np.eye(1)],
                                               graphs.path_graph(2)).agent_measurement([np.inf, 2.0, 3.0], 1),
     ValueError, r"\bz contains NaN or infinite"),
    # entries that overflow once squared, refused before the arithmetic
    (lambda: set_membership.correct(np.zeros(2), np.diag([1e300, 1.0]), np.zeros(1), np.eye(1, 2), np.eye(1),
                                    np.eye(1)), ValueError, r"\bshape has entries of magnitude 1e\+300"),
    (lambda: set_membership.correct(np.zeros(2), np.eye(2), np.zeros(1), np.eye(1, 2), np.eye(1), [[1e300]]),
     ValueError, r"D R D\^T \(from D and R\) has entries"),
    (lambda: rendezvous.team_spread([[1e300, 0.0], [0.0, 0.0]]), ValueError, r"\bvalues has entries of magnitude"),
    (lambda: team_observability.lyapunov_v(np.full(6, 1e300), np.eye(6)), ValueError, r"\berror has entries"),
    (lambda: lqr.top_down_lqr([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], np.diag([1e300, 1.0]), np.eye(2), np.eye(1),
                              graphs.ring_graph(4)), ValueError, r"\bQ1 has entries of magnitude"),
    (lambda: lqr.top_down_lqr([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], np.eye(2)[None, None], np.eye(2), np.eye(1),
                              graphs.ring_graph(4)), ValueError, r"\bQ1 must be a matrix \(2 x 2\)"),
    (lambda: observers.distributed_observer([[0.0, 1.0], [-1.0, -0.1]], [[0.0], [1.0]], [[1.0, 0.0]], np.eye(1),
                                            [[1e300]], np.eye(1), graphs.ring_graph(5)),
     ValueError, r"\bQ2 has entries of magnitude"),
    # records and small helpers
    (lambda: estimation.GaussianState(_nan(np.zeros(2)), np.eye(2)), ValueError, r"\bmean contains NaN"),
    (lambda: estimation.SetState(np.zeros(2), np.eye(3)), ValueError, r"\bshape must have shape"),
    (lambda: estimation.Message("state", "3"), ValueError, r"\bfloats must be a finite number"),
    (lambda: compare.target_cost("local", "8", 2), TypeError, r"\bn_agents must be an integer"),
    (lambda: plotting.agent_colors(HUGE), ValueError, r"n_agents asks for too much"),
    (lambda: plotting.plot_graph(np.zeros((3, 2)), graphs.path_graph(3), sensing_range=-1.0), ValueError,
     r"\bsensing_range must be a finite number > 0"),
    (lambda: claims.worst_deviation([np.nan], [1.0], "abs"), ValueError, r"\bpaper_value contains NaN"),
    (lambda: formatting.format_number(1.0, HUGE), ValueError, r"\bdigits must be an integer >= 1 and at most 17"),
])
def test_the_probe_findings_are_refused_by_name(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_a_set_membership_error_for_a_labelled_batch_names_the_input_not_numpy():
    """A per-agent label array with an unbatched ellipsoid once broke the message itself (a numpy broadcast error)."""
    model = set_membership.SetMembershipModel(C=np.eye(1, 2), D=np.eye(1), R=np.eye(1), n=2)
    with pytest.raises(ValueError, match=r"correction step, agent batch: center or shape has NaN/inf entries"):
        model.correct(_nan(np.zeros(2)), np.eye(2), np.zeros(1), agent=np.arange(3))


def test_set_membership_runs_name_their_own_arguments_when_too_large_or_mismatched():
    A, G, C, D, Q, R = np.eye(2), np.eye(2), np.eye(1, 2), np.eye(1), 0.01 * np.eye(2), 0.04 * np.eye(1)
    y = np.zeros((3, 1))
    with pytest.raises(ValueError, match=r"\bP0 has entries of magnitude 1e\+300"):
        set_membership.run_filter(np.zeros(2), np.diag([1e300, 1.0]), y, A, G, C, D, Q, R)
    with pytest.raises(ValueError, match=r"\bx0_hat has entries of magnitude 1e\+300"):
        set_membership.run_filter(np.array([1e300, 0.0]), np.eye(2), y, A, G, C, D, Q, R)
    with pytest.raises(ValueError, match=r"G Q G\^T overflows"):
        set_membership.run_filter(np.zeros(2), np.eye(2), y, A, G, C, D, np.diag([1e300, 1.0]), R)
    with pytest.raises(ValueError, match=r"do not broadcast: center \(10,\), shape \(11,\)"):
        set_membership.predict(np.zeros((10, 2)), np.broadcast_to(np.eye(2), (11, 2, 2)), A, G, Q)


def test_the_set_membership_forwarding_filter_refuses_a_non_finite_centre():
    from mascore import fusion_forwarding

    model = sensor_network.SensorNetworkModel(np.eye(1), 0.01 * np.eye(1), [np.eye(1)] * 2, [np.eye(1)] * 2,
                                              graphs.path_graph(2))
    with pytest.raises(ValueError, match=r"\bx contains NaN or infinite"):
        fusion_forwarding.SetMembershipForwardingFilter(model).predict(np.array([[np.nan], [1.0]]), np.ones((2, 1, 1)))
