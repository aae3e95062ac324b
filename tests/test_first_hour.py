"""A researcher's first hour: the confirmed defects and the ecosystem (networkx, python-control), each pinned."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from mascore import flocking, graphs, kalman, lqr, rendezvous, sensing
from mascore import set_membership as sm
from mascore.exceptions import RiccatiError

control = pytest.importorskip("control")

A2 = np.array([[0.0, 1.0], [-1.0, -0.5]])
B2 = np.array([[0.0], [1.0]])


# --------------------------------------------------------------------------- confirmed defects


def test_distributed_gain_checks_its_blocks_when_built():
    with pytest.raises(TypeError, match="K_self"):
        lqr.DistributedGain("abc", [[1, 2], [3]])
    with pytest.raises(TypeError, match="K_coupling"):
        lqr.DistributedGain([[1.0, 2.0]], [[1, 2], [3]])
    with pytest.raises(ValueError, match="K_coupling"):
        lqr.DistributedGain([[1.0, 2.0]], [[1.0, 2.0, 3.0]])
    with pytest.raises(ValueError, match="K_self"):
        lqr.DistributedGain([[np.nan, 2.0]], [[1.0, 2.0]])
    Ks = np.array([[1.0, 2.0]])
    gain = lqr.DistributedGain(Ks, [[0.5, 0.0]])
    Ks[0, 0] = 99.0  # the gain keeps its own read-only copy
    assert gain.K_self[0, 0] == 1.0 and not gain.K_self.flags.writeable


@pytest.mark.parametrize("solve", [lqr.lqr, lqr.dlqr])
@pytest.mark.parametrize("which", ["A", "B", "Q", "R"])
def test_lqr_names_an_argument_that_overflows(solve, which):
    args = dict(A=0.5 * A2, B=B2, Q=np.eye(2), R=np.eye(1))
    args[which] = 1e300 * args[which]
    with pytest.raises(ValueError, match=f"^{which} has entries of magnitude"):
        solve(args["A"], args["B"], args["Q"], args["R"])


def test_set_membership_predict_overflow_names_A_instead_of_a_nan_shape():
    with pytest.raises(ValueError, match="A has entries up to 1e\\+300"):
        sm.predict(np.zeros(2), np.eye(2), A=1e300 * np.array([[1.0, 0.1], [0.0, 1.0]]), G=np.eye(2),
                   Q=0.01 * np.eye(2))


def test_flock_statistics_refuse_partial_nan_and_keep_missing_teams():
    X = np.array([[0.0, 0.0, 1.0, 0.0], [2.0, 0.0, 1.0, 0.0]])
    bad = X.copy()
    bad[0, 0] = np.nan
    for f in (flocking.flock_spread, flocking.max_distance_from_centre):
        with pytest.raises(ValueError, match="X contains NaN"):
            f(bad)
        with pytest.raises(ValueError, match=r"team \(1,\)"):
            f(np.stack([X, bad]))
    std_p, _ = flocking.flock_spread(np.stack([X, np.full_like(X, np.nan)]))  # a whole missing team: NaN
    assert std_p[0] == 1.0 and np.isnan(std_p[1])


def test_nees_overflow_is_refused_not_inf():
    with pytest.raises(ValueError, match="NEES overflows"):
        kalman.nees([1e300, 0.0], np.eye(2))
    assert float(kalman.nees([1e100, 0.0], np.eye(2))) == pytest.approx(1e200)


# --------------------------------------------------------------------------- python-control


@pytest.mark.parametrize("cross", [False, True])
def test_lqr_and_dlqr_match_python_control(cross):
    rng = np.random.default_rng(0)
    A, B = rng.standard_normal((3, 3)), rng.standard_normal((3, 2))
    Q, R = np.eye(3), np.diag([1.0, 2.0])
    extra = (0.1 * rng.standard_normal((3, 2)),) if cross else ()
    for ours, theirs in ((lqr.lqr, control.lqr), (lqr.dlqr, control.dlqr)):
        K, S, E = ours(A, B, Q, R, *extra)
        Kc, Sc, Ec = theirs(A, B, Q, R, *extra)
        np.testing.assert_allclose(K, Kc, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(S, Sc, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(np.sort_complex(E), np.sort_complex(Ec), rtol=1e-7, atol=1e-9)


def test_lqr_accepts_a_state_space_system_and_N_by_keyword():
    rng = np.random.default_rng(1)
    A, B = rng.standard_normal((3, 3)), rng.standard_normal((3, 1))
    N = 0.05 * rng.standard_normal((3, 1))
    sys_c = control.ss(A, B, np.eye(3), 0)
    sys_d = control.ss(A, B, np.eye(3), 0, 0.1)
    np.testing.assert_allclose(lqr.lqr(sys_c, np.eye(3), np.eye(1), N=N)[0],
                               control.lqr(sys_c, np.eye(3), np.eye(1), N)[0], rtol=1e-7)
    np.testing.assert_allclose(lqr.dlqr(sys_d, np.eye(3), np.eye(1), N)[0],
                               control.dlqr(sys_d, np.eye(3), np.eye(1), N)[0], rtol=1e-7)
    # a discrete-time system given to lqr is solved in discrete time, as python-control does
    np.testing.assert_allclose(lqr.lqr(sys_d, np.eye(3), np.eye(1))[0],
                               control.lqr(sys_d, np.eye(3), np.eye(1))[0], rtol=1e-7)
    with pytest.raises(ValueError, match="continuous-time"):
        lqr.dlqr(sys_c, np.eye(3), np.eye(1))
    np.testing.assert_allclose(lqr.lqr(sys_c, Q=np.eye(3), R=np.eye(1), N=N)[0],
                               control.lqr(sys_c, np.eye(3), np.eye(1), N)[0], rtol=1e-7)
    with pytest.raises(TypeError, match="N given twice"):
        lqr.lqr(sys_c, np.eye(3), np.eye(1), N, N=N)
    with pytest.raises(ValueError, match="N: the cost weight"):
        lqr.lqr(A, B, np.eye(3), np.eye(1), 10 * np.ones((3, 1)))
    with pytest.raises(ValueError, match="Incompatible dimensions of N"):
        lqr.lqr(A, B, np.eye(3), np.eye(1), np.ones((2, 1)))


def test_lqr_still_raises_riccati_error_for_an_ill_posed_problem():
    with pytest.raises((RiccatiError, ValueError)):
        lqr.lqr([[0.0, 1.0], [-1.0, 0.0]], B2, np.zeros((2, 2)), [[1.0]])


# --------------------------------------------------------------------------- networkx


def test_networkx_graphs_are_accepted_where_an_adjacency_is():
    G = nx.connected_watts_strogatz_graph(6, 2, 0.3, seed=3)
    A = nx.to_numpy_array(G, nodelist=range(6))
    np.testing.assert_array_equal(graphs.laplacian(G), graphs.laplacian(A))
    assert graphs.is_connected(G) == graphs.is_connected(A)
    np.testing.assert_array_equal(sensing.sensing_mask(G), sensing.sensing_mask(A))
    D = nx.DiGraph([(0, 1), (1, 2)])  # 0 -> 1 -> 2: agent 1 hears 0, agent 2 hears 1
    np.testing.assert_array_equal(graphs.laplacian(D), [[0, 0, 0], [-1, 1, 0], [0, -1, 1]])
    W = nx.Graph()
    W.add_edge(1, 0, weight=2.5)
    np.testing.assert_array_equal(graphs.laplacian(W), [[2.5, -2.5], [-2.5, 2.5]])
    stack = [nx.cycle_graph(4), nx.path_graph(4)]
    assert graphs.graph_union(stack).shape == (4, 4)
    with pytest.raises(ValueError, match="self-loops"):
        graphs.laplacian(nx.Graph([(0, 0), (0, 1)]))


def test_graph_round_trip_through_to_networkx():
    A = graphs.adjacency_from_edges(4, [(0, 1), (1, 2, 2.0), (3, 0)], directed=True)
    np.testing.assert_array_equal(graphs.laplacian(graphs.to_networkx(A)), graphs.laplacian(A))
    np.testing.assert_array_equal(graphs.from_networkx(graphs.to_networkx(A)), A)
    assert graphs.from_networkx([nx.cycle_graph(3), nx.path_graph(3)]).shape == (2, 3, 3)
    with pytest.raises(TypeError, match="graph must be a networkx graph"):
        graphs.from_networkx(A)


def test_rendezvous_takes_a_networkx_graph():
    from mascore import agents

    di = agents.double_integrator(2, 0.1)
    model = rendezvous.RendezvousModel(di.A, di.B, rendezvous.rendezvous_gain(0.5, 1.5, 2), Q=1e-4 * np.eye(4),
                                       R=0.01 * np.eye(4), dt=0.1)
    x0 = np.random.default_rng(1).normal(size=(5, 4))
    a = rendezvous.simulate_rendezvous(0, model, x0, nx.cycle_graph(5), 5, "true")
    b = rendezvous.simulate_rendezvous(0, model, x0, graphs.ring_graph(5), 5, "true")
    np.testing.assert_array_equal(a.states, b.states)


# --------------------------------------------------------------------------- rendezvous: estimates, time base, graph


def _rendezvous_case(dt=0.1):
    from mascore import agents

    agent = agents.double_integrator(2, dt)
    K = rendezvous.rendezvous_gain(0.5, 1.5, 2)
    return agent, K, 1e-4 * np.eye(4), 0.01 * np.eye(4)


def test_the_written_out_loop_is_simulate_rendezvous():
    """The loop of simulate_rendezvous's docstring (and the apply chapter), run by hand, gives its states and estimates."""
    from mascore import distributed_kf, team_model

    agent, K, Q, R = _rendezvous_case()
    model = rendezvous.RendezvousModel.from_agent(agent, K, Q, R)
    N, T = 5, 15
    adjacency = nx.cycle_graph(N)
    x0 = np.random.default_rng(1).normal(scale=5.0, size=(N, 4))
    run = rendezvous.simulate_rendezvous(7, model, x0, adjacency, T, "estimation", x_hat0=x0.ravel(), P0=np.eye(4),
                                         return_estimates=True)
    proc_rng, meas_rng = np.random.default_rng(7).spawn(2)
    x, L = x0[None], graphs.laplacian(adjacency)
    team = distributed_kf.TeamFilter(team_model.team_filter_model(agent.A, agent.B, K, Q, R, N), L,
                                     x0.ravel()[None], np.eye(4), mode="eb")
    Z, S = sensing.measure(meas_rng, x, adjacency, R)
    estimates = [team.X_hat.copy()]
    for _ in range(T):
        U = rendezvous.consensus_control(team.X_hat, L, K)
        x = rendezvous.propagate_team(proc_rng, x, U, agent.A, agent.B, Q)
        team.predict()
        Z, S = sensing.measure(meas_rng, x, adjacency, R)
        team.update(Z, S)
        estimates.append(team.X_hat.copy())
    assert run.estimates.shape == (T + 1, N, N, 4)
    np.testing.assert_array_equal(run.states[-1], x[0])
    np.testing.assert_array_equal(run.estimates, np.array(estimates)[:, 0])
    # the error statistics are those of the returned estimates
    err = run.states[:, None, :, :2] - run.estimates[..., :2]
    np.testing.assert_allclose(run.pos_error, np.sqrt((err**2).sum(axis=(-1, -2))), rtol=1e-12)
    assert rendezvous.simulate_rendezvous(7, model, x0, adjacency, 3, "estimation", x_hat0=x0.ravel(),
                                          P0=np.eye(4)).estimates is None


