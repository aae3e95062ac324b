"""Immutable means immutable: every checked model and value object, probed as a maintainer would.

For every model class: no stored array (nor any array along its ``.base`` chain) can be made
writeable again, attributes cannot be set or deleted, pickle and deep copy rebuild an equal,
checked, frozen object. A model shared by 8 threads gives what the serial run gives (the SDP
path of the set-membership filter included), a solve leaves ``warnings.filters`` as it was, and
a filter's state read before a step is unchanged after it.
"""

import copy
import pickle
import threading
import warnings

import numpy as np
import pytest

from mascore import (
    agents,
    centralized_team_filter,
    consensus,
    consensus_filters,
    ellipsoids,
    estimation,
    fusion,
    fusion_forwarding,
    graphs,
    kalman,
    lqr,
    network_observer,
    observers,
    own_state,
    rendezvous,
    sensing,
    sensor_network,
    team_model,
)
from mascore import distributed_ekf as dekf
from mascore import distributed_kf as dkf
from mascore import set_membership as smf
from mascore import synchronization as sync
from mascore._validation import Frozen, frozen_copy
from mascore.flocking import FlockingGains

GAINS = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
AGENT = agents.double_integrator(1, 0.1)
OSCILLATOR = (np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]))
SM_KW = dict(A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), C=[[1.0, 0.0]], D=[[1.0]], Q=0.01 * np.eye(2), R=[[0.04]])


def _sensor_network():
    H = [[[1.0, 0.0]], np.zeros((0, 2)), [[1.0, 0.0]]]
    return sensor_network.SensorNetworkModel([[1.0, 0.1], [0.0, 1.0]], 0.01 * np.eye(2), H, [[[0.5]], None, [[2.0]]],
                                     graphs.path_graph(3))


