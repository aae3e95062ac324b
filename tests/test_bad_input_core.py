"""Bad input to the core modules (issue 14, "Nothing silent").

kalman, noise, agents, graphs, sensing, the team filters (team_model, distributed_kf,
centralized_team_filter, team_observability) and rendezvous: every public function refuses a
spoiled argument with a ``ValueError``/``TypeError`` whose message names the argument, never returns
NaN/inf from finite valid input, and a Kalman step never lets a modified argument through unchecked (the
plain-array steps check in full on every call; a model's matrices are read-only copies).
"""

from __future__ import annotations

import copy
import functools
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mascore import _kf_reference as reference
from mascore import agents, centralized_team_filter, graphs, kalman, noise, sensing, team_model, team_observability
from mascore import distributed_kf as dk
from mascore import rendezvous as rv

AGENT = agents.double_integrator(2, 0.1)
K_GAIN = rv.rendezvous_gain(0.5, 1.5, 2)
BK = AGENT.B @ K_GAIN
N = 3


def _model(N=N):
    return team_model.team_filter_model(AGENT.A, AGENT.B, K_GAIN, np.eye(4), 2.0 * np.eye(4), N)


def _spd(rng, n, batch=()):
    G = rng.normal(size=(*batch, n, n)) / np.sqrt(n)
    return G @ np.swapaxes(G, -1, -2) + 0.5 * np.eye(n)


# ----------------------------------------------------------------------------
# one valid call of every public function
# ----------------------------------------------------------------------------


