"""Spoiled inputs of mascore.consensus, mascore.flocking and mascore.distributed_ekf (issue 14, "Nothing silent").

For every public function: each argument spoiled in turn (NaN/inf entries, a string, wrong shapes,
indefinite or non-symmetric covariances, dt <= 0, counts 0/negative/float, a negative seed, a Laplacian
for an adjacency) raises ValueError/TypeError naming the argument. Valid finite inputs never give
NaN/inf (hypothesis). The hangs of the issue are regression tests with a time bound; degenerate but
meaningful inputs (one agent, an isolated agent, zero noise) have defined behaviour; the filters stay
symmetric positive definite over 10^4 steps.
"""

import re
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mascore import ConsensusBreakdownError, flocking
from mascore import consensus as cs
from mascore import distributed_ekf as dekf
from mascore.flocking import FlockingGains
from mascore.graphs import laplacian, ring_graph

GAINS = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)


def bounded(fn, seconds):
    """Run `fn` in a thread; fail (instead of hanging) if it has not finished after `seconds`."""
    box = {}

    def target():
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed back to the test
            box["error"] = exc

    thread = threading.Thread(target=target, daemon=True)
    start = time.perf_counter()
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"still running after {seconds} s (a hang)"
    return box, time.perf_counter() - start


# --------------------------------------------------------------------------- valid baselines

G3 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])  # a directed ring: 0 hears 1, 1 hears 2, ...
SEQ = np.stack([G3, G3.T, G3, np.zeros((3, 3))])
X3 = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, -1.0, 0.0]])
VIEWS = np.broadcast_to(X3, (3, 3, 4)).copy()
M3 = 12
SIG = np.broadcast_to(np.eye(M3), (3, M3, M3)).copy()
OBS = np.array([[True, True, False], [True, True, True], [False, True, True]])
P2 = np.array([[10.0, 0.0], [0.0, 20.0], [0.0, 0.0]])
V2 = np.array([[1.0, 0.0], [0.0, -1.0], [0.5, 0.5]])