MODELS = {  # every checked model or value class: a builder of one instance
    "LinearGaussianModel": lambda: kalman.LinearGaussianModel(F=[[1.0, 0.1], [0.0, 1.0]], Q=0.01 * np.eye(2),
                                                              H=[[1.0, 0.0]], R=[[0.5]], B=[[0.0], [0.1]]),
    "TeamFilterModel": lambda: team_model.team_filter_model(AGENT.A, AGENT.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
                                                     0.01 * np.eye(2), np.eye(2), n_agents=3),
    "SetMembershipModel": lambda: smf.SetMembershipModel(**SM_KW),
    "EKFModel": lambda: dekf.EKFModel(3, 0.1, GAINS, 0.01 * np.eye(12), np.eye(12)),
    "SynchronizationLaw": lambda: sync.SynchronizationLaw(graphs.ring_graph(4), [1.0, 0.0, 0.0, 0.0], np.eye(2), 1.5),
    "SensorNetworkModel": _sensor_network,
    # built without the constructor (only the new sensing checked): probed as well
    "SensorNetworkModel.with_sensing": lambda: _sensor_network().with_sensing(
        [[[1.0, 0.0]], [[0.0, 1.0]], np.zeros((0, 2))], [[[0.5]], [[1.0]], None]),
    "LinearGaussianModel.with_measurement": lambda: kalman.LinearGaussianModel(
        F=[[1.0, 0.1], [0.0, 1.0]], Q=0.01 * np.eye(2), H=[[1.0, 0.0]], R=[[0.5]]).with_measurement([[0.0, 1.0]], [[2.0]]),
    "DiffusionKalmanFilter": lambda: fusion.DiffusionKalmanFilter(_sensor_network()),
    "CovarianceIntersectionFilter": lambda: fusion.CovarianceIntersectionFilter(_sensor_network()),
    "ConsensusOnInformationFilter": lambda: fusion.ConsensusOnInformationFilter(_sensor_network(), 2),
    "InformationConsensusFilter": lambda: fusion.InformationConsensusFilter(_sensor_network(), 2),
    "MeasurementForwardingFilter": lambda: fusion.MeasurementForwardingFilter(_sensor_network()),
    "CentralizedFilter": lambda: fusion.CentralizedFilter(_sensor_network()),
    "KalmanConsensusNetworkFilter": lambda: fusion_forwarding.KalmanConsensusNetworkFilter(_sensor_network(), 0.2),
    "SetMembershipForwardingFilter": lambda: fusion_forwarding.SetMembershipForwardingFilter(_sensor_network(), 0.99),
    "LTIAgent": lambda: agents.LTIAgent.from_continuous([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], 0.1),
    "Ellipsoid": lambda: ellipsoids.Ellipsoid([1.0, 2.0], np.diag([4.0, 1.0])),
    "SwitchingTopology": lambda: consensus.SwitchingTopology([0.0, 1.0], [graphs.path_graph(3), graphs.ring_graph(3)]),
    "RendezvousModel": lambda: rendezvous.RendezvousModel(AGENT.A, AGENT.B, rendezvous.rendezvous_gain(0.5, 1.0, 1),
                                                          Q=1e-4 * np.eye(2), R=0.04 * np.eye(2), dt=0.1),
    "DistributedGain": lambda: lqr.DistributedGain(np.array([[1.0, 2.0]]), np.array([[0.5, 0.0]])),
    "TopDownLQR": lambda: lqr.top_down_lqr(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]),
                                           np.eye(2), 0.5 * np.eye(2), np.eye(1), graphs.ring_graph(4)),
    "BottomUpLQR": lambda: lqr.BottomUpLQR(np.array([[1.0, 2.0]]), np.array([[0.5, 1.0]]), Phi=np.array([[0.5]]),
                                           bound=3.0),
    "FlockingGains": lambda: GAINS,
    "OwnStateForwardingFilter": lambda: own_state.OwnStateForwardingFilter(np.eye(2), np.ones((2, 1)), 0.01 * np.eye(2),
                                                                           np.eye(2), np.eye(2)),
    "CentralizedOutputFilter": lambda: own_state.CentralizedOutputFilter(np.eye(2), np.ones((2, 1)), 0.01 * np.eye(2),
                                                                         [[1.0, 0.0]], 0.5, 3),
    "KalmanConsensusFilter": lambda: consensus_filters.KalmanConsensusFilter(0.1, 0.1),
    "AverageConsensusFilter": lambda: consensus_filters.AverageConsensusFilter(),
    "CentralFusionFilter": lambda: consensus_filters.CentralFusionFilter(),
    "NoFusionFilter": lambda: consensus_filters.NoFusionFilter(),
    "DiscreteNetworkObserver": lambda: network_observer.DiscreteNetworkObserver([[0.5], [0.1]], 0.2, graphs.ring_graph(3),
                                                                         [[1, 0.1], [0, 1]], [[0.0], [0.1]], [[1.0, 0.0]]),
    "GaussianState": lambda: estimation.GaussianState(np.zeros((3, 2)), np.broadcast_to(np.eye(2), (3, 2, 2))),
    "SetState": lambda: estimation.SetState(np.zeros(2), np.diag([2.0, 1.0])),
    # design results: read-only too, complex and boolean arrays included
    "MinEnergyObserver": lambda: observers.min_energy_observer(*OSCILLATOR, np.eye(1), np.eye(1)),
    "DistributedObserver": lambda: observers.distributed_observer(*OSCILLATOR, 10.0 * np.eye(1), 5.0 * np.eye(1),
                                                                  np.eye(1), graphs.ring_graph(4)),
    "SyncDesign": lambda: sync.design_synchronization(
        np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2),
        graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True), [1.0, 0.0, 0.0, 0.0],
        c0=2 / 3, r0=0.6),
}


def _subclasses(cls):
    for sub in cls.__subclasses__():
        yield sub
        yield from _subclasses(sub)


def test_every_frozen_class_is_probed_here():
    """A new model class on the frozen base is listed in MODELS, so that the probes below reach it."""
    found = {c.__name__ for c in _subclasses(Frozen) if c.__module__.startswith("mascore") and not c.__name__.startswith("_")}
    bases = {"NetworkFilter"}  # the fusion filters' shared base (no equations of its own): its subclasses are probed
    assert found - bases <= set(MODELS), f"add to MODELS: {sorted(found - bases - set(MODELS))}"


