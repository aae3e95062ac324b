"""Bad input to the set-membership and control modules is refused by name (issue 14, "Nothing silent").

Modules: mascore.ellipsoids, mascore.set_membership, mascore.synchronization, mascore.lqr,
mascore.observers (and mascore._solver). For every public function a small valid call is
listed in ``BASE``; each argument is then spoiled in a way that is never valid (a NaN or
inf entry, a string, a count < 1, a negative seed) and the call must raise a
``ValueError``/``TypeError`` whose message names the argument. ``SEMANTIC`` lists the
spoils that need the function's meaning (an indefinite shape where a positive definite
one is needed, a directed Laplacian where a theorem needs a symmetric one, an adjacency
passed as a Laplacian, self-loops, a family parameter at 0 or 1, one agent, ...).
Validation happens before any computation, so the spoiled calls of the SDP-based
functions return at once.
"""

from __future__ import annotations

import copy
import inspect
import re
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mascore import ellipsoids as ell
from mascore import graphs, lqr, observers, riccati
from mascore import set_membership as smf
from mascore import synchronization as sync
from mascore._solver import solve

SETTINGS = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# ---------------------------------------------------------------- valid data

C0 = np.array([0.5, -0.2])
P0 = np.array([[2.0, 0.3], [0.3, 1.0]])
CM = np.array([[1.0, 0.5]])
YM = np.array([0.4])
WM = np.array([[0.5]])