def baselines() -> dict[str, tuple]:
    """name -> (function, kwargs) of a valid call (small sizes)."""
    rng = np.random.default_rng(0)
    model = _model()
    A = graphs.path_graph(N)
    L = graphs.laplacian(A)
    S = sensing.sensing_mask(A)
    X = rng.normal(size=(2, N, N, 4))
    Z, _ = sensing.measure(1, rng.normal(size=(2, N, 4)), A, 2.0 * np.eye(4))
    Sig_aug = dk.eb_initial_covariance(model, np.eye(4))
    Sig_i = np.broadcast_to(np.eye(model.M_r), (1, N, model.M_r, model.M_r)).copy()
    Sig_full = team_model.expand_covariance(dk.eb_initial_covariance(model, np.eye(4), common=False)[0], model.kron)
    z_lists = [rng.normal(size=4 * len(s)) for s in sensing.neighbor_sets(A)]
    rv_model = rv.RendezvousModel(AGENT.A, AGENT.B, K_GAIN, 0.1 * np.eye(4), 0.5 * np.eye(4), 0.1)
    res = rv.simulate_rendezvous(1, rv_model, rng.normal(size=(1, N, 4)), A, 3, "estimation",
                                 x_hat0=np.zeros((1, 4 * N)), P0=np.eye(4))
    x4, P4 = np.zeros(4), np.eye(4)
    H = np.eye(2, 4)
    return {
        # kalman
        "kalman.predict": (kalman.predict, dict(x=x4, P=P4, F=AGENT.A, Q=0.1 * np.eye(4), B=AGENT.B, u=np.ones(2))),
        "kalman.update": (kalman.update, dict(x=x4, P=P4, z=np.ones(2), H=H, R=np.eye(2))),
        "kalman.kalman_gain": (kalman.kalman_gain, dict(P=P4, H=H, R=np.eye(2))),
        "kalman.run_filter": (kalman.run_filter, dict(x0=x4, P0=P4, z=np.ones((3, 2)), F=np.eye(4),
                                                      Q=0.1 * np.eye(4), H=H, R=np.eye(2))),
        "kalman.nees": (kalman.nees, dict(error=np.ones(4), P=P4)),
        "kalman.nees_interval": (kalman.nees_interval, dict(dof=4, n_runs=10, confidence=0.95)),
        "kalman.symmetrize": (kalman.symmetrize, dict(P=rng.normal(size=(3, 3)))),
        # noise
        "noise.psd_factor": (noise.psd_factor, dict(M=np.diag([2.0, 1.0]))),
        "noise.gaussian": (noise.gaussian, dict(rng=np.random.default_rng(1), cov=np.eye(2), size=3, mean=np.ones(2))),
        "noise.uniform_box": (noise.uniform_box, dict(rng=np.random.default_rng(1), low=[0.0, 0.0], high=[1.0, 2.0],
                                                      size=3)),
        "noise.uniform_ellipsoid": (noise.uniform_ellipsoid, dict(rng=np.random.default_rng(1), center=np.ones(2),
                                                                  shape=np.diag([2.0, 0.5]), size=3)),
        # agents
        "agents.double_integrator": (agents.double_integrator, dict(n=2, dt=0.1)),
        "agents.team_matrices": (agents.team_matrices, dict(A=AGENT.A, B=AGENT.B, n_agents=3)),
        "agents.team_state": (agents.team_state, dict(agent_states_=rng.normal(size=(3, 4)))),
        "agents.agent_states": (agents.agent_states, dict(team=rng.normal(size=12), n_states=4)),
        "agents.zoh": (agents.zoh, dict(A_c=[[0.0, 1.0], [0.0, -1.0]], B_c=[[0.0], [1.0]], dt=0.1)),
        "agents.system_matrices": (agents.system_matrices, dict(system=AGENT, time="continuous")),
        "agents.check_sampling_time": (agents.check_sampling_time, dict(A=AGENT.A)),
        "agents.is_system": (agents.is_system, dict(obj=AGENT)),
        # graphs
        "graphs.adjacency_from_edges": (graphs.adjacency_from_edges, dict(n_agents=3, edges=[(0, 1), (1, 2, 0.5)])),
        "graphs.laplacian": (graphs.laplacian, dict(A=A)),
        "graphs.laplacian_spectrum": (graphs.laplacian_spectrum, dict(laplacian=graphs.laplacian(graphs.ring_graph(4)))),
        "graphs.ring_graph": (graphs.ring_graph, dict(n_agents=4)),
        "graphs.path_graph": (graphs.path_graph, dict(n_agents=4)),
        "graphs.complete_graph": (graphs.complete_graph, dict(n_agents=4)),
        "graphs.star_graph": (graphs.star_graph, dict(n_agents=4, center=1)),
        "graphs.proximity_graph": (graphs.proximity_graph, dict(positions=rng.normal(size=(4, 2)), sensing_range=1.5)),
        "graphs.spanning_tree_roots": (graphs.spanning_tree_roots, dict(A=A)),
        "graphs.has_spanning_tree": (graphs.has_spanning_tree, dict(A=A)),
        "graphs.is_connected": (graphs.is_connected, dict(A=A)),
        "graphs.connected_components": (graphs.connected_components, dict(A=A)),
        "graphs.from_networkx": (graphs.from_networkx, dict(graph=graphs.to_networkx(A))),
        "graphs.require_connected": (graphs.require_connected, dict(A=A, why="the test")),
        "graphs.graph_union": (graphs.graph_union, dict(adjacencies=[A, graphs.complete_graph(N)])),
        "graphs.unions_over_windows": (graphs.unions_over_windows, dict(adjacencies=np.stack([A, A, A]), window=2)),
        "graphs.to_networkx": (graphs.to_networkx, dict(A=A)),
        # sensing
        "sensing.sensing_mask": (sensing.sensing_mask, dict(adjacency=A)),
        "sensing.neighbor_sets": (sensing.neighbor_sets, dict(adjacency=A)),
        "sensing.selection_matrix": (sensing.selection_matrix, dict(neighbors=np.array([0, 2]), n_agents=3, m=4)),
        "sensing.selection_matrices": (sensing.selection_matrices, dict(adjacency=A, m=4)),
        "sensing.team_noise_covariance": (sensing.team_noise_covariance, dict(R=np.eye(4), n_agents=3, m=4)),
        "sensing.measurement_noise": (sensing.measurement_noise, dict(rng=1, R=np.eye(4), shape=(2,), n_agents=3,
                                                                      m=4)),
        "sensing.measure": (sensing.measure, dict(rng=1, states=rng.normal(size=(2, N, 4)), adjacency=A, R=np.eye(4))),
        "sensing.stacked_measurement": (sensing.stacked_measurement, dict(Z=Z[0], mask=S, agent=1)),
        # distributed_kf
        "team_model.team_filter_model": (team_model.team_filter_model, dict(A=AGENT.A, B=AGENT.B, K=K_GAIN, Q=np.eye(4),
                                                                        R=2.0 * np.eye(4), n_agents=N)),
        "team_model.closed_loop_matrices": (team_model.closed_loop_matrices, dict(A=AGENT.A, BK=BK, laplacian=L)),
        "team_model.reduce_covariance": (team_model.reduce_covariance, dict(P=np.kron(_spd(rng, 3), np.eye(2)), kron=2)),
        "team_model.expand_covariance": (team_model.expand_covariance, dict(P_r=_spd(rng, 3), kron=2)),
        "distributed_kf.agent_update": (dk.agent_update, dict(X_pred=X, Sigma_pred=np.broadcast_to(
            np.eye(12), (1, N, 12, 12)).copy(), Z=Z, mask=S, R=2.0 * np.eye(4))),
        "distributed_kf.mb_predict": (dk.mb_predict, dict(model=model, X_hat=X, Sigma=Sig_i, laplacian=L,
                                                          KH_prev=0.1 * Sig_i)),
        "distributed_kf.mb_update": (dk.mb_update, dict(model=model, X_pred=X, Sigma_pred=Sig_i, Z=Z, mask=S)),
        "distributed_kf.eb_initial_covariance": (dk.eb_initial_covariance, dict(model=model, P0=np.eye(4))),
        "distributed_kf.eb_predict": (dk.eb_predict, dict(model=model, X_hat=X, Sigma=Sig_aug, laplacian=L)),
        "distributed_kf.eb_update": (dk.eb_update, dict(model=model, X_pred=X, Sigma_pred=Sig_aug + 0.1 * np.eye(
            Sig_aug.shape[-1]), Z=Z, mask=S)),
        "distributed_kf.agent_covariances": (dk.agent_covariances, dict(model=model, Sigma=Sig_aug)),
        "distributed_kf.plain_estimation_based_step": (reference.plain_estimation_based_step, dict(
            X_hat=rng.normal(size=(N, 4 * N)), Sigma=Sig_full, A=AGENT.A, BK=BK, Q=np.eye(4), R=2.0 * np.eye(4 * N),
            adjacency=A, z=z_lists)),
        "distributed_kf.plain_measurement_based_step": (reference.plain_measurement_based_step, dict(
            X_hat=rng.normal(size=(N, 4 * N)), Sigma=np.broadcast_to(np.eye(4 * N), (N, 4 * N, 4 * N)).copy(),
            A=AGENT.A, BK=BK, Q=np.eye(4), R=2.0 * np.eye(4 * N), adjacency=A, z=z_lists)),
        "centralized_team_filter.centralized_predict": (centralized_team_filter.centralized_predict, dict(
            model=model, x=rng.normal(size=(2, N, 4)), P=np.eye(model.M_r)[None], U=np.ones((2, N, 2)), B=AGENT.B)),
        "centralized_team_filter.centralized_update": (centralized_team_filter.centralized_update, dict(
            model=model, x_pred=rng.normal(size=(2, N, 4)), P_pred=np.eye(model.M_r)[None], Z=Z, mask=S)),
        "team_observability.observable_agents": (team_observability.observable_agents, dict(
            A=AGENT.A, BK=BK, adjacency=A, tol=1e-8)),
        "team_observability.require_observable": (team_observability.require_observable, dict(
            A=AGENT.A, BK=BK, adjacency=A)),
        "team_observability.lyapunov_v": (team_observability.lyapunov_v, dict(
            error=rng.normal(size=12), Sigma_r=_spd(rng, 6), kron=2)),
        "distributed_kf.team_nees": (dk.team_nees, dict(model=model, X_true=rng.normal(size=(2, N, 4)), X_hat=X,
                                                        Sigma_i=Sig_i)),
        "distributed_kf.f2_cross": (dk.f2_cross, dict(model=model, Sigma=Sig_aug, laplacian=L)),
        "team_observability.theorem1_min_eigenvalues": (team_observability.theorem1_min_eigenvalues, dict(
            model=res.model, laplacian=L, KH=res.gains, Sigma_i=res.sigma_i, F2_cross=res.f2_cross)),
        # rendezvous
        "rendezvous.rendezvous_gain": (rv.rendezvous_gain, dict(rho1=0.5, rho2=1.5, n=2)),
        "rendezvous.consensus_control": (rv.consensus_control, dict(views=X, laplacian=L, K=K_GAIN)),
        "rendezvous.true_state_views": (rv.true_state_views, dict(states=rng.normal(size=(2, N, 4)))),
        "rendezvous.propagate_team": (rv.propagate_team, dict(rng=1, states=rng.normal(size=(2, N, 4)),
                                                              inputs=np.ones((2, N, 2)), A=AGENT.A, B=AGENT.B,
                                                              Q=0.1 * np.eye(4))),
        "rendezvous.team_spread": (rv.team_spread, dict(values=rng.normal(size=(2, N, 2)))),
        "rendezvous.RendezvousModel": (rv.RendezvousModel, dict(
            A=AGENT.A, B=AGENT.B, K=K_GAIN, Q=0.1 * np.eye(4), R=0.5 * np.eye(4), dt=0.1)),
        "rendezvous.expected_spread": (rv.expected_spread, dict(
            model=rv_model, x0=rng.normal(size=(2, N, 4)), adjacency=A, n_steps=4, mode="measurement")),
        "rendezvous.simulate_rendezvous": (rv.simulate_rendezvous, dict(
            rng=1, model=rv_model, x0=rng.normal(size=(1, N, 4)), adjacency=A, n_steps=3, mode="estimation",
            x_hat0=np.zeros((1, 4 * N)), P0=np.eye(4), central=True)),
    }