def _attributes(obj):
    """Every stored attribute of `obj` (slots along the MRO and the instance dict), by name."""
    names = {n for cls in type(obj).__mro__ for n in getattr(cls, "__slots__", ())}
    names |= set(getattr(obj, "__dict__", {}))
    return {n: getattr(obj, n) for n in sorted(names) if hasattr(obj, n)}


def _arrays(obj, where="", seen=None):
    """Every array `obj` holds, with its path: attributes, tuples of arrays and nested frozen objects."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        yield where, obj
    elif isinstance(obj, (tuple, list)):
        for i, item in enumerate(obj):
            yield from _arrays(item, f"{where}[{i}]", seen)
    elif isinstance(obj, Frozen):
        for name, value in _attributes(obj).items():
            yield from _arrays(value, f"{where}.{name}", seen)


def _assert_frozen_arrays(obj):
    arrays = list(_arrays(obj))
    for where, arr in arrays:
        level, depth = arr, 0
        while isinstance(level, np.ndarray):
            assert not level.flags.writeable, f"{where}{'.base' * depth} is writeable"
            with pytest.raises(ValueError):
                level.setflags(write=True)
            level, depth = level.base, depth + 1
        assert isinstance(level, bytes), f"{where}: the memory at the end of .base is {type(level).__name__}"
    return arrays


@pytest.mark.parametrize("name", sorted(MODELS))
def test_no_stored_array_can_be_made_writeable_through_base(name):
    """``m.F.base.setflags(write=True); m.F.base[0, 0] = 2`` used to change every model: now refused at every level."""
    obj = MODELS[name]()
    arrays = _assert_frozen_arrays(obj)
    if name not in ("FlockingGains", "KalmanConsensusFilter", "AverageConsensusFilter", "CentralFusionFilter",
                    "NoFusionFilter"):  # numbers only, or nothing
        assert arrays, f"{name} holds no array: the probe would pass vacuously"


@pytest.mark.parametrize("name", sorted(MODELS))
def test_attributes_cannot_be_set_or_deleted(name):
    obj = MODELS[name]()
    for attr in [*_attributes(obj), "brand_new"]:
        with pytest.raises(AttributeError, match=attr):
            setattr(obj, attr, 1.0)
    for attr in _attributes(obj):
        with pytest.raises(AttributeError, match=attr):
            delattr(obj, attr)


def test_a_negative_coupling_gain_cannot_be_set_after_the_check():
    law = MODELS["SynchronizationLaw"]()
    with pytest.raises(AttributeError, match="'c'"):
        law.c = -5
    assert law.c == 1.5


@pytest.mark.parametrize("name", sorted(MODELS))
def test_pickle_and_deepcopy_rebuild_an_equal_checked_frozen_object(name):
    obj = MODELS[name]()
    for twin in (pickle.loads(pickle.dumps(obj)), copy.deepcopy(obj), copy.copy(obj)):
        assert type(twin) is type(obj)
        assert twin == obj and hash(twin) == hash(obj)
        _assert_frozen_arrays(twin)


def test_equality_compares_the_checked_values():
    """``==`` can fail: another matrix, another type, another filter setting."""
    a, b = MODELS["SetMembershipModel"](), smf.SetMembershipModel(**{**SM_KW, "R": [[0.05]]})
    assert a == MODELS["SetMembershipModel"]() and a != b
    assert MODELS["Ellipsoid"]() != ellipsoids.Ellipsoid([1.0, 2.0], np.diag([4.0, 2.0]))
    model = _sensor_network()
    assert fusion.ConsensusOnInformationFilter(model, 2) != fusion.ConsensusOnInformationFilter(model, 3)
    assert fusion.DiffusionKalmanFilter(model) != fusion.CovarianceIntersectionFilter(model)


def test_a_copy_is_checked_again():
    """Deep copy and unpickling go through the constructor: a tampered pickle is refused like a bad argument."""
    law = MODELS["SynchronizationLaw"]()
    cls, args = law.__reduce__()
    with pytest.raises(ValueError, match="c"):
        cls(*args[:3], -5.0)


def test_objects_keep_copies_not_the_callers_arrays():
    """A NaN or a finite write into the caller's arrays after construction changes nothing."""
    A, B = np.array([[1.0, 0.1], [0.0, 1.0]]), np.array([[0.0], [0.1]])
    agent = agents.LTIAgent(A, B)
    c, P = np.zeros(2), np.diag([4.0, 1.0])
    ell = ellipsoids.Ellipsoid(c, P)
    times = np.array([0.0, 1.0])
    topo = consensus.SwitchingTopology(times, [graphs.path_graph(3), graphs.ring_graph(3)])
    mean, cov = np.zeros(2), np.eye(2)
    state = estimation.GaussianState(mean, cov)
    A[0, 0], B[1, 0], c[0], P[0, 0], times[1], mean[0], cov[1, 1] = np.nan, np.nan, 5.0, 9.0, 0.5, np.nan, 4.0
    assert np.isfinite(agent.step(np.ones(2), np.ones(1))).all()
    assert agent.A[0, 0] == 1.0 and ell.center[0] == 0.0 and ell.shape[0, 0] == 4.0 and topo.times[1] == 1.0
    assert state.mean[0] == 0.0 and state.covariance[1, 1] == 1.0
    assert topo.at(0.75) is not None and np.array_equal(topo.at(0.75), graphs.path_graph(3))


