"""fusion.track: the one run loop for a user's own sensor network, on a fixed or a switching graph."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from mascore import fusion, fusion_forwarding, graphs, kalman, sensor_network

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


# --------------------------------------------------------------------------------------------
# per-step values: H_i(k) and R_i(k)

ALL_FILTERS = FILTERS + [fusion_forwarding.KalmanConsensusNetworkFilter, fusion_forwarding.SetMembershipForwardingFilter]


def _turning():
    """Each agent's row turns with time (a bearing-like sensor), its variance grows and shrinks: (K, q, n), (K, q, q)."""
    angle = 0.3 * np.arange(K)[:, None] + np.arange(N)[None, :]           # (K, N)
    H = np.zeros((K, N, 4))
    H[:, :, 0], H[:, :, 1] = np.cos(angle), np.sin(angle)
    variance = 0.04 * (1.0 + 0.5 * np.sin(0.5 * np.arange(K)[:, None] + np.arange(N)[None, :])) ** 2
    return H, variance[:, :, None] * np.eye(N)


@pytest.mark.parametrize("make", ALL_FILTERS)
def test_per_step_values_equal_to_the_models_give_the_fixed_run_bit_for_bit(make, monkeypatch):
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=8, n_runs=2)
    filt = make(model)
    H = np.broadcast_to(model.H_stacked, (K, N, 4))
    R = np.broadcast_to(model.R_stacked, (K, N, N))
    rebuilt = []
    original = sensor_network.SensorNetworkModel._with_stacked_sensing
    monkeypatch.setattr(sensor_network.SensorNetworkModel, "_with_stacked_sensing",
                        lambda self, *a, **kw: rebuilt.append(1) or original(self, *a, **kw))
    for given in (None, _switching()):
        x_fixed, P_fixed = fusion.track(filt, np.zeros(4), np.eye(4), z, given)
        for values in ({"H": H}, {"R": R}, {"H": H, "R": R}):
            x, P = fusion.track(filt, np.zeros(4), np.eye(4), z, given, **values)
            assert x.tobytes() == x_fixed.tobytes() and P.tobytes() == P_fixed.tobytes()
    assert not rebuilt  # the fast path: values that never change rebuild nothing
    x, P = fusion.track(filt, np.zeros(4), np.eye(4), z, H=H, R=R, sensing=_in_range())
    x_mask, P_mask = fusion.track(filt, np.zeros(4), np.eye(4), z, sensing=_in_range())
    assert x.tobytes() == x_mask.tobytes() and P.tobytes() == P_mask.tobytes()


@pytest.mark.parametrize("make", ALL_FILTERS)
def test_per_step_values_are_the_filter_of_each_steps_model(make):
    """An independent loop: one model per step built from H(k), R(k) by the full constructor, predict and update."""
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=9, n_runs=2)
    H, R = _turning()
    H[4] = model.H_stacked                                                 # a step with the model's values
    R[4] = model.R_stacked
    mask = _in_range()
    x, P = fusion.track(make(model), np.zeros(4), np.eye(4), z, _switching(), sensing=mask, H=H, R=R)
    xk, Pk = model.check_state(np.zeros(4), np.eye(4), per_agent=make(model)._per_agent)
    for k, A in enumerate(_switching()):
        if not mask[k].any():
            xk, Pk = make(model).predict(xk, Pk)
        else:
            f = make(sensor_network.SensorNetworkModel(
                model.F, model.Q, [H[k][[i]] if mask[k, i] else np.zeros((0, 4)) for i in range(N)],
                [R[k][[i]][:, [i]] if mask[k, i] else None for i in range(N)], A))
            xk, Pk = f.update(*f.predict(xk, Pk), z[k][..., mask[k]])
        np.testing.assert_array_equal(x[k], xk)
        np.testing.assert_array_equal(P[k], Pk)