BASELINES = baselines()
MODULES = (kalman, noise, agents, graphs, sensing, team_model, dk, centralized_team_filter, team_observability, rv)


def _has_nonfinite(value) -> bool:
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "fc" and not np.all(np.isfinite(value))
    if isinstance(value, (float, np.floating)):
        return not math.isfinite(value)
    if isinstance(value, (list, tuple)):
        return any(_has_nonfinite(v) for v in value)
    if isinstance(value, dict):
        return any(_has_nonfinite(v) for v in value.values())
    if hasattr(value, "__dataclass_fields__"):
        return any(_has_nonfinite(getattr(value, f)) for f in value.__dataclass_fields__)
    return False


def _call(key: str, **changes):
    func, kwargs = BASELINES[key]
    kwargs = copy.deepcopy(kwargs)
    kwargs.update(changes)
    return func(**kwargs)


def _refused(key: str, arg: str, bad, exc=(ValueError, TypeError), match: str | None = None) -> None:
    """Calling baseline `key` with `arg` replaced by `bad` raises `exc` naming `arg` (or matching `match`)."""
    with pytest.raises(exc) as info:
        _call(key, **{arg: bad})
    pattern = match if match is not None else rf"\b{re.escape(arg)}\b"
    assert re.search(pattern, str(info.value)), f"{key}({arg}=...): message does not name it: {info.value}"


def test_every_public_function_has_a_baseline():
    public = {f"{m.__name__.split('.')[-1]}.{n}" for m in MODULES for n in m.__all__
              if callable(getattr(m, n)) and getattr(getattr(m, n), "__module__", "") == m.__name__
              and not isinstance(getattr(m, n), type)}
    assert public <= set(BASELINES), sorted(public - set(BASELINES))


@pytest.mark.parametrize("key", sorted(BASELINES))
def test_baseline_is_valid_and_finite(key):
    assert not _has_nonfinite(_call(key))


# ----------------------------------------------------------------------------
# generic spoils: every float array argument, every count, every positive number, every seed
# ----------------------------------------------------------------------------


def _array_args():
    for key, (_, kwargs) in sorted(BASELINES.items()):
        for arg, value in kwargs.items():
            if isinstance(value, np.ndarray) and value.dtype.kind == "f" and value.size:
                yield key, arg
            elif isinstance(value, list) and value and all(isinstance(v, float) for v in value):
                yield key, arg


ARRAY_ARGS = list(_array_args())