#: function -> (callable, valid kwargs, {argument: kind}); kinds pick the spoils below
BASE = {
    "kalman_consensus_step": (cs.kalman_consensus_step,
                              dict(xi=[0.0, 1.0, 2.0], P=[1.0, 2.0, 0.5], G=G3, Q=0.1, Omega=0.1),
                              dict(xi="array", P="variances", G="graph_n", Q="cov", Omega="cov")),
    "kalman_consensus_step_vector": (cs.kalman_consensus_step,
                                     dict(xi=np.zeros((3, 2)), P=np.broadcast_to(np.eye(2), (3, 2, 2)), G=G3,
                                          Q=0.1 * np.eye(2), Omega=0.1 * np.eye(2), rng=0),
                                     dict(xi="array", P="pd", Q="cov", Omega="cov", rng="rng")),
    "kalman_consensus_discrete": (cs.kalman_consensus_discrete,
                                  dict(xi0=[0.0, 1.0, 2.0], P0=[1.0, 2.0, 0.5], topologies=SEQ, Q=0.1, Omega=0.1,
                                       n_steps=3, rng=1),
                                  dict(xi0="array", P0="variances", topologies="graph_n", Q="cov", Omega="cov",
                                       n_steps="count", rng="rng")),
    "consensus_matrix": (cs.consensus_matrix, dict(P=[1.0, 2.0, 0.5], G=G3, Q=0.1, Omega=0.2),
                         dict(P="variances", G="graph_n", Q="cov", Omega="cov")),
    "error_covariance": (cs.error_covariance, dict(P0=[1.0, 2.0, 0.5], topologies=SEQ, Q=0.1, Omega=0.2),
                         dict(P0="variances", topologies="graph_n", Q="cov", Omega="cov")),
    "kalman_consensus_continuous": (cs.kalman_consensus_continuous,
                                    dict(xi0=[0.0, 1.0, 2.0], P0=[1.0, 2.0, 0.5], topology=G3, t_final=1.0, Q=0.1,
                                         Omega=0.1, t_eval=[0.0, 0.5, 1.0], rtol=1e-6, atol=1e-8),
                                    dict(xi0="array", P0="variances", topology="graph_n", t_final="positive",
                                         Q="cov", Omega="cov", t_eval="array_opt", rtol="positive", atol="positive",
                                         dt="positive")),
    "kalman_consensus_continuous_noisy": (cs.kalman_consensus_continuous,
                                          dict(xi0=[0.0, 1.0, 2.0], P0=[1.0, 2.0, 0.5], topology=G3, t_final=0.1,
                                               Q=0.1, Omega=0.1, rng=2, dt=0.01),
                                          dict(rng="rng", dt="positive")),
    "average_consensus": (cs.average_consensus, dict(xi0=[0.0, 1.0, 2.0], topologies=SEQ, step_size=0.3),
                          dict(xi0="array", topologies="graph_n", step_size="positive", n_steps="count")),
    "central_fusion": (cs.central_fusion, dict(xi0=[0.0, 1.0, 2.0], P0=[1.0, 2.0, 0.5]),
                       dict(xi0="array", P0="variances")),
    "random_pairings": (cs.random_pairings, dict(n_agents=4, n_steps=5, rng=0, size=2),
                        dict(n_agents="count", n_steps="count", rng="rng", max_duration="count", size="count")),
    "periodic_sequence": (cs.periodic_sequence, dict(graphs=SEQ, dwell=2, n_steps=6),
                          dict(graphs="graph", dwell="count", n_steps="count")),
    "spanning_tree_windows": (cs.spanning_tree_windows, dict(adjacencies=SEQ, window=2),
                              dict(adjacencies="graph", window="count")),
    "union_condition_holds": (cs.union_condition_holds, dict(adjacencies=SEQ, window=2),
                              dict(adjacencies="graph", window="count")),
    "spread": (cs.spread, dict(xi=np.arange(6.0).reshape(3, 2)), dict(xi="array")),
    "SwitchingTopology": (cs.SwitchingTopology, dict(times=[0.0, 1.0], graphs=SEQ[:2]),
                          dict(times="array", graphs="graph")),
    "SwitchingTopology.periodic": (cs.SwitchingTopology.periodic, dict(graphs=SEQ, dwell=0.5, t_final=3.0),
                                   dict(graphs="graph", dwell="positive")),
    "phi1": (flocking.phi1, dict(p=P2, beta=0.3), dict(p="array", beta="nonnegative")),
    "phi2": (flocking.phi2, dict(p=P2, v=V2, gains=GAINS), dict(p="array", v="array", gains="gains")),
    "pair_term": (flocking.pair_term, dict(p=P2, v=V2, gains=GAINS), dict(p="array", v="array", gains="gains")),
    "pair_term_jacobian": (flocking.pair_term_jacobian, dict(p=P2, v=V2, gains=GAINS),
                           dict(p="array", v="array", gains="gains")),
    "flocking_control": (flocking.flocking_control, dict(X=X3, gains=GAINS, adjacency=G3 + G3.T),
                         dict(X="array", gains="gains", adjacency="weights")),
    "control_from_views": (flocking.control_from_views, dict(views=VIEWS, gains=GAINS, adjacency=G3 + G3.T),
                           dict(views="array", gains="gains", adjacency="weights")),
    "closed_loop_step": (flocking.closed_loop_step, dict(X=X3, dt=0.1, gains=GAINS),
                         dict(X="array", dt="positive", gains="gains")),
    "closed_loop_jacobian": (flocking.closed_loop_jacobian, dict(X=X3, dt=0.1, gains=GAINS),
                             dict(X="array", dt="positive", gains="gains")),
    "simulate_measured_flocking": (flocking.simulate_measured_flocking,
                                   dict(X0=X3, n_steps=3, dt=0.1, gains=GAINS, Q=0.01 * np.eye(4),
                                        R=0.01 * np.eye(4), rng=0, sensing_range=150.0),
                                   dict(X0="array", n_steps="count", dt="positive", gains="gains", Q="cov",
                                        R="cov", rng="rng", sensing_range="positive")),
    "flock_spread": (flocking.flock_spread, dict(X=X3), dict(X="array_nan_ok")),
    "max_distance_from_centre": (flocking.max_distance_from_centre, dict(X=X3), dict(X="array_nan_ok")),
    "ekf_predict": (dekf.ekf_predict, dict(X_hat=VIEWS, Sigma=SIG, dt=0.1, gains=GAINS, Q_team=0.01 * np.eye(M3)),
                    dict(X_hat="array", Sigma="cov", dt="positive", gains="gains", Q_team="cov")),
    "masked_update": (dekf.masked_update, dict(X_pred=VIEWS, Sigma_pred=SIG, z=VIEWS, observed=OBS, R=np.eye(M3),
                                               agent=np.arange(3)),
                      dict(X_pred="array", Sigma_pred="cov", z="array", observed="mask", R="pd")),
    "ekf_flocking_step": (dekf.ekf_flocking_step,
                          dict(X_pred=VIEWS, Sigma_pred=SIG, z=VIEWS, observed=OBS, R=np.eye(M3), dt=0.1,
                               gains=GAINS, Q_team=0.01 * np.eye(M3)),
                          dict(X_pred="array", Sigma_pred="cov", z="array", observed="mask", R="pd",
                               dt="positive", gains="gains", Q_team="cov")),
    "simulate_estimation_based_flocking": (dekf.simulate_estimation_based_flocking,
                                           dict(X0=X3, X_hat0=VIEWS, Sigma0=np.eye(M3), n_steps=3, dt=0.1,
                                                gains=GAINS, Q=0.01 * np.eye(4), R=np.eye(4), rng=0,
                                                sensing_range=150.0, observer=1),
                                           dict(X0="array", X_hat0="array", Sigma0="cov", n_steps="count",
                                                dt="positive", gains="gains", Q="cov", R="pd", rng="rng",
                                                sensing_range="positive", observer="index")),
}