def test_rendezvous_model_refuses_a_dt_that_contradicts_A():
    agent, K, Q, R = _rendezvous_case(dt=0.05)
    with pytest.raises(ValueError, match=r"dt = 0.1 s contradicts A: .* h = 0.05 s"):
        rendezvous.RendezvousModel(agent.A, agent.B, K, Q, R, 0.1)
    assert rendezvous.RendezvousModel(agent.A, agent.B, K, Q, R, 0.05).dt == 0.05
    assert rendezvous.RendezvousModel.from_agent(agent, K, Q, R).dt == 0.05
    with pytest.raises(ValueError, match="contradicts the agent's sampling time"):
        rendezvous.RendezvousModel.from_agent(agent, K, Q, R, dt=0.1)
    from mascore.agents import LTIAgent

    with pytest.raises(ValueError, match="carries no sampling time"):  # plain arrays: no time base at all
        rendezvous.RendezvousModel.from_agent(LTIAgent(np.array(agent.A), np.array(agent.B)), K, Q, R)
    assert LTIAgent(agent.A, agent.B).dt == 0.05  # the A of a sampled agent remembers its dt


def test_lti_agent_checks_its_continuous_time_origin():
    from mascore.agents import LTIAgent

    A_c, B_c = [[0.0, 1.0], [0.0, -2.0]], [[0.0], [1.0]]
    agent = LTIAgent.from_continuous(A_c, B_c, 0.05)
    assert agent.dt == 0.05
    LTIAgent(agent.A, agent.B, dt=0.05, A_c=A_c, B_c=B_c)  # consistent: accepted
    with pytest.raises(ValueError, match="dt = 0.1 s contradicts A, which was sampled over dt = 0.05 s"):
        LTIAgent(agent.A, agent.B, dt=0.1, A_c=A_c, B_c=B_c)
    with pytest.raises(ValueError, match="A is not the zero-order-hold sampling"):  # plain arrays: checked by zoh
        LTIAgent(np.array(agent.A), agent.B, dt=0.1, A_c=A_c, B_c=B_c)
    with pytest.raises(ValueError, match="both A_c and B_c"):
        LTIAgent(agent.A, agent.B, dt=0.05, A_c=A_c)


