"""fusion.track: the one run loop for a user's own sensor network, on a fixed or a switching graph."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from mascore import fusion, graphs, sensor_network

N, K = 5, 12


def _model():
    H = [np.eye(4)[[i % 2]] for i in range(N)]  # each agent one coordinate: nobody observes alone
    return sensor_network.SensorNetworkModel(np.block([[np.eye(2), 0.1 * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]]),
                                     1e-3 * np.eye(4), H, [0.04 * np.eye(1)] * N, graphs.ring_graph(N))


FILTERS = [fusion.CentralizedFilter, fusion.MeasurementForwardingFilter, fusion.DiffusionKalmanFilter,
           lambda m: fusion.ConsensusOnInformationFilter(m, 3), lambda m: fusion.InformationConsensusFilter(m, 4),
           fusion.CovarianceIntersectionFilter]


def _switching():
    rng = np.random.default_rng(3)
    out = []
    for _ in range(K):
        A = graphs.ring_graph(N)
        i, j = rng.choice(N, 2, replace=False)
        A[i, j] = A[j, i] = 1.0  # a chord that moves
        out.append(A)
    return out


@pytest.mark.parametrize("make", FILTERS)
def test_on_the_fixed_graph_track_is_run(make):
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=1, n_runs=3)
    filt = make(model)
    x_run, P_run = filt.run(np.zeros(4), np.eye(4), z)
    for given in (None, [model.adjacency] * K):
        x, P = fusion.track(filt, np.zeros(4), np.eye(4), z, given)
        assert x.tobytes() == x_run.tobytes() and P.tobytes() == P_run.tobytes()


@pytest.mark.parametrize("make", FILTERS)
def test_on_a_switching_graph_track_is_the_filter_of_each_steps_graph(make):
    """An independent loop: one model and one filter per step, predict and update by hand."""
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=2, n_runs=2)
    G = _switching()
    x, P = fusion.track(make(model), np.zeros(4), np.eye(4), z, [graphs.to_networkx(A) for A in G])
    per_agent = make(model)._per_agent
    xk, Pk = model.check_state(np.zeros(4), np.eye(4), per_agent=per_agent)
    for k, A in enumerate(G):
        f = make(sensor_network.SensorNetworkModel(model.F, model.Q, model.H, model.R, A))
        xk, Pk = f.update(*f.predict(xk, Pk), z[k])
        np.testing.assert_allclose(x[k], xk, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(P[k], Pk, rtol=1e-12, atol=1e-12)


def test_the_centralized_filter_does_not_depend_on_the_graph():
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=4)
    filt = fusion.CentralizedFilter(model)
    np.testing.assert_array_equal(fusion.track(filt, np.zeros(4), np.eye(4), z, _switching())[0],
                                  filt.run(np.zeros(4), np.eye(4), z)[0])


def test_bad_graphs_are_named_by_step():
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=0)
    filt = fusion.ConsensusOnInformationFilter(model, 2)
    with pytest.raises(ValueError, match=r"graphs must hold one graph per step: K = 12"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, _switching()[:-1])
    bad = _switching()
    bad[4] = graphs.ring_graph(N + 1)
    with pytest.raises(ValueError, match=r"graphs\[4\]"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, bad)
    bad[4] = nx.to_numpy_array(nx.cycle_graph(N, create_using=nx.DiGraph))
    with pytest.raises(ValueError, match=r"graphs\[4\] must be symmetric"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, bad)
    with pytest.raises(TypeError, match=r"graphs must be a sequence"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, graphs.ring_graph)
    with pytest.raises(TypeError, match=r"filt must be one of mascore.fusion's filters"):
        fusion.track("ci", np.zeros(4), np.eye(4), z, _switching())
    own = fusion.DiffusionKalmanFilter(model, weights=np.full((N, N), 1.0 / N) * (graphs.ring_graph(N) + np.eye(N))
                                       * N / 3)
    with pytest.raises(ValueError, match=r"weights='metropolis'"):
        fusion.track(own, np.zeros(4), np.eye(4), z, _switching())


def _in_range():
    rng = np.random.default_rng(5)
    mask = rng.random((K, N)) < 0.7  # who sees the target changes from step to step
    mask[2] = False                  # a step nobody senses: prediction only
    mask[3] = True
    return mask


@pytest.mark.parametrize("make", FILTERS)
def test_sensing_that_never_changes_is_the_fixed_sensing_run_bit_for_bit(make):
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=6, n_runs=2)
    filt = make(model)
    everyone = np.ones((K, N), dtype=bool)
    for given in (None, _switching()):
        x_fixed, P_fixed = fusion.track(filt, np.zeros(4), np.eye(4), z, given)
        x, P = fusion.track(filt, np.zeros(4), np.eye(4), z, given, sensing=everyone)
        assert x.tobytes() == x_fixed.tobytes() and P.tobytes() == P_fixed.tobytes()


@pytest.mark.parametrize("make", FILTERS)
def test_an_agent_out_of_range_contributes_no_measurement(make):
    """An independent loop: at each step, the model with the rows of the agents out of range removed."""
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=7, n_runs=2)
    mask = _in_range()
    z_unread = z.copy()
    z_unread[:, :, ~mask.any(axis=0)] = np.nan  # never read
    z_unread[~mask[:, None, :].repeat(2, axis=1)] = np.nan
    x, P = fusion.track(make(model), np.zeros(4), np.eye(4), z_unread, _switching(), sensing=mask)
    xk, Pk = model.check_state(np.zeros(4), np.eye(4), per_agent=make(model)._per_agent)
    for k, A in enumerate(_switching()):
        if not mask[k].any():
            xk, Pk = make(model).predict(xk, Pk)
        else:
            H = [model.H[i] if mask[k, i] else np.zeros((0, 4)) for i in range(N)]
            f = make(sensor_network.SensorNetworkModel(model.F, model.Q, H, [model.R[i] if mask[k, i] else None
                                                                          for i in range(N)], A))
            xk, Pk = f.update(*f.predict(xk, Pk), z[k][..., mask[k]])  # one row per agent here
        np.testing.assert_array_equal(x[k], xk)
        np.testing.assert_array_equal(P[k], Pk)
    off = np.ones((K, N), dtype=bool)
    off[:, 1] = False  # agent 1 never in range: the model without its H row
    H = [h if i != 1 else np.zeros((0, 4)) for i, h in enumerate(model.H)]
    without = sensor_network.SensorNetworkModel(model.F, model.Q, H, [r if i != 1 else None
                                                                     for i, r in enumerate(model.R)], model.adjacency)
    x_off = fusion.track(make(model), np.zeros(4), np.eye(4), z, sensing=off)[0]
    np.testing.assert_array_equal(x_off, make(without).run(np.zeros(4), np.eye(4), np.delete(z, 1, axis=-1))[0])


def test_bad_sensing_is_refused_before_any_step():
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=0)
    filt = fusion.ConsensusOnInformationFilter(model, 2)
    with pytest.raises(ValueError, match=r"sensing must be \(K, N\) = \(12, 5\)"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, sensing=np.ones((K, N + 1), dtype=bool))
    with pytest.raises(TypeError, match=r"sensing must be a \(K, N\) array of bool"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, sensing=np.ones((K, N)))
    mask = _in_range()
    bad = z.copy()
    k, i = np.argwhere(mask)[-1]
    bad[k, i] = np.nan  # an agent in range with no number
    with pytest.raises(ValueError, match=r"z \(where the agent senses\)"):
        fusion.track(filt, np.zeros(4), np.eye(4), bad, sensing=mask)