def _with_entry(value, entry, where=0):
    arr = np.array(value, dtype=float)
    arr.flat[where] = entry
    return arr


def _nonsymmetric(value):
    arr = np.array(value, dtype=float)
    if arr.ndim == 0:
        return None
    arr[..., 0, -1] += 1.0
    return arr


def _spoils(kind, value):
    """(label, spoiled value, exception) for one argument of the given kind."""
    out = []
    if kind in ("array", "array_opt", "array_nan_ok", "variances", "graph", "graph_n", "weights", "cov", "pd"):
        if kind != "array_nan_ok":
            out.append(("nan entry", _with_entry(value, np.nan), ValueError))
        out.append(("inf entry", _with_entry(value, np.inf, -1), ValueError))
        out.append(("string", "array", TypeError))
        if kind not in ("array_opt", "weights"):  # None is valid there (default grid, fully connected)
            out.append(("None", None, TypeError))
    if kind in ("array", "array_opt", "array_nan_ok", "variances", "graph", "graph_n") and np.ndim(value) >= 1:
        out.append(("ragged list", [[0.0, 1.0], [2.0]], (TypeError, ValueError)))
    if kind == "variances":
        out.append(("zero variance", _with_entry(value, 0.0), ValueError))
        out.append(("negative variance", _with_entry(value, -1.0), ValueError))
    if kind in ("cov", "pd"):
        out.append(("negated (indefinite)", -np.asarray(value, dtype=float) - 0.5 * np.eye(np.shape(value)[-1])
                    if np.ndim(value) >= 2 else -abs(float(value)) - 0.5, ValueError))
        nonsym = _nonsymmetric(value)
        if nonsym is not None:
            out.append(("non-symmetric", nonsym, ValueError))
    if kind == "pd":
        out.append(("singular", np.zeros_like(np.asarray(value, dtype=float)), ValueError))
    if kind in ("graph", "graph_n", "weights"):
        A = np.asarray(value, dtype=float)
        L = A.sum(axis=-1)[..., None] * np.eye(A.shape[-1]) - A  # its Laplacian
        out.append(("laplacian for adjacency", L if np.any(A) else L - 0.5 + 0.5 * np.eye(A.shape[-1]), ValueError))
        out.append(("negative weight", np.where(np.eye(A.shape[-1], dtype=bool), 0.0, -1.0) + 0 * A, ValueError))
        if kind != "graph":  # a graph of a given team size
            out.append(("wrong size", np.zeros(A.shape[:-2] + (A.shape[-1] + 1, A.shape[-1] + 1)), ValueError))
    if kind in ("graph", "graph_n"):
        out.append(("self-loop", A + np.eye(A.shape[-1]), ValueError))
    if kind == "mask":
        out.append(("float mask with NaN", _with_entry(np.asarray(value, dtype=float), np.nan), ValueError))
        out.append(("wrong length", np.asarray(value)[..., :-1], ValueError))
    if kind in ("positive", "nonnegative"):
        out += [("nan", float("nan"), ValueError), ("inf", float("inf"), ValueError),
                ("negative", -1.0, ValueError), ("string", "0.1", TypeError)]
        if kind == "positive":
            out.append(("zero", 0.0, ValueError))
    if kind in ("count", "index"):
        out += [("negative", -1, ValueError), ("float", 2.5, TypeError), ("string", "3", TypeError)]
        if kind == "count":
            out.append(("zero", 0, ValueError))
    if kind == "index":
        out.append(("out of range", 3, ValueError))
    if kind == "rng":
        out += [("negative seed", -1, ValueError), ("string seed", "seed", TypeError)]
    if kind == "gains":
        out += [("dict for gains", {"rho3": 1.0}, TypeError)]
    return out