def test_a_disconnected_graph_is_named_as_such():
    agent, K, Q, R = _rendezvous_case()
    model = rendezvous.RendezvousModel.from_agent(agent, K, Q, R)
    split = nx.union(nx.path_graph(3), nx.path_graph([3, 4, 5]))
    x0 = np.zeros((6, 4))
    with pytest.raises(ValueError, match=r"disconnected graph \(2 components: \[\[0, 1, 2\], \[3, 4, 5\]\]\)"):
        rendezvous.simulate_rendezvous(0, model, x0, split, 3, "estimation", x_hat0=x0.ravel(), P0=np.eye(4))
    assert [c.tolist() for c in graphs.connected_components(split)] == [[0, 1, 2], [3, 4, 5]]
    from mascore import synchronization as sync

    with pytest.raises(ValueError, match=r"Assumption 4 fails: .* disconnected graph, 2 components"):
        sync.design_synchronization(np.eye(2), np.eye(2), np.eye(2), split, np.ones(6))


# --------------------------------------------------------------------------- synchronization design without a grid search


def test_default_circle_is_the_smallest_ratio_and_the_design_uses_it():
    from mascore import synchronization as sync

    ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)
    pin = [1.0, 0.0, 0.0, 0.0]
    c0, r0 = sync.default_circle(ring, pin)
    eigs = np.linalg.eigvals(sync.pinned_interaction_matrix(ring, pin))
    assert sync.circle_contains(eigs, c0, r0).all()
    centres = np.linspace(0.2, 2.0, 20001)  # brute force over the centre: no circle has a smaller r0 / c0
    best = np.min(np.max(np.abs(eigs[None] - centres[:, None]), axis=1) / centres)
    assert r0 / c0 <= best * (1 + 1e-5)
    A, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), 0.1 * np.eye(2)
    d = sync.design_synchronization(A, np.eye(2), Q, ring, pin)
    assert (d.c0, d.r0) == (c0, r0) and d.c == pytest.approx(1 / c0) and d.rho < 1
    d_c0 = sync.design_synchronization(A, np.eye(2), Q, ring, pin, c0=2 / 3)  # smallest radius about c0
    assert d_c0.in_circle.all() and d_c0.r0 < 0.6
    with pytest.raises(ValueError, match="r0 was given without c0"):
        sync.design_synchronization(A, np.eye(2), Q, ring, pin, r0=0.6)
    # real spectrum [a, b]: the circle is ((a + b) / 2, (b - a) / 2)
    path = nx.path_graph(3)
    c0, r0 = sync.default_circle(path, [1.0, 0.0, 0.0])
    lam = np.sort(np.linalg.eigvals(sync.pinned_interaction_matrix(path, [1.0, 0.0, 0.0])).real)
    assert c0 == pytest.approx((lam[0] + lam[-1]) / 2, rel=1e-6) and r0 == pytest.approx((lam[-1] - lam[0]) / 2, rel=1e-5)