@pytest.mark.parametrize("key,arg", ARRAY_ARGS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_entry_is_refused_by_name(key, arg, bad):
    value = np.array(BASELINES[key][1][arg], dtype=float)
    value.flat[value.size // 2] = bad
    _refused(key, arg, value)


@pytest.mark.parametrize("key,arg", ARRAY_ARGS)
@pytest.mark.parametrize("bad", ["array", None, [[1.0, 2.0], [3.0]], np.array([1 + 2j])])
def test_wrong_type_for_an_array_is_refused_by_name(key, arg, bad):
    if bad is None and (key, arg) in {("kalman.predict", "B"), ("kalman.predict", "u"),
                                      ("noise.gaussian", "mean"), ("distributed_kf.mb_predict", "KH_prev")}:
        pytest.skip("None is this argument's documented default")
    _refused(key, arg, bad)


@settings(max_examples=50, deadline=None)
@given(data=st.data())
def test_nan_anywhere_in_any_array_is_refused(data):
    """Hypothesis picks the function, the argument and the entry."""
    key, arg = data.draw(st.sampled_from(ARRAY_ARGS))
    value = np.array(BASELINES[key][1][arg], dtype=float)
    value.flat[data.draw(st.integers(0, value.size - 1))] = data.draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    _refused(key, arg, value)


COUNTS = [(k, a) for k, (_, kw) in sorted(BASELINES.items()) for a, v in kw.items()
          if a in {"n", "n_agents", "m", "n_states", "n_steps", "dof", "n_runs", "window", "kron"}]


@pytest.mark.parametrize("key,arg", COUNTS)
@pytest.mark.parametrize("bad,exc", [(0, ValueError), (-1, ValueError), (2.5, TypeError), (2.0, TypeError),
                                     ("3", TypeError), (True, TypeError), (None, TypeError)])
def test_bad_count_is_refused_by_name(key, arg, bad, exc):
    _refused(key, arg, bad, exc)


POSITIVES = [(k, a) for k, (_, kw) in sorted(BASELINES.items()) for a, v in kw.items()
             if a in {"dt", "sensing_range", "rho1", "rho2", "tol"}]


@pytest.mark.parametrize("key,arg", POSITIVES)
@pytest.mark.parametrize("bad,exc", [(0.0, ValueError), (-0.5, ValueError), (np.nan, ValueError),
                                     (np.inf, ValueError), ("0.1", TypeError), (None, TypeError)])
def test_bad_positive_number_is_refused_by_name(key, arg, bad, exc):
    _refused(key, arg, bad, exc)


SEEDS = [k for k, (_, kw) in sorted(BASELINES.items()) if "rng" in kw]


@pytest.mark.parametrize("key", SEEDS)
@pytest.mark.parametrize("bad,exc", [(-1, ValueError), ("seed", TypeError), (1.5, TypeError), (None, TypeError)])
def test_bad_seed_is_refused_by_name(key, bad, exc):
    _refused(key, "rng", bad, exc)


FLAGS = [("sensing.sensing_mask", "allow_isolated"), ("distributed_kf.eb_initial_covariance", "common"),
         ("team_model.team_filter_model", "reduce"), ("rendezvous.simulate_rendezvous", "central"),
         ("rendezvous.simulate_rendezvous", "switching")]


@pytest.mark.parametrize("key,arg", FLAGS)
def test_non_boolean_flag_is_refused_by_name(key, arg):
    _refused(key, arg, "yes", TypeError)


# ----------------------------------------------------------------------------
# covariances: shape, symmetry, definiteness
# ----------------------------------------------------------------------------

COVARIANCES = [
    ("kalman.predict", "P", False), ("kalman.predict", "Q", False), ("kalman.update", "P", False),
    ("kalman.update", "R", True), ("kalman.kalman_gain", "P", False), ("kalman.kalman_gain", "R", False),
    ("kalman.nees", "P", True), ("noise.psd_factor", "M", False), ("noise.gaussian", "cov", False),
    ("noise.uniform_ellipsoid", "shape", False), ("sensing.team_noise_covariance", "R", False),
    ("sensing.measurement_noise", "R", False), ("sensing.measure", "R", False),
    ("team_model.team_filter_model", "Q", False), ("team_model.team_filter_model", "R", True),
    ("team_model.reduce_covariance", "P", False),
    ("distributed_kf.agent_update", "Sigma_pred", False), ("distributed_kf.agent_update", "R", True),
    ("distributed_kf.mb_predict", "Sigma", False), ("distributed_kf.mb_update", "Sigma_pred", False),
    ("distributed_kf.eb_initial_covariance", "P0", False), ("distributed_kf.eb_predict", "Sigma", False),
    ("distributed_kf.eb_update", "Sigma_pred", False), ("distributed_kf.agent_covariances", "Sigma", False),
    ("distributed_kf.plain_estimation_based_step", "Sigma", False),
    ("distributed_kf.plain_estimation_based_step", "Q", False),
    ("distributed_kf.plain_estimation_based_step", "R", True),
    ("distributed_kf.plain_measurement_based_step", "Sigma", False),
    ("centralized_team_filter.centralized_predict", "P", False), ("centralized_team_filter.centralized_update", "P_pred", True),
    ("team_observability.lyapunov_v", "Sigma_r", True), ("distributed_kf.team_nees", "Sigma_i", True),
    ("distributed_kf.f2_cross", "Sigma", False), ("team_observability.theorem1_min_eigenvalues", "Sigma_i", True),
    ("rendezvous.propagate_team", "Q", False), ("rendezvous.RendezvousModel", "Q", False),
    ("rendezvous.RendezvousModel", "R", False), ("rendezvous.simulate_rendezvous", "P0", False),
]


def _nonsymmetric(P):
    P = np.array(P, dtype=float)
    P[..., 0, -1] += 1.0
    return P


def _indefinite(P):
    P = np.array(P, dtype=float)
    n = P.shape[-1]
    return P - (np.abs(P).max() + 1.0) * np.eye(n) * (np.arange(n) == 0)  # one negative eigenvalue


@pytest.mark.parametrize("key,arg,definite", COVARIANCES)
def test_non_symmetric_covariance_is_refused(key, arg, definite):
    _refused(key, arg, _nonsymmetric(BASELINES[key][1][arg]), ValueError)


@pytest.mark.parametrize("key,arg,definite", COVARIANCES)
def test_indefinite_covariance_is_refused(key, arg, definite):
    _refused(key, arg, _indefinite(BASELINES[key][1][arg]), ValueError)
    _refused(key, arg, -np.array(BASELINES[key][1][arg]), ValueError)


@pytest.mark.parametrize("key,arg,definite", [c for c in COVARIANCES if c[2]])
def test_singular_covariance_is_refused_where_an_inverse_is_needed(key, arg, definite):
    value = np.array(BASELINES[key][1][arg], dtype=float)
    _refused(key, arg, np.zeros_like(value), ValueError, match=rf"{arg}.*positive definite")


@pytest.mark.parametrize("key,arg,definite", [c for c in COVARIANCES if c[:2] != ("noise.psd_factor", "M")])
def test_covariance_of_the_wrong_size_is_refused(key, arg, definite):
    """(psd_factor has nothing to compare the size of M with: any size is valid there.)"""
    value = np.array(BASELINES[key][1][arg], dtype=float)
    _refused(key, arg, value[..., :-1, :-1], ValueError)


# ----------------------------------------------------------------------------
# graph meaning: adjacency vs Laplacian, self-loops, weights
# ----------------------------------------------------------------------------

LAPLACIAN_ARGS = [("team_model.closed_loop_matrices", "laplacian"), ("distributed_kf.mb_predict", "laplacian"),
                  ("distributed_kf.eb_predict", "laplacian"), ("distributed_kf.f2_cross", "laplacian"),
                  ("team_observability.theorem1_min_eigenvalues", "laplacian"),
                  ("rendezvous.consensus_control", "laplacian")]
ADJACENCY_ARGS = [("graphs.laplacian", "A"), ("graphs.spanning_tree_roots", "A"), ("graphs.is_connected", "A"),
                  ("graphs.connected_components", "A"), ("graphs.require_connected", "A"),
                  ("graphs.has_spanning_tree", "A"), ("graphs.to_networkx", "A"),
                  ("sensing.sensing_mask", "adjacency"), ("sensing.neighbor_sets", "adjacency"),
                  ("sensing.selection_matrices", "adjacency"), ("sensing.measure", "adjacency"),
                  ("team_observability.observable_agents", "adjacency"), ("team_observability.require_observable", "adjacency"),
                  ("distributed_kf.plain_estimation_based_step", "adjacency"),
                  ("distributed_kf.plain_measurement_based_step", "adjacency"),
                  ("rendezvous.expected_spread", "adjacency"), ("rendezvous.simulate_rendezvous", "adjacency")]


@pytest.mark.parametrize("key,arg", LAPLACIAN_ARGS)
def test_adjacency_passed_as_laplacian_is_named(key, arg):
    _refused(key, arg, graphs.path_graph(N), ValueError, match=r"laplacian looks like an adjacency.*graphs\.laplacian")


@pytest.mark.parametrize("key,arg", LAPLACIAN_ARGS)
def test_non_laplacian_is_refused(key, arg):
    L = graphs.laplacian(graphs.path_graph(N))
    L[0, 1] = 0.5  # positive off-diagonal entry, rows no longer sum to zero
    _refused(key, arg, L, ValueError, match=r"laplacian must be a graph Laplacian")


def test_directed_laplacian_is_allowed_where_the_math_allows_it():
    """F_1 = I ⊗ A - L ⊗ BK and the consensus law hold for any Laplacian: directed rings are fine."""
    L = graphs.laplacian(graphs.adjacency_from_edges(3, [(0, 1), (1, 2), (2, 0)], directed=True))
    F1, F2 = team_model.closed_loop_matrices(AGENT.A, BK, L)
    assert np.all(np.isfinite(F1)) and np.all(np.isfinite(F2))
    assert np.all(np.isfinite(rv.consensus_control(np.ones((N, N, 4)), L, K_GAIN)))


@pytest.mark.parametrize("key,arg", ADJACENCY_ARGS)
def test_laplacian_passed_as_adjacency_is_named(key, arg):
    _refused(key, arg, graphs.laplacian(graphs.path_graph(N)), ValueError, match=rf"{arg} looks like a Laplacian")


@pytest.mark.parametrize("key,arg", ADJACENCY_ARGS)
def test_negative_weight_or_self_loop_is_refused(key, arg):
    bad = graphs.path_graph(N)
    bad[0, 1] = -1.0
    _refused(key, arg, bad, ValueError, match=rf"{arg}.*non-negative")
    loop = graphs.path_graph(N) + np.diag([0.0, 1.0, 0.0])
    _refused(key, arg, loop, ValueError, match=rf"{arg}.*zero diagonal")


@pytest.mark.parametrize("edges,exc,match", [
    ([(0, 1, np.nan)], ValueError, "finite positive weight"),
    ([(0, 1, np.inf)], ValueError, "finite positive weight"),
    ([(0, 1, -1.0)], ValueError, "finite positive weight"),
    ([(0, 1, "heavy")], TypeError, "weight"),
    ([(0.0, 1)], TypeError, "integer index"),
    ([(0, 0)], ValueError, "self-loop"),
    ([(0, 5)], ValueError, "outside"),
    ([(0,)], ValueError, "tuples"),
    ("01", TypeError, "edges"),
    (5, TypeError, "edges"),
])
def test_bad_edges_are_refused(edges, exc, match):
    with pytest.raises(exc, match=match) as info:
        graphs.adjacency_from_edges(3, edges)
    assert "edges" in str(info.value)


def test_mask_holding_nan_is_refused():
    """Issue 14: a NaN in a mask used to be read as True."""
    S = sensing.sensing_mask(graphs.path_graph(N)).astype(float)
    S[0, 2] = np.nan
    for key in ("distributed_kf.mb_update", "distributed_kf.eb_update", "centralized_team_filter.centralized_update",
                "distributed_kf.agent_update", "sensing.stacked_measurement"):
        _refused(key, "mask", S, ValueError)
    S[0, 2] = 0.5
    _refused("distributed_kf.eb_update", "mask", S, ValueError)
    _refused("distributed_kf.eb_update", "mask", np.zeros((N, N), bool), ValueError)  # agents must sense themselves


@pytest.mark.parametrize("key,arg,bad,exc", [
    ("graphs.star_graph", "center", 7, ValueError), ("graphs.star_graph", "center", 1.0, TypeError),
    ("graphs.to_networkx", "directed", "yes", TypeError),
    ("sensing.stacked_measurement", "agent", 5, ValueError), ("sensing.stacked_measurement", "agent", 1.0, TypeError),
    ("sensing.selection_matrix", "neighbors", np.array([0, 0]), ValueError),
    ("sensing.selection_matrix", "neighbors", np.array([0.0, 1.0]), TypeError),
    ("sensing.measurement_noise", "shape", (2.5,), TypeError),
    ("sensing.measurement_noise", "shape", (-1,), ValueError),
    ("noise.gaussian", "size", -2, ValueError), ("noise.gaussian", "size", 2.5, TypeError),
    ("noise.gaussian", "size", "3", TypeError), ("noise.uniform_box", "high", [-1.0, 2.0], ValueError),
    ("noise.uniform_box", "high", [1.0], ValueError),
    ("kalman.nees_interval", "confidence", 1.0, ValueError), ("kalman.nees_interval", "confidence", "0.9", TypeError),
    ("kalman.nees_interval", "confidence", np.nan, ValueError),
    ("team_model.reduce_covariance", "P", np.eye(5), ValueError),
    ("distributed_kf.eb_initial_covariance", "P0", np.eye(3), ValueError),
    ("distributed_kf.mb_predict", "model", "model", TypeError),
    ("distributed_kf.eb_update", "model", None, TypeError),
    ("distributed_kf.plain_estimation_based_step", "z", [np.ones(3)] * N, ValueError),
    ("distributed_kf.plain_estimation_based_step", "z", "z", TypeError),
    ("team_observability.lyapunov_v", "error", np.ones(5), ValueError),
    ("rendezvous.expected_spread", "mode", "estimation", ValueError),
    ("rendezvous.simulate_rendezvous", "mode", 3, ValueError),
    ("rendezvous.simulate_rendezvous", "x_hat0", np.zeros((1, 5)), ValueError),
    ("rendezvous.consensus_control", "K", np.ones((2, 3)), ValueError),
    ("rendezvous.propagate_team", "inputs", np.ones((2, N + 1, 2)), ValueError),
    ("kalman.predict", "F", np.eye(3), ValueError), ("kalman.update", "H", np.eye(3, 4), ValueError),
    ("kalman.update", "z", np.ones(3), ValueError), ("kalman.predict", "u", np.ones(3), ValueError),
    ("kalman.update", "x", np.zeros(3), ValueError), ("kalman.update", "x", 1.0, ValueError),
])
def test_specific_bad_values_are_refused_by_name(key, arg, bad, exc):
    _refused(key, arg, bad, exc)


def test_lone_B_or_u_is_refused():
    with pytest.raises(ValueError, match="B and u"):
        _call("kalman.predict", u=None)
    with pytest.raises(ValueError, match="B and u"):
        _call("kalman.predict", B=None)


# ----------------------------------------------------------------------------
# the examples of issue 14, one by one
# ----------------------------------------------------------------------------


def test_issue_examples_of_the_kalman_step():
    x, H, R = np.zeros(2), np.ones((1, 2)), np.eye(1)
    with pytest.raises(ValueError, match="P must be positive semidefinite"):
        kalman.update(x, -np.eye(2), np.zeros(1), H, R)
    with pytest.raises(ValueError, match="x contains NaN"):
        kalman.predict([np.nan, 2.0], np.eye(2), np.eye(2), np.eye(2))
    with pytest.raises(TypeError, match="R must be an array"):
        kalman.kalman_gain(np.eye(2), H, None)


def test_issue_examples_of_the_team_filter():
    model = _model()
    key = "distributed_kf.eb_update"
    Sig = np.array(BASELINES[key][1]["Sigma_pred"])
    Sig[0, 3, 5] = np.nan
    _refused(key, "Sigma_pred", Sig, ValueError, match="Sigma_pred contains NaN")
    Sig = -dk.eb_initial_covariance(model, np.eye(4))  # negative semidefinite
    _refused("distributed_kf.eb_predict", "Sigma", Sig, ValueError, match="Sigma must be positive semidefinite")
    _refused("centralized_team_filter.centralized_predict", "x", np.full((2, N, 4), np.nan), ValueError)
    _refused("team_model.closed_loop_matrices", "laplacian", graphs.ring_graph(3), ValueError,
             match="looks like an adjacency")
    with pytest.raises(ValueError, match="edges"):
        graphs.adjacency_from_edges(3, [(0, 1, np.nan)])


@pytest.mark.parametrize("key", SEEDS)
def test_negative_seed_names_rng(key):
    with pytest.raises(ValueError, match=r"rng must be a numpy\.random\.Generator or a non-negative integer"):
        _call(key, rng=-1)


# ----------------------------------------------------------------------------
# valid finite input never gives NaN/inf (hypothesis)
# ----------------------------------------------------------------------------

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), m=st.integers(1, 5), q=st.integers(1, 3), steps=st.integers(1, 20))
def test_random_valid_kalman_runs_stay_finite_symmetric_psd(seed, m, q, steps):
    rng = np.random.default_rng(seed)
    F = rng.normal(size=(m, m)) / np.sqrt(m)
    Q = _spd(rng, m) * rng.uniform(0, 2)
    H = rng.normal(size=(q, m))
    R = _spd(rng, q)
    x, P = rng.normal(size=m), _spd(rng, m)
    for _ in range(steps):
        x, P = kalman.predict(x, P, F, Q)
        x, P = kalman.update(x, P, rng.normal(size=q), H, R)
        assert np.all(np.isfinite(x)) and np.all(np.isfinite(P))
        np.testing.assert_array_equal(P, P.T)
        assert np.linalg.eigvalsh(P).min() > -1e-9 * np.abs(P).max()
    assert np.all(np.isfinite(kalman.kalman_gain(P, H, R)))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), scale=st.floats(1e-3, 1e3))