CASES = [
    pytest.param(fname, arg, label, spoiled, exc, id=f"{fname}-{arg}-{label}")
    for fname, (func, kwargs, kinds) in BASE.items()
    for arg, kind in kinds.items()
    for label, spoiled, exc in _spoils(kind, kwargs.get(arg, 1e-3 if kind == "positive" else 5))
]


@pytest.mark.parametrize("fname", list(BASE))
def test_baselines_are_valid_and_finite(fname):
    func, kwargs, _ = BASE[fname]
    out = func(**kwargs)
    flat = [out] if not isinstance(out, tuple) else list(out)
    for value in flat:
        if isinstance(value, (np.ndarray, float)):
            assert np.all(np.isfinite(value))


@pytest.mark.parametrize("fname, arg, label, spoiled, exc", CASES)
def test_spoiled_argument_is_refused_by_name(fname, arg, label, spoiled, exc):
    func, kwargs, _ = BASE[fname]
    trial = dict(kwargs)
    trial[arg] = spoiled
    with pytest.raises(exc, match=re.escape(arg)):
        func(**trial)


def test_nan_marks_a_missing_team_in_the_statistics():
    """flock_spread and max_distance_from_centre read NaN as a missing state (a diverged run's placeholder)."""
    X = np.stack([X3, np.full_like(X3, np.nan)])
    std_p, std_v = flocking.flock_spread(X)
    assert np.isfinite(std_p[0]) and np.isnan(std_p[1]) and np.isnan(std_v[1])
    d = flocking.max_distance_from_centre(X)
    assert np.isfinite(d[0]) and np.isnan(d[1])


# --------------------------------------------------------------------------- meaning of the graphs


def test_directed_graphs_are_accepted_by_consensus():
    """Ren et al. use directed switching graphs: no symmetry is required."""
    res = cs.kalman_consensus_discrete([0.0, 1.0, 2.0], [1.0, 1.0, 1.0], G3, 0.0, 0.1, n_steps=200)
    assert res.spread[-1] < 0.01 * res.spread[0]
    assert cs.union_condition_holds(SEQ[:2], 1)


@pytest.mark.parametrize("call", [
    lambda L: cs.kalman_consensus_step([0.0, 1.0, 2.0], [1.0, 1.0, 1.0], L, 0.1, 0.1),
    lambda L: cs.kalman_consensus_continuous([0.0, 1.0, 2.0], [1.0, 1.0, 1.0], L, 1.0, 0.1, 0.1),
    lambda L: cs.average_consensus([0.0, 1.0, 2.0], L, n_steps=3),
    lambda L: flocking.flocking_control(X3, GAINS, L),
])
def test_laplacian_passed_as_adjacency_is_named(call):
    with pytest.raises(ValueError, match="looks like a graph Laplacian.*adjacency"):
        call(laplacian(ring_graph(3)))


# --------------------------------------------------------------------------- the hangs and silent NaN of the issue


@pytest.mark.parametrize("tol", ["rtol", "atol"])
def test_nan_tolerance_is_refused_fast(tol):
    box, seconds = bounded(lambda: cs.kalman_consensus_continuous(
        np.arange(5.0), np.ones(5), ring_graph(5), 10.0, 0.1, 0.1, **{tol: float("nan")}), 10)
    assert isinstance(box.get("error"), ValueError) and tol in str(box["error"])