# --------------------------------------------------------------------------- EKF flocking: Q is a tuning knob


def _flock_case():
    from mascore.flocking import FlockingGains

    gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
    X = np.array([[[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]]])
    X = X + np.random.default_rng(0).normal(size=(3, 3, 4))  # three runs
    X_hat0 = X[:, None] + np.random.default_rng(1).normal(size=(3, 3, 3, 4))
    return gains, X, X_hat0, np.eye(12)


def test_recording_the_nees_changes_nothing_else_and_q_filter_defaults_to_q():
    from mascore import distributed_ekf as dekf

    gains, X, X_hat0, S0 = _flock_case()
    args = (X, X_hat0, S0, 30, 0.1, gains, 0.01 * np.eye(4), np.eye(4))
    a = dekf.simulate_estimation_based_flocking(*args, np.random.default_rng(5), 150.0)
    b = dekf.simulate_estimation_based_flocking(*args, np.random.default_rng(5), 150.0, record_nees=True,
                                                Q_filter=0.01 * np.eye(4))
    assert a.nees is None and b.nees.shape == (3, 31) and a.estimates is None
    c = dekf.simulate_estimation_based_flocking(*args, np.random.default_rng(5), 150.0, return_estimates=True)
    assert c.estimates.shape == (3, 31, 3, 3, 4)
    np.testing.assert_array_equal(c.estimates[:, :, 0], a.X_hat)  # the observer's row is the recorded X_hat
    np.testing.assert_array_equal(c.X, a.X)
    for name in ("X", "X_hat", "position_variance", "rms_error"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    # the recorded NEES is kalman.nees of the observer's error against its updated covariance at the last step
    assert np.all(b.nees > 0) and np.all(np.isfinite(b.nees))


def test_nees_against_q_shows_the_knob():
    from mascore import distributed_ekf as dekf

    gains, X, X_hat0, S0 = _flock_case()
    q = [1e-3, 1e-1]
    # model-matched at every q: far overconfident at q = 1e-3 (linearization error not in Q), consistent at 0.1
    ratio = dekf.nees_against_q(q, X, X_hat0, S0, 60, 0.1, gains, np.eye(4), 150.0, seed=2, transient=10)
    assert ratio.shape == (2,) and ratio[0] > 10 * ratio[1] and 0.5 < ratio[1] < 2
    # the truth at 1e-3, the filter told 0.1: inflating the assumed Q removes the overconfidence
    tuned = dekf.nees_against_q(q, X, X_hat0, S0, 60, 0.1, gains, np.eye(4), 150.0, seed=2, q_true=1e-3, transient=10)
    assert tuned[0] == ratio[0] and tuned[1] < 2
    np.testing.assert_array_equal(ratio, dekf.nees_against_q(q, X, X_hat0, S0, 60, 0.1, gains, np.eye(4), 150.0,
                                                             seed=2, transient=10))  # the seed fixes it
    with pytest.raises(ValueError, match="q_values"):
        dekf.nees_against_q([0.0], X, X_hat0, S0, 10, 0.1, gains, np.eye(4), 150.0, seed=2)
    with pytest.raises(ValueError, match="q_true"):
        dekf.nees_against_q([1.0], X, X_hat0, S0, 10, 0.1, gains, np.eye(4), 150.0, seed=2, q_true=-1.0)


def test_networkx_graphs_work_across_the_modules():
    """One conversion point (float_array) serves every module that takes an adjacency."""
    from mascore import consensus, observers
    from mascore import synchronization as sync
    from mascore.flocking import FlockingGains

    G = nx.cycle_graph(4)
    A = graphs.ring_graph(4)
    gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
    X = np.random.default_rng(0).normal(scale=50.0, size=(4, 4))
    np.testing.assert_array_equal(flocking.flocking_control(X, gains, adjacency=G),
                                  flocking.flocking_control(X, gains, adjacency=A))
    A_di, B_di = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])
    w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    np.testing.assert_array_equal(lqr.top_down_lqr(A_di, B_di, **w, adjacency=G).K_coupling,
                                  lqr.top_down_lqr(A_di, B_di, **w, adjacency=A).K_coupling)
    pin = [1.0, 0.0, 0.0, 0.0]
    np.testing.assert_array_equal(sync.pinned_interaction_matrix(G, pin), sync.pinned_interaction_matrix(A, pin))
    law_nx, law = sync.SynchronizationLaw(G, pin, np.eye(2), 1.0), sync.SynchronizationLaw(A, pin, np.eye(2), 1.0)
    np.testing.assert_array_equal(law_nx(X[:, :2], [0.0, 0.0]), law(X[:, :2], [0.0, 0.0]))
    assert consensus.union_condition_holds([G, G], window=1) == consensus.union_condition_holds(np.stack([A, A]), 1)
    C = np.array([[1.0, 0.0]])
    a = observers.distributed_observer([[0.0, 1.0], [-1.0, -0.1]], np.eye(2), C, np.eye(1), 0.5 * np.eye(1), np.eye(2), G)
    b = observers.distributed_observer([[0.0, 1.0], [-1.0, -0.1]], np.eye(2), C, np.eye(1), 0.5 * np.eye(1), np.eye(2), A)
    np.testing.assert_allclose(a.L, b.L)