def test_random_valid_team_filter_steps_stay_finite(seed, scale):
    rng = np.random.default_rng(seed)
    model = _model()
    L = graphs.laplacian(graphs.complete_graph(N))
    S = sensing.sensing_mask(graphs.path_graph(N))
    X = scale * rng.normal(size=(2, N, N, 4))
    Z = scale * rng.normal(size=(2, N, N, 4))
    Sig = scale * _spd(rng, N * model.M_r, (1,))
    for out in (dk.eb_update(model, *dk.eb_predict(model, X, Sig, L), Z, S),
                dk.mb_update(model, *dk.mb_predict(model, X, dk.agent_covariances(model, Sig), L), Z, S)):
        assert not _has_nonfinite(out)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), size=st.integers(0, 4))
def test_random_noise_draws_are_finite(seed, size):
    rng = np.random.default_rng(seed)
    cov = _spd(rng, 3) * rng.uniform(0, 5)
    cov[0] = cov[:, 0] = 0.0  # singular (semidefinite) is allowed
    assert np.all(np.isfinite(noise.gaussian(rng, cov, size)))
    assert np.all(np.isfinite(noise.uniform_ellipsoid(rng, np.zeros(3), cov, size)))


def test_overflow_is_refused_not_returned():
    with pytest.raises(ValueError, match="Kalman prediction produced NaN or inf from finite input: the values overflow"):
        kalman.predict(np.full(2, 1e300), np.eye(2), 1e10 * np.eye(2), np.eye(2))
    model = kalman.LinearGaussianModel(1e10 * np.eye(2), np.eye(2), np.eye(2), np.eye(2))
    with pytest.raises(ValueError, match="Kalman prediction produced NaN or inf from finite input: the values overflow"):
        kalman.predict(np.full(2, 1e300), np.eye(2), model)