def test_per_step_H_is_a_kalman_filter_written_by_hand():
    """The centralized filter with H(k), R(k) against the textbook equations, in plain numpy."""
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=10)
    H, R = _turning()
    x, P = fusion.track(fusion.CentralizedFilter(model), np.zeros(4), np.eye(4), z, H=H, R=R)
    F, Q = model.F, model.Q
    xk, Pk = np.zeros(4), np.eye(4)
    for k in range(K):
        xk, Pk = F @ xk, F @ Pk @ F.T + Q
        gain = Pk @ H[k].T @ np.linalg.inv(H[k] @ Pk @ H[k].T + R[k])
        xk, Pk = xk + gain @ (z[k] - H[k] @ xk), (np.eye(4) - gain @ H[k]) @ Pk
        np.testing.assert_allclose(x[k], xk, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(P[k], Pk, rtol=1e-9, atol=1e-12)
    x_fixed = fusion.track(fusion.CentralizedFilter(model), np.zeros(4), np.eye(4), z)[0]
    assert np.abs(x - x_fixed).max() > 1e-2  # the values were used


def test_the_centralized_filter_is_consistent_when_the_noise_grows_with_range():
    """Sensors whose noise standard deviation grows with their distance to the target: told each step's R, the
    Kalman filter's average NEES lies in its chi-square interval; told the noise of a target at the sensor, it is
    overconfident (above it)."""
    runs, steps, n_sensors = 60, 30, 4
    sensors = np.array([[-8.0, -8.0], [8.0, -8.0], [8.0, 8.0], [-8.0, 8.0]])  # m
    F = np.block([[np.eye(2), 0.5 * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    Q = np.diag([1e-3, 1e-3, 1e-2, 1e-2])
    position = np.hstack([np.eye(2), np.zeros((2, 2))])
    floor, slope = 0.1, 0.08                                                 # sigma = floor + slope d (m)
    model = sensor_network.SensorNetworkModel(F, Q, [position] * n_sensors, [floor**2 * np.eye(2)] * n_sensors,
                                              graphs.ring_graph(n_sensors))
    x0, P0 = np.array([-5.0, 0.0, 0.5, 0.1]), np.diag([1.0, 1.0, 0.1, 0.1])
    rng = np.random.default_rng(2031)
    x_true, _ = model.simulate(x0, P0, steps, rng, n_runs=runs)             # (K + 1, runs, 4)
    d = np.linalg.norm(x_true[1:, :, None, :2] - sensors, axis=-1)          # (K, runs, sensors)
    sigma = np.repeat(floor + slope * d, 2, axis=-1)                        # (K, runs, 2 per sensor)
    z = np.tile(x_true[1:, :, :2], n_sensors) + sigma * rng.standard_normal(sigma.shape)
    cen = fusion.CentralizedFilter(model)
    x, P = fusion.track(cen, x0, P0, z, R=sigma[..., None] ** 2 * np.eye(2 * n_sensors))  # R (K, runs, 8, 8)
    anees_told = kalman.nees(x_true[1:] - x, P).mean(axis=1)                            # (K,): over the runs
    x, P = fusion.track(cen, x0, P0, z)
    anees_floor = kalman.nees(x_true[1:] - x, P[:, None]).mean(axis=1)
    low, high = kalman.nees_interval(dof=4, n_runs=runs)  # of one step's average; the time average varies less
    assert low <= anees_told[5:].mean() <= high, (low, anees_told[5:].mean(), high)
    assert np.mean((anees_told >= low) & (anees_told <= high)) >= 0.8
    assert anees_floor[5:].mean() > 2 * high


def test_bad_per_step_values_are_refused_by_name_and_step_before_any_step(monkeypatch):
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=0)
    filt = fusion.ConsensusOnInformationFilter(model, 2)
    steps = []
    monkeypatch.setattr(fusion.ConsensusOnInformationFilter, "predict",
                        lambda self, x, P: steps.append(1) or fusion._NetworkFilter.predict(self, x, P))
    H, R = _turning()
    with pytest.raises(ValueError, match=r"H must be \(K, \.\.\., 5, 4\) with K = 12"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, H=H[:-1])
    with pytest.raises(ValueError, match=r"R must be \(K, \.\.\., 5, 5\) with K = 12"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, R=R[:, :4, :4])
    with pytest.raises(ValueError, match=r"x0 and z .* and H and R .* do not broadcast"):
        fusion.track(filt, np.zeros(4), np.eye(4), np.stack([z, z], axis=1), R=np.stack([R, R, R], axis=1))
    with pytest.raises(TypeError, match=r"H must be an array of real numbers"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, H="H")
    bad = H.copy()
    bad[K - 1, 2, 0] = np.nan
    with pytest.raises(ValueError, match=r"H\[11\] \(step 11\) contains NaN"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, H=bad)
    mask = np.ones((K, N), dtype=bool)
    mask[K - 1, 2] = False                                                  # the NaN row is not read
    fusion.track(filt, np.zeros(4), np.eye(4), z, H=bad, sensing=mask)
    bad = R.copy()
    bad[7, 1, 3] = bad[7, 3, 1] = 0.01
    with pytest.raises(ValueError, match=r"R\[7\] \(step 7\) must be block diagonal"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, R=bad)
    bad = R.copy()
    bad[9, 3, 3] = -0.1
    with pytest.raises(ValueError, match=r"R\[9\] \(step 9\), agent 3's block \[3:4, 3:4\], must be positive definite"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, R=bad)
    bad[9, 3, 3] = np.inf
    with pytest.raises(ValueError, match=r"R\[9\] \(step 9\), agent 3's block .* NaN or infinite"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, R=bad)
    bad[9, 3, 3] = 1e-320                                                   # positive, but its inverse overflows
    with pytest.raises(ValueError, match=r"step 9: .*information matrices"):
        fusion.track(filt, np.zeros(4), np.eye(4), z, R=bad)
    steps.clear()
    fusion.track(filt, np.zeros(4), np.eye(4), z, R=R)
    assert len(steps) == K   # the counter counts: no step ran in the refusals above


def test_with_sensing_is_the_constructor():
    model = _model()
    H, R = _turning()
    Hs, Rs = [H[3][[i]] for i in range(N)], [R[3][[i]][:, [i]] for i in range(N)]
    new = model.with_sensing(Hs, Rs)
    built = sensor_network.SensorNetworkModel(model.F, model.Q, Hs, Rs, model.adjacency)
    assert new == built
    for name in ("information_matrices", "H_stacked", "R_stacked", "weights"):
        assert getattr(new, name).tobytes() == getattr(built, name).tobytes()
    with pytest.raises(ValueError, match=r"R\[2\] must be positive definite"):
        model.with_sensing(Hs, Rs[:2] + [-Rs[2]] + Rs[3:])
    with pytest.raises(ValueError, match=r"H must hold one matrix per agent"):
        model.with_sensing(Hs[:-1], Rs)


@pytest.mark.parametrize("make", FILTERS + [fusion_forwarding.KalmanConsensusNetworkFilter])
def test_per_run_values_in_one_call_are_one_call_per_run(make):
    """H and R with a run axis (a range to each run's own target): the runs of one call are the calls of each run."""
    model = _model()
    runs = 3
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=11, n_runs=runs)
    H, R = _turning()
    scale = 1.0 + np.arange(runs)[None, :, None, None]                     # each run its own noise level
    H_runs, R_runs = np.broadcast_to(H[:, None], (K, runs, N, 4)), R[:, None] * scale
    mask = _in_range()
    x, P = fusion.track(make(model), np.zeros(4), np.eye(4), z, _switching(), sensing=mask, H=H_runs, R=R_runs)
    assert P.shape[:2] == (K, runs)
    for r in range(runs):
        x_r, P_r = fusion.track(make(model), np.zeros(4), np.eye(4), z[:, r], _switching(), sensing=mask, H=H,
                                R=R_runs[:, r])
        np.testing.assert_allclose(x[:, r], x_r, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(P[:, r], P_r, rtol=1e-10, atol=1e-12)


def test_the_set_membership_filter_refuses_per_run_values_by_name():
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=12, n_runs=2)
    _, R = _turning()
    smf = fusion_forwarding.SetMembershipForwardingFilter(model)
    with pytest.raises(ValueError, match=r"filt: a SetMembershipForwardingFilter takes one H and R per step for all runs"):
        fusion.track(smf, np.zeros(4), smf.initial_shape(np.eye(4)), z, R=np.stack([R, 2 * R], axis=1))
    fusion.track(smf, np.zeros(4), smf.initial_shape(np.eye(4)), z, R=R)   # one R per step: taken


def test_values_that_repeat_are_built_once_per_call(monkeypatch):
    model = _model()
    _, z = model.simulate(np.zeros(4), np.eye(4), K, rng=15)
    built = []
    original = sensor_network.SensorNetworkModel._with_stacked_sensing
    monkeypatch.setattr(sensor_network.SensorNetworkModel, "_with_stacked_sensing",
                        lambda self, *a: built.append(1) or original(self, *a))
    R = np.broadcast_to(model.R_stacked, (K, N, N)) * np.where(np.arange(K) % 2, 1.0, 3.0)[:, None, None]
    x, P = fusion.track(fusion.ConsensusOnInformationFilter(model, 2), np.zeros(4), np.eye(4), z, R=R)
    assert len(built) == 1          # the odd steps are the model's; the even ones share one R
    twice = sensor_network.SensorNetworkModel(model.F, model.Q, model.H, [3.0 * r for r in model.R], model.adjacency)
    f = fusion.ConsensusOnInformationFilter(twice, 2)
    g = fusion.ConsensusOnInformationFilter(model, 2)
    xk, Pk = model.check_state(np.zeros(4), np.eye(4))
    for k in range(K):
        step = g if k % 2 else f
        xk, Pk = step.update(*step.predict(xk, Pk), z[k])
    np.testing.assert_array_equal(x[-1], xk)
    np.testing.assert_array_equal(P[-1], Pk)