# --------------------------------------------------------------------------- what Q and R are, in every signature


def test_every_q_and_r_parameter_says_what_it_is():
    """Covariance, cost weight, ellipsoid shape or noise intensity: every public docstring says which."""
    import importlib
    import inspect

    docscrape = pytest.importorskip("numpydoc.docscrape")
    names = {"Q", "R", "Q1", "Q2", "Q_team", "Omega", "Q_filter"}
    words = ("covariance", "weight", "shape", "intensity", "as in")
    exempt = {("flocking.FlockingGains", "R")}  # the spring's rest length (m), Song et al.'s calligraphic R
    missing = []
    for mod in ("kalman", "team_model", "distributed_kf", "centralized_team_filter", "team_observability",
                "rendezvous", "sensing", "distributed_ekf", "flocking", "consensus",
                "set_membership", "ellipsoids", "synchronization", "lqr", "observers", "noise"):
        module = importlib.import_module(f"mascore.{mod}")
        for name in module.__all__:
            obj = getattr(module, name)
            targets = []
            if inspect.isclass(obj):
                targets.append((f"{mod}.{name}", docscrape.ClassDoc(obj)))
                targets += [(f"{mod}.{name}.{m}", docscrape.FunctionDoc(f))
                            for m, f in inspect.getmembers(obj, inspect.isfunction) if not m.startswith("_") and f.__doc__]
            elif callable(obj):
                targets.append((f"{mod}.{name}", docscrape.FunctionDoc(obj)))
            for where, doc in targets:
                for param in doc["Parameters"]:
                    for pname in (x.strip() for x in param.name.split(",")):
                        text = " ".join(param.desc).lower()
                        if pname in names and (where, pname) not in exempt and not any(w in text for w in words):
                            missing.append(f"{where}({pname})")
    assert not missing, missing