# ----------------------------------------------------------------------------
# a modified argument is never let through unchecked
# ----------------------------------------------------------------------------


def test_returned_state_modified_in_place_is_checked_again():
    F, Q, H, R = AGENT.A, 0.1 * np.eye(4), np.eye(2, 4), np.eye(2)
    x, P = kalman.predict(np.zeros(4), np.eye(4), F, Q)
    x, P = kalman.update(x, P, np.ones(2), H, R)
    P[0, 0] = -5.0  # the same object, now indefinite
    with pytest.raises(ValueError, match="P must be positive semidefinite"):
        kalman.predict(x, P, F, Q)
    x, P = kalman.predict(np.zeros(4), np.eye(4), F, Q)
    x[1] = np.nan
    with pytest.raises(ValueError, match="x contains NaN"):
        kalman.update(x, P, np.ones(2), H, R)


def test_constant_matrix_modified_in_place_is_checked_again():
    F, Q, H, R = AGENT.A.copy(), 0.1 * np.eye(4), np.eye(2, 4), np.eye(2)
    x, P = kalman.predict(np.zeros(4), np.eye(4), F, Q)
    Q[0, 0] = -1.0
    with pytest.raises(ValueError, match="Q must be positive semidefinite"):
        kalman.predict(x, P, F, Q)
    Q[0, 0] = 0.1
    x, P = kalman.predict(x, P, F, Q)
    x, P = kalman.update(x, P, np.ones(2), H, R)
    R[1, 1] = 0.0
    with pytest.raises(ValueError, match="R must be positive definite"):
        kalman.update(x, P, np.ones(2), H, R)
    F[2, 2] = np.inf
    with pytest.raises(ValueError, match="F contains NaN"):
        kalman.predict(x, P, F, 0.1 * np.eye(4))