@pytest.mark.parametrize("rng", [None, 0])
def test_absurd_horizon_is_refused_fast(rng):
    """t_final = 1e300 hung in RK45 (and would need 1e303 Euler-Maruyama steps)."""
    box, seconds = bounded(lambda: cs.kalman_consensus_continuous(
        np.arange(5.0), np.ones(5), ring_graph(5), 1e300, 0.1, 0.1, rng=rng), 30)
    assert isinstance(box.get("error"), ValueError) and "t_final" in str(box["error"])
    assert seconds < 10


def test_ode_budget_stops_a_stiff_zero_noise_run(monkeypatch):
    """With Omega = 0 the ODE becomes stiff as P collapses: the evaluation budget stops it with a message."""
    monkeypatch.setattr(cs, "ODE_MAX_EVALUATIONS", 30_000)
    box, _ = bounded(lambda: cs.kalman_consensus_continuous(
        np.arange(5.0), np.ones(5), ring_graph(5), 50.0, 0.0, 0.0), 60)
    assert isinstance(box.get("error"), ValueError)
    assert re.search("t_final.*out of reach.*Omega", str(box["error"]))


def test_valid_continuous_run_fits_the_budget():
    res = cs.kalman_consensus_continuous(np.arange(6.0), np.ones(6), ring_graph(6), 200.0, 0.1, 0.1)
    assert np.all(np.isfinite(res.xi)) and np.all(res.P > 0)


@pytest.mark.parametrize("vector", [False, True])
def test_zero_noise_underflow_is_named_not_nan(vector):
    """Q = Omega = 0: P shrinks by ~1/3 a step on a ring of 5 and underflows at step 512 (NaN before, or
    LinAlgError in the vector form); now a ConsensusBreakdownError that says why and where."""
    xi0, P0, Q, Om = np.arange(5.0), np.ones(5), 0.0, 0.0
    if vector:
        xi0, P0, Q, Om = np.stack([xi0, -xi0], -1), np.broadcast_to(np.eye(2), (5, 2, 2)), 0.0 * np.eye(2), 0.0
    with pytest.raises(ConsensusBreakdownError, match=r"step 512.*Omega is singular.*n_steps <= 511"):
        cs.kalman_consensus_discrete(xi0, P0, ring_graph(5), Q, Om, n_steps=600)
    assert issubclass(ConsensusBreakdownError, ValueError)
    ok = cs.kalman_consensus_discrete(xi0, P0, ring_graph(5), Q, Om, n_steps=511)  # up to the last good step
    assert np.all(np.isfinite(ok.xi)) and np.all(np.isfinite(ok.P))
    # a little communication noise keeps P away from zero for good
    noisy = cs.kalman_consensus_discrete(xi0, P0, ring_graph(5), Q, 1e-6 if not vector else 1e-6 * np.eye(2),
                                         n_steps=600)
    assert np.all(np.isfinite(noisy.P)) and noisy.spread[-1] < 0.01 * noisy.spread[0]


def test_too_many_steps_are_refused_before_running():
    with pytest.raises(ValueError, match="n_steps"):
        cs.kalman_consensus_discrete([0.0, 1.0], [1.0, 1.0], np.zeros((2, 2)), 0.1, 0.1, n_steps=10**9)
    with pytest.raises(ValueError, match="n_steps"):
        cs.kalman_consensus_discrete(np.zeros((10**4, 10)), np.ones((10**4, 10)), np.zeros((10, 10)), 0.1, 0.1,
                                     n_steps=10**5)
    with pytest.raises(ValueError, match="dwell"):
        cs.SwitchingTopology.periodic(SEQ, 1e-9, 1e9)
    with pytest.raises(ValueError, match="n_steps"):
        flocking.simulate_measured_flocking(X3, 10**9, 0.1, GAINS, np.eye(4), np.eye(4), 0, None)


def test_average_consensus_overflow_names_step_size():
    with pytest.raises(ValueError, match="step_size"):
        cs.average_consensus([0.0, 1.0, 2.0], ring_graph(3), n_steps=2000, step_size=5.0)