A_SYNC = np.array([[0.0, -1.0], [1.0, 0.0]])
ADJ_RING_DIRECTED = np.array([[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], dtype=float)
PIN = np.array([1.0, 0.0, 0.0, 0.0])
GAMMA = sync.pinned_interaction_matrix(ADJ_RING_DIRECTED, PIN)
AC, BC = sync.closed_loop_matrices(A_SYNC, np.eye(2), A_SYNC, 1.5, GAMMA)

A_AG = np.array([[0.0, 1.0], [-1.0, -0.1]])
B_AG = np.array([[0.0], [1.0]])
C_AG = np.array([[1.0, 0.0]])
RING4 = graphs.ring_graph(4)
LAP4 = graphs.laplacian(RING4)
GAIN = lqr.DistributedGain(np.array([[1.0, 1.0]]), np.array([[0.1, 0.1]]))
L_OBS = observers.min_energy_observer(A_AG, B_AG, C_AG, [[10.0]], [[1.0]]).L
LAM4 = np.linalg.eigvalsh(LAP4)
LAM4[0] = 0.0
G_FACT = [B_AG] * 4
NOISE = [np.array([[10.0 + 5.0 * l]]) for l in LAM4]
A_E = observers.observer_error_matrix(A_AG, L_OBS, C_AG, 0.3, LAP4)
T_GRID = np.linspace(0.0, 1.0, 11)

BASE: dict[str, tuple] = {
    # ellipsoids
    "ellipsoids.Ellipsoid": (ell.Ellipsoid, dict(center=C0, shape=P0)),
    "ellipsoids.trace": (ell.trace, dict(shape=P0)),
    "ellipsoids.volume": (ell.volume, dict(shape=P0)),
    "ellipsoids.contains": (ell.contains, dict(points=[[0.1, 0.2]], center=C0, shape=P0, rtol=1e-9)),
    "ellipsoids.mahalanobis_sq": (ell.mahalanobis_sq, dict(points=[[0.1, 0.2]], center=C0, shape=P0)),
    "ellipsoids.affine_image": (ell.affine_image, dict(center=C0, shape=P0, M=[[1.0, 2.0], [0.0, 1.0], [1.0, 1.0]],
                                                       b=[1.0, 2.0, 3.0])),
    "ellipsoids.minkowski_sum": (ell.minkowski_sum, dict(center1=C0, shape1=P0, center2=-C0, shape2=np.eye(2),
                                                         beta=0.3)),
    "ellipsoids.minkowski_sum_min_trace": (ell.minkowski_sum_min_trace,
                                           dict(center1=C0, shape1=P0, center2=-C0, shape2=np.eye(2))),
    "ellipsoids.intersection_gain_form": (ell.intersection_gain_form, dict(center=C0, shape=P0, C=CM, y=YM, W=WM,
                                                                           t=0.4)),
    "ellipsoids.intersection_family": (ell.intersection_family, dict(center=C0, shape=P0, C=CM, y=YM, W=WM, t=0.4)),
    "ellipsoids.intersection_min_trace": (ell.intersection_min_trace, dict(center=C0, shape=P0, C=CM, y=YM, W=WM,
                                                                           tol=1e-13, max_iter=100)),
    "ellipsoids.max_innovation_form": (ell.max_innovation_form, dict(center=C0, shape=P0, C=CM, y=YM, W=WM,
                                                                     n_iter=60)),
    "ellipsoids.intersection_is_empty": (ell.intersection_is_empty, dict(center=C0, shape=P0, C=CM, y=YM, W=WM,
                                                                         rtol=1e-9)),
    "ellipsoids.sample_boundary": (ell.sample_boundary, dict(rng=0, center=C0, shape=P0, size=5)),
    "ellipsoids.sample_interior": (ell.sample_interior, dict(rng=0, center=C0, shape=P0, size=5)),
    # set_membership
    "set_membership.correct": (smf.correct, dict(center=C0, shape=P0, y=YM, C=CM, D=[[1.0]], R=[[0.5]])),
    "set_membership.predict": (smf.predict, dict(center=C0, shape=P0, A=A_SYNC, G=np.eye(2), Q=0.01 * np.eye(2),
                                                 B=np.eye(2), u=[0.1, 0.0])),
    "set_membership.run_filter": (smf.run_filter, dict(x0_hat=C0, P0=P0, y=np.full((3, 1), 0.4), A=A_SYNC,
                                                       G=np.eye(2), C=CM, D=[[1.0]], Q=0.01 * np.eye(2),
                                                       R=[[0.5]])),
    # synchronization
    "synchronization.riccati_like": (sync.riccati_like, dict(A=A_SYNC, B=np.eye(2), Q=0.1 * np.eye(2), rtol=1e-8)),
    "synchronization.riccati_like_residual": (sync.riccati_like_residual,
                                              dict(A=A_SYNC, B=np.eye(2), Q=0.1 * np.eye(2), P=0.1 * np.eye(2))),
    "synchronization.riccati_gain": (sync.riccati_gain, dict(A=A_SYNC, B=np.eye(2), P=0.1 * np.eye(2))),
    "synchronization.lemma2_r": (sync.lemma2_r, dict(A=A_SYNC, B=np.eye(2), Q=0.1 * np.eye(2), P=0.1 * np.eye(2))),
    "synchronization.check_assumption4": (sync.check_assumption4, dict(adjacency=ADJ_RING_DIRECTED, pinning=PIN)),
    "synchronization.pinned_interaction_matrix": (sync.pinned_interaction_matrix,
                                                  dict(adjacency=ADJ_RING_DIRECTED, pinning=PIN)),
    "synchronization.circle_contains": (sync.circle_contains, dict(points=[0.5, 0.6], c0=2 / 3, r0=0.6)),
    "synchronization.default_circle": (sync.default_circle, dict(adjacency=ADJ_RING_DIRECTED, pinning=PIN)),
    "synchronization.closed_loop_matrices": (sync.closed_loop_matrices, dict(A=A_SYNC, B=np.eye(2), K=A_SYNC, c=1.5,
                                                                             Gamma=GAMMA)),
    "synchronization.spectral_radius": (sync.spectral_radius, dict(M=AC)),
    "synchronization.power_norms": (sync.power_norms, dict(M=AC, k_max=20)),
    "synchronization.fit_alpha": (sync.fit_alpha, dict(M=AC, mu=0.9, k_max=50)),
    "synchronization.exponential_bound_ratio": (sync.exponential_bound_ratio, dict(M=AC, alpha=1.1, mu=0.9,
                                                                                   k_max=50)),
    "synchronization.mu_bar": (sync.mu_bar, dict(alpha=1.1, mu=0.9, n_agents=4)),
    "synchronization.bound_eq21": (sync.bound_eq21, dict(Bc=BC, G_dist=np.eye(2), p0=2.0, q_bar=0.1)),
    "synchronization.design_synchronization": (sync.design_synchronization,
                                               dict(A=A_SYNC, B=np.eye(2), Q=0.1 * np.eye(2),
                                                    adjacency=ADJ_RING_DIRECTED, pinning=PIN, c0=2 / 3, r0=0.6)),
    "synchronization.local_control": (sync.local_control, dict(xhat=np.ones((4, 2)), x_leader=[0.5, 0.5],
                                                               adjacency=ADJ_RING_DIRECTED, pinning=PIN, K=A_SYNC,
                                                               c=1.5)),
    # lqr
    "riccati.is_controllable": (riccati.is_controllable, dict(A=A_AG, B=B_AG, tol=1e-9)),
    "riccati.is_stabilizable": (riccati.is_stabilizable, dict(A=A_AG, B=B_AG, discrete=False, tol=1e-9)),
    "riccati.care": (riccati.care, dict(A=A_AG, B=B_AG, Q=np.eye(2), R=[[1.0]])),
    "riccati.dare": (riccati.dare, dict(A=0.5 * A_AG, B=B_AG, Q=np.eye(2), R=[[1.0]])),
    "lqr.dlqr": (lqr.dlqr, dict(A=0.5 * A_AG, B=B_AG, Q=np.eye(2), R=[[1.0]])),
    "lqr.lqr": (lqr.lqr, dict(A=A_AG, B=B_AG, Q=np.eye(2), R=[[1.0]])),
    "graphs.laplacian_spectrum": (graphs.laplacian_spectrum, dict(laplacian=LAP4)),
    "lqr.network_lqr_weights": (lqr.network_lqr_weights, dict(Q1=np.eye(2), Q2=np.eye(2), R=[[1.0]], laplacian=LAP4)),
    "lqr.centralized_network_lqr": (lqr.centralized_network_lqr, dict(A=A_AG, B=B_AG, Q1=np.eye(2), Q2=np.eye(2),
                                                                      R=[[1.0]], laplacian=LAP4)),
    "lqr.borrelli_keviczky_structure": (lqr.borrelli_keviczky_structure,
                                        dict(A=A_AG, B=B_AG, Q1=np.eye(2), Q2=np.eye(2), R=[[1.0]], n_agents=4)),
    "lqr.top_down_lqr": (lqr.top_down_lqr, dict(A=A_AG, B=B_AG, Q1=np.eye(2), Q2=np.eye(2), R=[[1.0]],
                                                adjacency=RING4)),
    "lqr.bottom_up_lqr": (lqr.bottom_up_lqr, dict(A=A_AG, B=B_AG, Q1=np.eye(2), Q2=np.eye(2), R=[[1.0]],
                                                  adjacency=RING4)),
    "lqr.assemble_network_gain": (lqr.assemble_network_gain, dict(gain=GAIN, laplacian=LAP4)),
    "lqr.network_controller_cost": (lqr.network_controller_cost, dict(A=A_AG, B=B_AG, Q1=np.eye(2), Q2=np.eye(2),
                                                                      R=[[1.0]], laplacian=LAP4, gain=GAIN)),
    "lqr.centralized_network_cost": (lqr.centralized_network_cost, dict(A=A_AG, B=B_AG, Q1=np.eye(2),
                                                                        Q2=np.eye(2), R=[[1.0]], laplacian=LAP4)),
    # observers
    "observers.is_observable": (observers.is_observable, dict(A=A_AG, C=C_AG)),
    "observers.min_energy_observer": (observers.min_energy_observer, dict(A=A_AG, Bbar=B_AG, C=C_AG, Q=[[10.0]],
                                                                          R=[[1.0]])),
    "observers.distributed_observer": (observers.distributed_observer,
                                       dict(A=A_AG, Bbar=B_AG, C=C_AG, Q1=10.0, Q2=5.0, R=1.0, adjacency=RING4)),
    "observers.coupled_gain_lmi": (observers.coupled_gain_lmi, dict(A=A_AG, C=C_AG, L=L_OBS, lam=LAM4,
                                                                    process_factors=G_FACT, noise_weights=NOISE)),
    "observers.bound_at_fixed_phi": (observers.bound_at_fixed_phi,
                                     dict(A=A_AG, C=C_AG, L=L_OBS, lam=LAM4, process_factors=G_FACT,
                                          noise_weights=NOISE, Phi=0.3)),
    "observers.observer_error_matrix": (observers.observer_error_matrix, dict(A=A_AG, L=L_OBS, C=C_AG, Phi=0.3,
                                                                              laplacian=LAP4)),
    "observers.simulate_estimation_errors": (observers.simulate_estimation_errors,
                                             dict(A_e=A_E, e0=np.ones((4, 2)), t=T_GRID)),
    "observers.simulate_network_observer": (observers.simulate_network_observer,
                                            dict(A=A_AG, C=C_AG, L=L_OBS, Phi=0.3, laplacian=LAP4, x0=np.ones((4, 2)),
                                                 x_hat0=np.zeros((4, 2)), t=T_GRID, Bbar=B_AG,
                                                 disturbance=np.zeros((11, 4, 1)))),
    "observers.disagreement": (observers.disagreement, dict(errors=np.ones((3, 4, 2)))),
    "observers.achieved_cost": (observers.achieved_cost, dict(A=A_AG, Bbar=B_AG, C=C_AG, R=[[1.0]], L=L_OBS,
                                                              Phi=0.3, lam=LAM4, noise_weights=NOISE, T=np.eye(2))),
}

#: Integer arguments that count something (>= 1).
COUNTS = {"size", "max_iter", "n_iter", "k_max", "n_agents"}
#: Arguments that are options or labels, not data.
SKIP = {"method", "reading", "trace_in", "what", "shrink", "agent", "step", "check_consistency", "gain"}


def _call(key: str, **changes):
    func, kwargs = BASE[key]
    kwargs = copy.deepcopy(kwargs)
    kwargs.update(changes)
    return func(**kwargs)


def _always_invalid(name: str, value) -> list[tuple[str, object]]:
    """(kind, spoiled value) pairs that no function may accept for this argument."""
    if name in SKIP:
        return []
    if name == "rng":
        return [("negative seed", -1), ("string seed", "seed"), ("float seed", 1.5)]
    if name in COUNTS:
        return [("zero", 0), ("negative", -1), ("float", 2.5), ("string", "3")]
    if isinstance(value, (list, tuple)) and value and isinstance(value[0], np.ndarray):  # sequence of matrices
        nan = [v.copy() for v in value]
        nan[0].flat[0] = np.nan
        return [("nan in first matrix", nan), ("string", "matrices")]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [("nan", float("nan")), ("inf", float("inf")), ("string", "0.1")]
    arr = np.asarray(value, dtype=float)
    nan, inf = arr.copy(), arr.copy()
    nan.flat[0] = np.nan
    inf.flat[-1] = np.inf
    return [("nan entry", nan), ("inf entry", inf), ("string", "array"), ("None", None)]


def _optional(func, name: str) -> bool:
    """True if `name` defaults to None (None is then a valid value: "not given")."""
    param = inspect.signature(func).parameters.get(name)
    return param is not None and param.default is None


ALWAYS_INVALID = [
    pytest.param(key, name, spoiled, id=f"{key}-{name}-{kind}")
    for key, (func, kwargs) in BASE.items()
    for name, value in kwargs.items()
    for kind, spoiled in _always_invalid(name, value)
    if not (spoiled is None and _optional(func, name))
]


@pytest.mark.parametrize("key", sorted(BASE))
def test_baseline_calls_are_valid(key):
    """Each baseline is itself a valid call (so a refusal below is due to the spoiled argument)."""
    result = _call(key)
    assert result is not None or key == "synchronization.check_assumption4"


@pytest.mark.parametrize("key,name,spoiled", ALWAYS_INVALID)
def test_always_invalid_spoil_is_refused_by_name(key, name, spoiled):
    with pytest.raises((ValueError, TypeError), match=re.escape(name)):
        _call(key, **{name: spoiled})


# ---------------------------------------------------------------- spoils that need the meaning

NEG_DEF = -np.eye(2)
INDEFINITE = np.diag([1.0, -1.0])
NONSYM = np.array([[2.0, 1.0], [0.0, 1.0]])
DIRECTED_LAP = graphs.laplacian(np.triu(RING4))
SELF_LOOP = RING4 + np.eye(4)
DISCONNECTED = np.kron(np.eye(2), np.array([[0.0, 1.0], [1.0, 0.0]]))

SEMANTIC = [
    # ellipsoids
    ("ellipsoids.contains", "shape", NEG_DEF, ValueError, "shape must be positive definite"),
    ("ellipsoids.contains", "shape", NONSYM, ValueError, "shape must be symmetric"),
    ("ellipsoids.contains", "center", [0.1, 0.2, 0.3], ValueError, "center must have last dimension 2"),
    ("ellipsoids.contains", "rtol", -1e-3, ValueError, "rtol"),
    ("ellipsoids.contains", "points", np.zeros((3, 2)), None, None),  # broadcasting against one centre: valid
    ("ellipsoids.mahalanobis_sq", "shape", np.zeros((2, 2)), ValueError, "shape must be positive definite"),
    ("ellipsoids.mahalanobis_sq", "points", np.zeros((3, 3)), ValueError, "points must have last dimension 2"),
    ("ellipsoids.Ellipsoid", "shape", NEG_DEF, ValueError, "shape must be positive definite"),
    ("ellipsoids.Ellipsoid", "center", [1.0], ValueError, "center must have length 2"),
    ("ellipsoids.affine_image", "M", [[1.0, 2.0, 3.0]], ValueError, "M has 3 columns"),
    ("ellipsoids.affine_image", "b", [1.0, 2.0], ValueError, "b must have shape"),
    ("ellipsoids.affine_image", "shape", INDEFINITE, ValueError, "shape must be positive semidefinite"),
    ("ellipsoids.minkowski_sum", "shape1", INDEFINITE, ValueError, "shape1 must be positive semidefinite"),
    ("ellipsoids.minkowski_sum", "shape2", -P0, ValueError, "shape2 must be positive semidefinite"),
    ("ellipsoids.minkowski_sum", "beta", 0.0, ValueError, "beta must lie strictly between 0 and 1"),
    ("ellipsoids.minkowski_sum", "beta", 1.0, ValueError, "beta must lie strictly between 0 and 1"),
    ("ellipsoids.minkowski_sum", "beta", [0.5, 1.5], ValueError, "beta must lie strictly between 0 and 1"),
    ("ellipsoids.minkowski_sum", "center2", [1.0, 2.0, 3.0], ValueError, "center2"),
    ("ellipsoids.minkowski_sum_min_trace", "shape1", INDEFINITE, ValueError, "shape1 must be positive semidefinite"),
    ("ellipsoids.minkowski_sum_min_trace", "shape2", np.eye(3), ValueError, "Incompatible dimensions of shape2"),
    ("ellipsoids.intersection_gain_form", "t", 0.0, ValueError, "t must lie strictly between 0 and 1"),
    ("ellipsoids.intersection_gain_form", "t", 1.0, ValueError, "t must lie strictly between 0 and 1"),
    ("ellipsoids.intersection_gain_form", "W", [[-1.0]], ValueError, "W must be positive definite"),
    ("ellipsoids.intersection_gain_form", "C", [[1.0, 0.0, 0.0]], ValueError, "Incompatible dimensions of C"),
    ("ellipsoids.intersection_gain_form", "y", [0.1, 0.2], ValueError, "y must have last dimension 1"),
    ("ellipsoids.intersection_gain_form", "shape", NEG_DEF, ValueError, "shape must be positive definite"),
    ("ellipsoids.intersection_family", "t", 1.0, ValueError, "t must lie strictly between 0 and 1"),
    ("ellipsoids.intersection_min_trace", "tol", 0.0, ValueError, "tol"),
    ("ellipsoids.intersection_min_trace", "max_iter", True, TypeError, "max_iter"),
    ("ellipsoids.intersection_min_trace", "shape", np.zeros((2, 2)), ValueError, "shape must be positive definite"),
    ("ellipsoids.max_innovation_form", "W", np.zeros((1, 1)), ValueError, "W must be positive definite"),
    ("ellipsoids.intersection_is_empty", "rtol", -1.0, ValueError, "rtol"),
    ("ellipsoids.sample_boundary", "shape", INDEFINITE, ValueError, "shape must be positive semidefinite"),
    ("ellipsoids.sample_interior", "size", (2, 0), ValueError, "size"),
    # set_membership
    ("set_membership.correct", "shape", NEG_DEF, ValueError, "shape matrix is not symmetric positive definite"),
    ("set_membership.correct", "R", [[-1.0]], ValueError, "R must be symmetric positive definite"),
    ("set_membership.correct", "C", [[1.0, 0.0, 0.0]], ValueError, "Incompatible dimensions of C"),
    ("set_membership.correct", "y", [0.1, 0.2], ValueError, "y must have last dimension 1"),
    ("set_membership.correct", "method", "kalman", ValueError, "method must be one of"),
    ("set_membership.correct", "method", 3, TypeError, "method must be one of"),
    ("set_membership.predict", "Q", -0.01 * np.eye(2), ValueError, "Q must be symmetric positive definite"),
    ("set_membership.predict", "u", None, ValueError, "give both B and u"),
    ("set_membership.predict", "A", np.eye(3), ValueError, "A"),
    ("set_membership.run_filter", "P0", NEG_DEF, ValueError, "P0 must be positive definite"),
    ("set_membership.run_filter", "x0_hat", [0.0, 0.0, 0.0], ValueError, "x0_hat must have last dimension 2"),
    ("set_membership.run_filter", "x0_hat", np.zeros((5, 2)), None, None),  # a batch of 5 filters: valid
    ("set_membership.run_filter", "y", [0.4, 0.4], ValueError, "y must be an array"),
    ("set_membership.run_filter", "method", "kalman", ValueError, "method must be one of"),
    # synchronization (directed graphs are valid; Assumption 4 and the weights are checked)
    ("synchronization.riccati_like", "Q", INDEFINITE, ValueError, "Q must be positive definite"),
    ("synchronization.riccati_like", "rtol", 0.0, ValueError, "rtol"),
    ("synchronization.riccati_like", "B", np.zeros((2, 0)), ValueError, "B must have at least one column"),
    ("synchronization.riccati_like_residual", "P", NEG_DEF, ValueError, "P must be positive definite"),
    ("synchronization.riccati_gain", "B", [[1.0, 2.0], [2.0, 4.0]], ValueError, "B must have full column rank"),
    ("synchronization.lemma2_r", "Q", np.zeros((2, 2)), ValueError, "Q must be positive definite"),
    ("synchronization.check_assumption4", "adjacency", ADJ_RING_DIRECTED + np.eye(4), ValueError, "no self-loops"),
    ("synchronization.check_assumption4", "adjacency", -ADJ_RING_DIRECTED, ValueError,
     "adjacency must have non-negative weights"),
    ("synchronization.check_assumption4", "adjacency", graphs.laplacian(ADJ_RING_DIRECTED), ValueError,
     "adjacency looks like a Laplacian"),
    ("synchronization.check_assumption4", "adjacency", np.zeros((4, 4)), ValueError,
     "no directed spanning tree .*adjacency"),
    ("synchronization.check_assumption4", "pinning", [-1.0, 0.0, 0.0, 0.0], ValueError,
     "pinning gains must be non-negative"),
    ("synchronization.check_assumption4", "pinning", [1.0, 0.0], ValueError, "pinning must have length 4"),
    ("synchronization.check_assumption4", "pinning", [0.0, 1.0, 0.0, 0.0], None, None),  # another root: valid
    ("synchronization.pinned_interaction_matrix", "pinning", np.zeros(4), ValueError, "no root of a spanning tree"),
    ("synchronization.circle_contains", "r0", 0.0, ValueError, "r0"),
    ("synchronization.circle_contains", "points", [1.0 + 1.0j], None, None),  # complex points: valid
    ("synchronization.closed_loop_matrices", "K", np.eye(3), ValueError, "Incompatible dimensions of K"),
    ("synchronization.closed_loop_matrices", "Gamma", np.ones((2, 3)), ValueError, "Gamma must be square"),
    ("synchronization.spectral_radius", "M", np.ones((2, 3)), ValueError, "M must be a non-empty square matrix"),
    ("synchronization.power_norms", "k_max", 2.0, TypeError, "k_max"),
    ("synchronization.fit_alpha", "mu", 1.5, ValueError, "mu"),
    ("synchronization.fit_alpha", "mu", 0.1, ValueError, r"rho\(A_c\) = .* < mu"),
    ("synchronization.exponential_bound_ratio", "alpha", 0.0, ValueError, "alpha"),
    ("synchronization.exponential_bound_ratio", "mu", -0.5, ValueError, "mu"),
    ("synchronization.mu_bar", "mu", 1.0, ValueError, r"mu must lie in \(0, 1\)"),
    ("synchronization.mu_bar", "n_agents", 4.0, TypeError, "n_agents"),
    ("synchronization.bound_eq21", "p0", -1.0, ValueError, "p0"),
    ("synchronization.bound_eq21", "q_bar", -1.0, ValueError, "q_bar"),
    ("synchronization.design_synchronization", "c0", 0.0, ValueError, "c0"),
    ("synchronization.design_synchronization", "r0", -0.6, ValueError, "r0"),
    ("synchronization.design_synchronization", "adjacency", np.ones((4, 4)) - np.eye(4), ValueError,
     r"Gamma \(eq. \(15\), from adjacency and pinning\)"),
    ("synchronization.local_control", "xhat", np.ones((3, 2)), ValueError, "xhat must have shape"),
    ("synchronization.local_control", "x_leader", [0.5], ValueError, "x_leader must have shape"),
    ("synchronization.local_control", "adjacency", ADJ_RING_DIRECTED + np.eye(4), ValueError, "adjacency"),
    ("synchronization.local_control", "pinning", -PIN, ValueError, "pinning gains must be non-negative"),
    ("synchronization.local_control", "c", "1.5", TypeError, "c must be a real number"),
    ("synchronization.local_control", "c", float("nan"), ValueError, "c must be finite"),
    # lqr: the network designs need undirected graphs (Laplacian eigenvectors orthogonal)
    ("lqr.lqr", "R", [[0.0]], ValueError, "R must be positive definite"),
    ("lqr.lqr", "Q", INDEFINITE, ValueError, "Q must be positive semidefinite"),
    ("riccati.is_controllable", "tol", 0.0, ValueError, "tol"),
    ("graphs.laplacian_spectrum", "laplacian", RING4, ValueError, r"laplacian looks like an adjacency matrix; pass "
                                                                r"mascore.graphs.laplacian\(A\)"),
    ("graphs.laplacian_spectrum", "laplacian", DIRECTED_LAP, ValueError,
     r"laplacian must be symmetric \(an undirected graph\)"),
    ("graphs.laplacian_spectrum", "laplacian", np.zeros((4, 4)), ValueError, "laplacian describes a disconnected graph"),
    ("lqr.network_lqr_weights", "laplacian", DIRECTED_LAP, ValueError, "laplacian must be symmetric"),
    ("lqr.network_lqr_weights", "Q2", INDEFINITE, ValueError, "Q2 must be positive semidefinite"),
    ("lqr.centralized_network_lqr", "laplacian", RING4, ValueError, "laplacian looks like an adjacency matrix"),
    ("lqr.borrelli_keviczky_structure", "n_agents", 2.5, TypeError, "n_agents"),
    ("lqr.top_down_lqr", "adjacency", SELF_LOOP, ValueError, "adjacency must have a zero diagonal"),
    ("lqr.top_down_lqr", "adjacency", np.triu(RING4), ValueError, r"adjacency must be symmetric \(an undirected"),
    ("lqr.top_down_lqr", "adjacency", LAP4, ValueError, "adjacency looks like a Laplacian"),
    ("lqr.top_down_lqr", "adjacency", DISCONNECTED, ValueError, "adjacency describes a disconnected graph"),
    ("lqr.bottom_up_lqr", "adjacency", SELF_LOOP, ValueError, "adjacency must have a zero diagonal"),
    ("lqr.bottom_up_lqr", "adjacency", np.triu(RING4), ValueError, "adjacency must be symmetric"),
    ("lqr.bottom_up_lqr", "adjacency", LAP4, ValueError, "adjacency looks like a Laplacian"),
    ("lqr.bottom_up_lqr", "adjacency", -RING4, ValueError, "adjacency must have non-negative weights"),
    ("lqr.bottom_up_lqr", "R", [[-1.0]], ValueError, "R must be positive definite"),
    ("lqr.assemble_network_gain", "laplacian", DIRECTED_LAP, ValueError,
     r"laplacian must be symmetric \(an undirected graph\)"),
    ("lqr.assemble_network_gain", "laplacian", RING4, ValueError, "laplacian looks like an adjacency matrix"),
    ("lqr.assemble_network_gain", "gain", "K", TypeError, "gain must be a DistributedGain"),
    # a DistributedGain with mismatched or NaN blocks is refused when built (tests/test_first_hour.py)
    ("lqr.network_controller_cost", "gain", lqr.DistributedGain(np.ones((2, 2)), np.ones((2, 2))), ValueError,
     "gain.K_self"),
    ("lqr.network_controller_cost", "laplacian", DIRECTED_LAP, ValueError, "laplacian must be symmetric"),
    ("lqr.centralized_network_cost", "laplacian", DISCONNECTED, ValueError, "laplacian looks like an adjacency"),
    # observers
    ("observers.distributed_observer", "adjacency", np.zeros((1, 1)), ValueError,
     "adjacency describes one agent: the distributed observer needs N >= 2"),
    ("observers.distributed_observer", "adjacency", np.triu(RING4), ValueError, "adjacency must be symmetric"),
    ("observers.distributed_observer", "adjacency", SELF_LOOP, ValueError, "adjacency must have a zero diagonal"),
    ("observers.distributed_observer", "adjacency", LAP4, ValueError, "adjacency looks like a Laplacian"),
    ("observers.distributed_observer", "Q1", -10.0, ValueError, "Q1 must be positive definite"),
    ("observers.distributed_observer", "Q2", -5.0, ValueError, "Q2 must be positive semidefinite"),
    ("observers.distributed_observer", "reading", "matlab", ValueError, "reading must be one of"),
    ("observers.distributed_observer", "trace_in", "both", ValueError, "trace_in must be"),
    ("observers.min_energy_observer", "Q", [[0.0]], ValueError, "Q must be positive definite"),
    ("observers.coupled_gain_lmi", "lam", [-1.0, 0.0, 2.0, 2.0], ValueError, "lam must hold non-negative"),
    ("observers.coupled_gain_lmi", "lam", [0.0, 2.0], ValueError, "process_factors needs one entry per eigenvalue"),
    ("observers.coupled_gain_lmi", "noise_weights", [np.array([[-1.0]])] * 4, ValueError,
     r"noise_weights\[0\] must be positive definite"),
    ("observers.coupled_gain_lmi", "noise_weights", 3.0, TypeError, "noise_weights must be a sequence"),
    ("observers.coupled_gain_lmi", "L", np.ones((2, 2)), ValueError, "Incompatible dimensions of L"),
    ("observers.bound_at_fixed_phi", "Phi", np.ones((2, 2)), ValueError, "Phi must be finite, one"),
    ("observers.observer_error_matrix", "laplacian", DIRECTED_LAP, ValueError,
     r"laplacian must be symmetric \(an undirected graph\)"),
    ("observers.observer_error_matrix", "laplacian", RING4, ValueError, "laplacian looks like an adjacency"),
    ("observers.simulate_estimation_errors", "t", [0.0, 0.1, 0.3], ValueError, "t must be uniform"),
    ("observers.simulate_estimation_errors", "e0", np.ones((3, 2)), ValueError, "e0 must have N"),
    ("observers.simulate_network_observer", "laplacian", DIRECTED_LAP, ValueError,
     r"laplacian must be symmetric \(an undirected graph\)"),
    ("observers.simulate_network_observer", "laplacian", RING4, ValueError, "laplacian looks like an adjacency"),
    ("observers.simulate_network_observer", "t", T_GRID[::-1], ValueError, "t must"),
    ("observers.simulate_network_observer", "disturbance", np.zeros((10, 4, 1)), ValueError,
     "disturbance must have shape"),
    ("observers.disagreement", "errors", np.ones(4), ValueError, "errors must be an array"),
    ("observers.achieved_cost", "lam", LAM4[:3], ValueError, "noise_weights needs one entry per eigenvalue"),
    ("observers.achieved_cost", "T", np.eye(3), ValueError, "Incompatible dimensions of T"),
]


@pytest.mark.parametrize("key,name,value,exc,match", SEMANTIC,
                         ids=[f"{k}-{n}-{i}" for i, (k, n, *_) in enumerate(SEMANTIC)])
def test_meaningful_spoil_is_refused_by_name(key, name, value, exc, match):
    if exc is None:  # a variation that is valid and must keep working
        _call(key, **{name: value})
        return
    with pytest.raises(exc, match=match):
        _call(key, **{name: value})


# ---------------------------------------------------------------- the items of the issue


@pytest.mark.parametrize("t", [0.0, 1.0])
def test_gain_form_at_the_ends_of_the_family_is_refused(t):
    """Was: a NaN shape."""
    with pytest.raises(ValueError, match="t must lie strictly between 0 and 1"):
        ell.intersection_gain_form(C0, P0, CM, YM, WM, t)


def test_minkowski_sum_of_an_indefinite_shape_is_refused():
    """Was: an indefinite result."""
    with pytest.raises(ValueError, match="shape2 must be positive semidefinite"):
        ell.minkowski_sum(C0, P0, C0, INDEFINITE, 0.5)


def test_contains_with_a_negative_definite_shape_is_refused():
    """Was: True (the quadratic form is negative)."""
    with pytest.raises(ValueError, match="shape must be positive definite"):
        ell.contains(np.array([[100.0, 100.0]]), C0, -np.eye(2))


def test_distributed_observer_with_one_agent_is_refused():
    """Was: disagreement_abscissa = -inf. One agent has no disagreement modes and Phi is undetermined."""
    with pytest.raises(ValueError, match="one agent.*min_energy_observer"):
        observers.distributed_observer(A_AG, B_AG, C_AG, 10.0, 5.0, 1.0, np.zeros((1, 1)))


def test_network_functions_refuse_directed_laplacians_and_say_why():
    for call in (lambda: lqr.assemble_network_gain(GAIN, DIRECTED_LAP),
                 lambda: observers.simulate_network_observer(A_AG, C_AG, L_OBS, 0.3, DIRECTED_LAP, np.ones((4, 2)),
                                                             np.zeros((4, 2)), T_GRID)):
        with pytest.raises(ValueError, match=r"laplacian must be symmetric \(an undirected graph\): .*eigenvectors"):
            call()


def test_bottom_up_lqr_refuses_self_loops():
    with pytest.raises(ValueError, match=r"adjacency must have a zero diagonal \(no self-loops\)"):
        lqr.bottom_up_lqr(A_AG, B_AG, np.eye(2), np.eye(2), [[1.0]], SELF_LOOP)


@pytest.mark.parametrize("func", [ell.sample_boundary, ell.sample_interior])
def test_negative_seed_is_refused_by_name(func):
    with pytest.raises(ValueError, match="rng must be a numpy.random.Generator or a non-negative integer seed"):
        func(-1, C0, P0, 3)
    with pytest.raises(ValueError, match="rng"):
        ell.Ellipsoid(C0, P0).sample_boundary(-1, 3)


def test_seed_and_generator_give_the_same_samples():
    for func in (ell.sample_boundary, ell.sample_interior):
        np.testing.assert_array_equal(func(7, C0, P0, 4), func(np.random.default_rng(7), C0, P0, 4))


def test_synchronization_keeps_the_directed_pinned_ring():
    """Bhattacharjee's example: a directed ring pinned at agent 1 is valid (Assumption 4 holds)."""
    d = sync.design_synchronization(A_SYNC, np.eye(2), 0.1 * np.eye(2), ADJ_RING_DIRECTED, PIN, 2 / 3, 0.6)
    assert d.rho < 1
    u = sync.local_control(np.ones((4, 2)), [0.0, 0.0], ADJ_RING_DIRECTED, PIN, d.K, d.c)
    assert np.all(np.isfinite(u))


def test_local_control_cache_does_not_alias_the_callers_arrays():
    adj, pin, K = ADJ_RING_DIRECTED.copy(), PIN.copy(), A_SYNC.copy()
    x = np.arange(8.0).reshape(4, 2)
    u1 = sync.local_control(x, [0.0, 0.0], adj, pin, K, 1.5)
    K *= 2.0  # in place: the next call sees the new value
    u2 = sync.local_control(x, [0.0, 0.0], adj, pin, K, 1.5)
    np.testing.assert_allclose(u2, 2 * u1)
    K /= 2.0
    np.testing.assert_array_equal(sync.local_control(x, [0.0, 0.0], adj, pin, K, 1.5), u1)


def test_run_filter_refuses_B_without_u():
    """Was: B silently ignored."""
    with pytest.raises(ValueError, match="give both B and u"):
        _call("set_membership.run_filter", B=np.eye(2))


def test_solver_refuses_a_non_problem():
    with pytest.raises(TypeError, match="problem must be a cvxpy.Problem"):
        solve("min x", "test program")


def test_documented_infinite_values_stay():
    """inf is a defined value where documented: the cost of an unstable loop, Lemma 2's r when A = 0."""
    unstable = lqr.DistributedGain(np.zeros((1, 2)), np.zeros((1, 2)))
    assert lqr.network_controller_cost(np.eye(2), B_AG, np.eye(2), np.eye(2), [[1.0]], LAP4, unstable,
                                       dt=0) == np.inf  # A = I in continuous time (dt=0 says so)
    assert sync.lemma2_r(np.zeros((2, 2)), np.eye(2), np.eye(2), np.eye(2)) == np.inf


def test_spoiled_sdp_calls_return_at_once():
    """Validation comes before the SDPs: a bad call costs no solve (bounded, no hang)."""
    start = time.perf_counter()
    for key, name, value in [("observers.distributed_observer", "adjacency", np.zeros((1, 1))),
                             ("lqr.bottom_up_lqr", "adjacency", SELF_LOOP),
                             ("observers.coupled_gain_lmi", "lam", [np.nan, 0.0, 2.0, 2.0]),
                             ("set_membership.correct", "shape", NEG_DEF)]:
        with pytest.raises(ValueError):
            _call(key, **{name: value}, **({"method": "sdp"} if key.startswith("set_membership") else {}))
    assert time.perf_counter() - start < 2.0


# ---------------------------------------------------------------- properties


def _pd(draw, n):
    M = np.array(draw(st.lists(st.floats(-3, 3), min_size=n * n, max_size=n * n))).reshape(n, n)
    return M @ M.T + draw(st.floats(0.05, 2.0)) * np.eye(n)


@st.composite
def prior_and_measurement(draw):
    n = draw(st.integers(1, 3))
    p = draw(st.integers(1, n))
    P = _pd(draw, n)
    c = np.array(draw(st.lists(st.floats(-10, 10), min_size=n, max_size=n)))
    C = np.array(draw(st.lists(st.floats(-2, 2), min_size=p * n, max_size=p * n))).reshape(p, n)
    C = C + np.eye(p, n)  # full row rank for most draws; any C is valid
    y = c @ C.T + np.array(draw(st.lists(st.floats(-0.5, 0.5), min_size=p, max_size=p)))
    W = _pd(draw, p)
    return c, P, C, y, W


@SETTINGS
@given(prior_and_measurement(), st.booleans())
def test_valid_finite_input_gives_finite_output(data, shrink):
    c, P, C, y, W = data
    q = ell.max_innovation_form(c, P, C, y, W)
    assert np.isfinite(q)
    new_c, new_P, L, t = ell.intersection_min_trace(c, P, C, y, W, shrink=shrink and q < 1)
    for out in (new_c, new_P, L, t):
        assert np.all(np.isfinite(out))
    c2, P2, b = ell.minkowski_sum_min_trace(c, P, -c, P)
    assert np.all(np.isfinite(P2)) and np.linalg.eigvalsh(P2)[0] > 0 and np.isfinite(b)
    assert np.isfinite(ell.mahalanobis_sq(c + 1.0, c, P))


@SETTINGS
@given(prior_and_measurement(), st.sampled_from(["center", "shape", "C", "y", "W"]), st.data())
def test_a_nan_anywhere_is_refused_by_name(data, name, draw):
    args = dict(zip(["center", "shape", "C", "y", "W"], [a.copy() for a in data]))
    arr = args[name]
    arr.flat[draw.draw(st.integers(0, arr.size - 1))] = draw.draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    for func in (ell.intersection_min_trace, ell.max_innovation_form, ell.intersection_is_empty):
        with pytest.raises(ValueError, match=f"{name} contains NaN or infinite entries"):
            func(**args)


@SETTINGS
@given(st.integers(1, 4), st.data())
def test_indefinite_shapes_are_refused_by_name(n, data):
    Q, _ = np.linalg.qr(np.array(data.draw(st.lists(st.floats(-1, 1), min_size=n * n, max_size=n * n))).reshape(n, n)
                        + 3 * np.eye(n))
    eig = np.array(data.draw(st.lists(st.floats(0.1, 5), min_size=n, max_size=n)))
    eig[data.draw(st.integers(0, n - 1))] *= -1.0  # one negative eigenvalue
    S = Q @ np.diag(eig) @ Q.T
    S = 0.5 * (S + S.T)
    c = np.zeros(n)
    with pytest.raises(ValueError, match="shape must be positive definite"):
        ell.contains(np.ones(n), c, S)
    with pytest.raises(ValueError, match="shape1 must be positive semidefinite"):
        ell.minkowski_sum(c, S, c, np.eye(n), 0.5)
    with pytest.raises(ValueError, match="P0 must be positive definite"):
        smf.run_filter(c, S, np.zeros((2, 1)), np.eye(n), np.eye(n), np.eye(1, n), [[1.0]], np.eye(n), [[1.0]])


@SETTINGS
@given(st.integers(2, 6), st.data())
def test_random_directed_graphs_are_refused_where_a_symmetric_laplacian_is_needed(N, data):
    upper = np.triu(np.array(data.draw(st.lists(st.sampled_from([0.0, 1.0, 2.5]), min_size=N * N,
                                                max_size=N * N))).reshape(N, N), 1)
    adj = upper + upper.T
    i, j = data.draw(st.sampled_from([(a, b) for a in range(N) for b in range(N) if a != b]))
    adj[i, j] += 1.0  # one asymmetric weight
    Lap = graphs.laplacian(adj)
    with pytest.raises(ValueError, match="laplacian must be symmetric"):
        graphs.laplacian_spectrum(Lap)
    with pytest.raises(ValueError, match="laplacian must be symmetric"):
        lqr.assemble_network_gain(GAIN, Lap)
    with pytest.raises(ValueError, match="adjacency must be symmetric"):
        lqr.top_down_lqr(A_AG, B_AG, np.eye(2), np.eye(2), [[1.0]], adj)
    # the synchronization law accepts it (directed graphs are the paper's setting)
    assert np.all(np.isfinite(sync.local_control(np.ones((N, 2)), [0.0, 0.0], adj, np.ones(N), A_SYNC, 1.0)))


def test_set_membership_filter_stays_pd_and_contains_the_truth_over_10_000_steps():
    """Long horizon: the correction shapes stay symmetric positive definite and finite, and the
    true state of a system driven by bounded noise stays inside every correction ellipsoid."""
    from mascore import set_membership as smf

    rng = np.random.default_rng(11)
    A = np.array([[np.cos(0.1), -np.sin(0.1)], [np.sin(0.1), np.cos(0.1)]])
    G, C, D = np.eye(2), np.array([[1.0, 0.0]]), np.eye(1)
    Q, R = 0.01 * np.eye(2), 0.01 * np.eye(1)
    n_steps = 10_000
    # w_k in the ball of shape Q (radius 0.1), v_k in [-0.1, 0.1]: inside E(0, Q) and E(0, R)
    w = rng.uniform(-1, 1, (n_steps, 2)) * 0.1 / np.sqrt(2)
    v = rng.uniform(-0.1, 0.1, (n_steps + 1, 1))
    x = np.array([1.0, -0.5])
    xs = [x]
    for k in range(n_steps):
        x = A @ x + w[k]
        xs.append(x)
    xs = np.array(xs)
    y = xs @ C.T + v
    hist = smf.run_filter(np.zeros(2), 4.0 * np.eye(2), y, A, G, C, D, Q, R)
    P = hist.shape_corr
    assert np.all(np.isfinite(P)) and np.allclose(P, np.swapaxes(P, -1, -2))
    assert np.linalg.eigvalsh(P).min() > 0
    e = xs - hist.center_corr
    assert np.max(np.einsum("ki,ki->k", e, np.linalg.solve(P, e[..., None])[..., 0])) <= 1 + 1e-9