def test_frozen_copy_is_a_copy_on_immutable_memory():
    src = np.arange(6.0).reshape(2, 3)
    out = frozen_copy(src)
    src[0, 0] = 7.0
    assert out[0, 0] == 0.0 and out.shape == (2, 3) and out.dtype == float
    assert frozen_copy(np.zeros((0, 0))).shape == (0, 0)
    assert frozen_copy([1, 2], int).dtype.kind == "i"


# ------------------------------------------------------------------------------------------ threads


def _in_threads(fn, args):
    """`fn(arg)` for each arg, all started together in their own thread; the results in order."""
    out = [None] * len(args)
    errors = []
    start = threading.Barrier(len(args))

    def work(i):
        try:
            start.wait()
            out[i] = fn(args[i])
        except BaseException as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(len(args))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return out


def test_a_set_membership_model_shared_by_8_threads_on_the_sdp_path_equals_the_serial_run():
    pytest.importorskip("cvxpy")
    model = smf.SetMembershipModel(**SM_KW)
    rng = np.random.default_rng(11)
    ys = [0.2 * rng.standard_normal((3, 1)) for _ in range(8)]

    def run(y):
        h = model.run(np.zeros(2), np.eye(2), y, method="sdp")
        return h.center_corr, h.shape_corr, h.shape_pred

    def steps(y):  # step by step, the caller keeping the compiled programs
        programs, c, P = {}, np.zeros(2), np.eye(2)
        for k in range(y.shape[0]):
            c, P, _ = model.correct(c, P, y[k], method="sdp", programs=programs)
            c, P = model.predict(c, P, method="sdp", programs=programs)
        return c, P

    for fn in (run, steps):
        serial = [fn(y) for y in ys]
        for got, want in zip(_in_threads(fn, ys), serial):
            for g, w in zip(got, want):
                assert np.array_equal(g, w)
    assert pickle.loads(pickle.dumps(model)) == model  # nothing of the solver was left in the model


def test_models_shared_by_8_threads_equal_the_serial_run():
    km = MODELS["LinearGaussianModel"]()
    net = fusion.CovarianceIntersectionFilter(_sensor_network())
    law = MODELS["SynchronizationLaw"]()
    team_model = MODELS["TeamFilterModel"]()
    path = graphs.path_graph(3)

    def work(seed):
        rng = np.random.default_rng(seed)
        x, P = km.check_state(np.zeros(2), np.eye(2))
        xs, Ps = np.zeros((3, 2)), np.broadcast_to(np.eye(2), (3, 2, 2))
        team = dkf.TeamFilter(team_model, graphs.laplacian(path), np.zeros((1, 6)), P0=np.eye(2))
        for _ in range(30):
            x, P = kalman.update(*kalman.predict(x, P, km, u=rng.standard_normal(1)), rng.standard_normal(1), km)
            xs, Ps = net.update(*net.predict(xs, Ps), rng.standard_normal(2))
            team.predict()
            Z, mask = sensing.measure(rng, np.zeros((1, 3, 2)), path, np.eye(2))
            team.update(Z, mask[0])
        return x, P, xs, Ps, law(rng.standard_normal((4, 2)), np.ones(2)), team.X_hat, team.Sigma

    serial = [work(s) for s in range(8)]
    for got, want in zip(_in_threads(work, list(range(8))), serial):
        for g, w in zip(got, want):
            assert np.array_equal(g, w)