@pytest.mark.parametrize("call", [
    lambda dt: flocking.closed_loop_step(X3, dt, GAINS),
    lambda dt: flocking.closed_loop_jacobian(X3, dt, GAINS),
    lambda dt: flocking.simulate_measured_flocking(X3, 3, dt, GAINS, np.eye(4), np.eye(4), 0, None),
    lambda dt: dekf.ekf_predict(VIEWS, SIG, dt, GAINS, np.eye(M3)),
    lambda dt: dekf.simulate_estimation_based_flocking(X3, VIEWS, np.eye(M3), 3, dt, GAINS, np.eye(4), np.eye(4),
                                                       0, 150.0),
])
@pytest.mark.parametrize("dt", [0.0, -0.1, float("nan"), float("inf")])
def test_dt_must_be_positive(call, dt):
    with pytest.raises(ValueError, match="dt must be a finite number > 0"):
        call(dt)


@pytest.mark.parametrize("call", [
    lambda r: cs.kalman_consensus_step([0.0, 1.0], [1.0, 1.0], np.zeros((2, 2)), 0.1, 0.1, rng=r),
    lambda r: cs.kalman_consensus_discrete([0.0, 1.0], [1.0, 1.0], np.zeros((2, 2)), 0.1, 0.1, n_steps=2, rng=r),
    lambda r: cs.kalman_consensus_continuous([0.0, 1.0], [1.0, 1.0], np.zeros((2, 2)), 0.1, 0.1, 0.1, rng=r),
    lambda r: cs.random_pairings(4, 3, r),
    lambda r: flocking.simulate_measured_flocking(X3, 3, 0.1, GAINS, np.eye(4), np.eye(4), r, None),
    lambda r: dekf.simulate_estimation_based_flocking(X3, VIEWS, np.eye(M3), 3, 0.1, GAINS, np.eye(4), np.eye(4),
                                                      r, 150.0),
])
def test_negative_seed_is_refused_by_name(call):
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator or a non-negative integer seed"):
        call(-1)


# --------------------------------------------------------------------------- degenerate but meaningful inputs


def test_one_agent_is_defined():
    one = cs.kalman_consensus_discrete([3.0], [2.0], np.zeros((1, 1)), 0.1, 0.1, n_steps=5)
    assert np.all(one.xi == 3.0) and np.all(np.diff(one.P) < 0)  # keeps its state; its own term adds information
    cont = cs.kalman_consensus_continuous([3.0], [2.0], np.zeros((1, 1)), 1.0, 0.1, 0.1)
    assert np.all(cont.xi == 3.0) and np.all(cont.P > 0)
    assert cs.spread(np.array([[3.0]])) == 0.0
    np.testing.assert_allclose(cs.central_fusion([3.0], [2.0]), (3.0, 2.0))
    assert np.all(cs.average_consensus([3.0], np.zeros((1, 1)), n_steps=3).xi == 3.0)
    with pytest.raises(ValueError, match="n_agents.*nobody to pair with"):
        cs.random_pairings(1, 5, 0)
    X1 = X3[:1]
    assert np.all(flocking.flocking_control(X1, GAINS) == 0.0)
    run = flocking.simulate_measured_flocking(X1, 5, 0.1, GAINS, 0.01 * np.eye(4), 0.01 * np.eye(4), 0, 150.0)
    assert np.all(np.isfinite(run.X))
    est = dekf.simulate_estimation_based_flocking(X1, X1[None], np.eye(4), 5, 0.1, GAINS, 0.01 * np.eye(4),
                                                  0.01 * np.eye(4), 0, 150.0)
    assert np.all(np.isfinite(est.rms_error)) and np.all(est.position_variance > 0)


def test_isolated_agent_is_defined():
    G = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # agent 2 hears nobody
    res = cs.kalman_consensus_discrete([0.0, 1.0, 5.0], [1.0, 1.0, 1.0], G, 0.1, 0.1, n_steps=20)
    assert np.all(res.xi[:, 2] == 5.0) and np.all(np.isfinite(res.P))
    far = X3.copy()
    far[2, :2] = [5000.0, 5000.0]  # out of sensing range of both others
    est = dekf.simulate_estimation_based_flocking(far, np.broadcast_to(far, (3, 3, 4)), np.eye(M3), 5, 0.1, GAINS,
                                                  0.01 * np.eye(4), np.eye(4), 0, 150.0, observer=2)
    assert np.all(np.isfinite(est.X_hat)) and not est.adjacency[:, 2].any()
    assert est.position_variance[-1, 2] < est.position_variance[-1, 0]  # it measures only itself