def test_fresh_measurement_with_nan_is_named():
    F, Q, H, R = AGENT.A, 0.1 * np.eye(4), np.eye(2, 4), np.eye(2)
    x, P = kalman.predict(np.zeros(4), np.eye(4), F, Q)
    with pytest.raises(ValueError, match="z contains NaN"):
        kalman.update(x, P, np.array([1.0, np.nan]), H, R)


def test_returned_team_covariance_modified_in_place_is_checked_again():
    key = "distributed_kf.eb_predict"
    kwargs = dict(BASELINES[key][1])
    X, Sig = dk.eb_predict(**kwargs)
    Sig[0, 0, 0] = -10.0
    with pytest.raises(ValueError, match="Sigma_pred must be positive semidefinite"):
        dk.eb_update(kwargs["model"], X, Sig, BASELINES["distributed_kf.eb_update"][1]["Z"],
                     BASELINES["distributed_kf.eb_update"][1]["mask"])


def test_model_path_gives_the_plain_array_path_numbers():
    """The two forms of the step (model checked once, arrays checked every call) give the same bits."""
    F, Q, H, R = AGENT.A, 0.1 * np.eye(4), np.eye(2, 4), np.eye(2)
    model = kalman.LinearGaussianModel(F, Q, H, R)
    zs = np.random.default_rng(3).normal(size=(50, 2))
    a = b = (np.zeros(4), 10.0 * np.eye(4))
    for z in zs:
        a = kalman.update(*kalman.predict(*a, F, Q), z, H, R)
        b = kalman.update(*kalman.predict(*b, model), z, model)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_model_step_names_a_nan_input():
    """With a model only shapes are checked per call; a NaN passed in is named by the result's finiteness test."""
    model = kalman.LinearGaussianModel(AGENT.A, 0.1 * np.eye(4), np.eye(2, 4), np.eye(2), B=AGENT.B)
    x, P = np.zeros(4), np.eye(4)
    for arg, call in (("x", lambda: kalman.predict(np.array([0, np.nan, 0, 0]), P, model)),
                      ("P", lambda: kalman.update(x, np.diag([1.0, np.inf, 1.0, 1.0]), np.ones(2), model)),
                      ("z", lambda: kalman.update(x, P, np.array([1.0, np.nan]), model)),
                      ("u", lambda: kalman.predict(x, P, model, np.array([np.nan, 0.0])))):
        with pytest.raises(ValueError, match=rf"^{arg} contains NaN or infinite entries"):
            call()