def test_solving_in_threads_leaves_the_warning_filters_as_they_were():
    """The solver's inaccuracy is decided from its status: no solve touches the process-wide ``warnings.filters``."""
    pytest.importorskip("cvxpy")
    before = list(warnings.filters)
    model = smf.SetMembershipModel(**SM_KW)
    rng = np.random.default_rng(5)
    _in_threads(lambda y: model.run(np.zeros(2), np.eye(2), y, method="sdp"),
                [0.2 * rng.standard_normal((2, 1)) for _ in range(8)])
    assert warnings.filters == before


def test_an_inaccurate_solve_raises_from_its_status_without_a_warning():
    pytest.importorskip("cvxpy")
    from mascore._solver import SolverError

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(SolverError, match="status"):
            smf.correct(np.zeros(2), np.eye(2), [0.1], SM_KW["C"], SM_KW["D"], SM_KW["R"], method="sdp",
                        solver_options={"max_iter": 2})
    assert not [w for w in caught if "inaccurate" in str(w.message)]


# ------------------------------------------------------------------------------------------ state reads


def _team_filter(mode="eb", n_agents=3):
    """A whole-team filter; 14 agents make ``N M_r > 384``: the estimation-based step then runs in place."""
    model = team_model.team_filter_model(AGENT.A, AGENT.B, rendezvous.rendezvous_gain(0.5, 1.5, 1), 0.01 * np.eye(2),
                                  np.eye(2), n_agents=n_agents)
    path = graphs.path_graph(n_agents)
    filt = dkf.TeamFilter(model, graphs.laplacian(path), np.zeros((1, 2 * n_agents)), P0=np.eye(2), mode=mode)
    return filt, lambda k: (filt.predict(), filt.update(*_measure(k, n_agents)))


def _measure(k, n_agents=3):
    Z, mask = sensing.measure(k, np.ones((1, n_agents, 2)), graphs.path_graph(n_agents), np.eye(2))
    return Z, mask[0]


def _central_filter():
    filt = centralized_team_filter.CentralizedTeamFilter(MODELS["TeamFilterModel"](), AGENT.B, np.zeros((1, 6)), np.eye(2))
    return filt, lambda k: (filt.predict(np.zeros((1, 3, 1))), filt.update(*_measure(k)))


def _flocking_ekf():
    X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])
    filt = dekf.FlockingEKF(MODELS["EKFModel"](), np.broadcast_to(X, (3, 3, 4)), np.eye(12))
    return filt, lambda k: filt.step(X + 0.1 * (k + 1), np.ones((3, 3), bool))


@pytest.mark.parametrize("build, names", [(_team_filter, ("X_hat", "Sigma", "KH")),
                                          (lambda: _team_filter("mb"), ("X_hat", "Sigma", "KH")),
                                          (lambda: _team_filter("eb", 14), ("X_hat", "Sigma", "KH")),
                                          (_central_filter, ("x_hat", "P")),
                                          (_flocking_ekf, ("X_hat", "Sigma"))])
def test_a_state_read_before_a_step_is_unchanged_after_it(build, names):
    filt, step = build()
    step(0)
    kept = {n: getattr(filt, n) for n in names}
    frozen = {n: kept[n].copy() for n in names}
    views = {n: filt.view(n) for n in names}
    for k in (1, 2, 3):  # the filters may swap work buffers: reads are kept over several steps
        step(k)
    for n in names:
        assert np.array_equal(kept[n], frozen[n]), f"{n} read before the step changed with it"
        assert np.array_equal(getattr(filt, n), filt.view(n))
        assert not views[n].flags.writeable
    assert any(not np.array_equal(getattr(filt, n), frozen[n]) for n in names)  # the step did move the state
    with pytest.raises(ValueError, match="name"):
        filt.view("nope")