# --------------------------------------------------------------------------- valid finite inputs never give NaN


finite = st.floats(-1e3, 1e3, allow_nan=False)


@given(st.integers(1, 5), st.integers(1, 3), st.integers(0, 2**32 - 1), st.floats(0.0, 2.0), st.floats(0.0, 2.0))
@settings(max_examples=40, deadline=None)
def test_consensus_step_of_valid_input_is_finite(n, m, seed, q, om):
    rng = np.random.default_rng(seed)
    xi = rng.uniform(-1e3, 1e3, (n, m))
    A = rng.standard_normal((n, m, m))
    P = A @ np.swapaxes(A, -1, -2) + 1e-3 * np.eye(m)
    G = (rng.random((n, n)) < 0.5) * (1 - np.eye(n))
    xi1, P1 = cs.kalman_consensus_step(xi, P, G, q * np.eye(m), om * np.eye(m), rng=rng)
    assert np.all(np.isfinite(xi1)) and np.all(np.isfinite(P1))
    assert np.all(np.linalg.eigvalsh(P1) > 0)


@given(st.integers(1, 5), st.integers(0, 2**32 - 1), st.floats(1e-3, 0.5))
@settings(max_examples=40, deadline=None)
def test_flocking_kernels_of_valid_input_are_finite(N, seed, dt):
    rng = np.random.default_rng(seed)
    X = np.concatenate([rng.uniform(-500, 500, (N, 2)), rng.uniform(-10, 10, (N, 2))], -1)
    if N > 1 and seed % 3 == 0:
        X[1] = X[0]  # two agents at the same point
    for out in (flocking.flocking_control(X, GAINS), flocking.closed_loop_step(X, dt, GAINS),
                flocking.closed_loop_jacobian(X, dt, GAINS), *flocking.flock_spread(X)):
        assert np.all(np.isfinite(out))


@given(st.integers(1, 4), st.integers(0, 2**32 - 1))
@settings(max_examples=30, deadline=None)
def test_ekf_step_of_valid_input_is_finite_and_psd(N, seed):
    rng = np.random.default_rng(seed)
    M = 4 * N
    X = np.concatenate([rng.uniform(-300, 300, (N, N, 2)), rng.uniform(-5, 5, (N, N, 2))], -1)
    A = rng.standard_normal((N, M, M))
    Sigma = A @ np.swapaxes(A, -1, -2) / M + 0.1 * np.eye(M)
    observed = (rng.random((N, N)) < 0.5) | np.eye(N, dtype=bool)
    out = dekf.ekf_flocking_step(X, Sigma, X + rng.standard_normal(X.shape), observed, np.eye(M), 0.1, GAINS,
                                 0.01 * np.eye(M))
    assert all(np.all(np.isfinite(o)) for o in out)
    assert np.all(np.linalg.eigvalsh(out[4]) > 0)


# --------------------------------------------------------------------------- long horizons stay symmetric PD


def test_kalman_consensus_stays_symmetric_pd_over_10_000_steps():
    rng = np.random.default_rng(3)
    n, m = 6, 2
    G = cs.random_pairings(n, 10_000, rng)
    A = rng.standard_normal((n, m, m))
    P0 = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(m)
    res = cs.kalman_consensus_discrete(rng.standard_normal((n, m)), P0, G, 0.01 * np.eye(m), 0.1 * np.eye(m),
                                       rng=rng)
    assert np.all(np.isfinite(res.xi)) and np.all(np.isfinite(res.P))
    np.testing.assert_array_equal(res.P, np.swapaxes(res.P, -1, -2))
    assert np.linalg.eigvalsh(res.P).min() > 0


def test_ekf_flocking_stays_symmetric_pd_over_10_000_steps():
    rng = np.random.default_rng(4)
    N = 2
    X0 = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0]])
    run = dekf.simulate_estimation_based_flocking(X0, np.broadcast_to(X0, (N, N, 4)), np.eye(4 * N), 10_000, 0.1,
                                                  GAINS, 0.01 * np.eye(4), np.eye(4), rng, 150.0)
    assert np.all(np.isfinite(run.X_hat)) and np.all(run.position_variance > 0)
    assert np.all(np.isfinite(run.rms_error))