# ----------------------------------------------------------------------------
# long horizon: the covariances stay symmetric positive definite at every step
# ----------------------------------------------------------------------------
#
# On a fixed model and graph a Kalman-type covariance recursion reads neither the data nor the step number: the next
# covariance is a function of the last one alone. Iterated in floating point it falls into a cycle (a fixed point or
# a round-off cycle of a few steps) within a few hundred steps; once a state repeats bit for bit, every later step
# repeats one already checked. So checking every step up to the first repeat proves symmetry and definiteness at
# 10^4 steps and at any other horizon (a run of 10^4 steps checked them there at 10-40 times the CPU).


def _check_until_a_repeat(step, state: tuple, definite=lambda state: state, symmetry: float = 1e-12,
                          max_steps: int = 1_000, max_period: int = 4) -> int:
    """Step a covariance recursion until its state repeats bit for bit; every state on the way is symmetric PD.

    Parameters
    ----------
    step : callable
        ``step(state) -> state``, a tuple of covariances, each ``(..., n, n)``; a function of `state` alone.
    state : tuple of ndarray
        The initial covariances; each must stay symmetric.
    definite : callable
        ``definite(state) -> tuple of (..., n, n) arrays`` that must stay symmetric positive definite
        (default: the state's covariances).
    symmetry : float
        Largest asymmetry allowed, relative to the largest entry (0: exactly symmetric).
    max_steps, max_period : int
        Fail if no state repeats one of the last `max_period` within `max_steps` steps.

    Returns
    -------
    int
        The step at which the state first repeats.
    """
    seen: list[tuple] = []
    for k in range(max_steps + 1):
        for P in (*state, *definite(state)):
            np.testing.assert_allclose(P, np.swapaxes(P, -1, -2), rtol=0, atol=symmetry * np.abs(P).max())
        assert all(np.linalg.eigvalsh(P).min() > 0 for P in definite(state)), k
        if any(all(np.array_equal(a, b) for a, b in zip(state, old)) for old in seen[-max_period:]):
            return k
        seen.append(state)
        state = step(state)
    pytest.fail(f"the covariances did not repeat within {max_steps} steps")


def test_kalman_filter_stays_symmetric_pd_at_every_step():
    F, Q, H, R = AGENT.A, 0.01 * np.eye(4), np.eye(2, 4), 0.25 * np.eye(2)
    x, z = np.zeros(4), np.zeros(2)  # the covariance does not read them

    def step(state):
        (P,) = state
        return (kalman.update(*kalman.predict(x, P, F, Q), z, H, R)[1],)

    assert _check_until_a_repeat(step, (10.0 * np.eye(4),), symmetry=0.0) < 1_000  # exactly symmetric
    rng = np.random.default_rng(7)
    x, P = np.zeros(4), 10.0 * np.eye(4)
    for zk in rng.normal(size=(300, 2)):  # the filter on data runs the same covariance recursion
        x, P = kalman.update(*kalman.predict(x, P, F, Q), zk, H, R)
    (expected,) = functools.reduce(lambda s, _: step(s), range(300), (10.0 * np.eye(4),))
    np.testing.assert_array_equal(P, expected)
    assert np.all(np.isfinite(x))


@pytest.mark.parametrize("mode", ["estimation", "measurement-filter"])
def test_team_filters_stay_symmetric_pd_at_every_step(mode):
    """Both team filters and the centralized one: their whole covariance state repeats (eb after 149 steps, period 2;
    mb after 111, period 1), and the closed loop (simulate_rendezvous) runs this recursion, step for step."""
    model = team_model.team_filter_model(AGENT.A, AGENT.B, K_GAIN, 0.01 * np.eye(4), 0.5 * np.eye(4), 2)
    adjacency = graphs.complete_graph(2)
    L, S = graphs.laplacian(adjacency), sensing.sensing_mask(adjacency)
    team = dk.TeamFilter(model, L, np.zeros((1, 8)), np.eye(4), mode="eb" if mode == "estimation" else "mb")
    central = centralized_team_filter.CentralizedTeamFilter(model, AGENT.B, np.zeros((1, 8)), np.eye(4))
    Z, U = np.zeros((1, 2, 2, 4)), np.zeros((1, 2, 2))  # the covariances do not read them
    sigma_i = [team.agent_covariances()[0]]

    def step(state):  # the filters' covariance state is (Sigma, P): the step's function of it
        team.predict()
        team.update(Z, S)
        central.predict(U)
        central.update(Z, S)
        sigma_i.append(team.agent_covariances()[0])
        return team.Sigma, central.P

    repeat = _check_until_a_repeat(step, (team.Sigma, central.P), lambda state: (  # eb: Sigma is singular at step 0
        sigma_i[-1], state[1]))
    rv_model = rv.RendezvousModel(AGENT.A, AGENT.B, K_GAIN, 0.01 * np.eye(4), 0.5 * np.eye(4), 0.1)
    res = rv.simulate_rendezvous(3, rv_model, np.random.default_rng(1).normal(size=(1, 2, 4)), adjacency, repeat,
                                 mode, x_hat0=np.zeros((1, 8)), P0=np.eye(4), central=True)
    np.testing.assert_array_equal(res.sigma_i, np.stack(sigma_i[:repeat + 1]))
    assert np.all(np.isfinite(res.nees)) and np.all(np.isfinite(res.central_pos_std))
