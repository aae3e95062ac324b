"""Consensus with relative confidence: the Kalman consensus of Ren, Beard and Kingston (2005).

Each of ``n`` agents holds an *information state* ``xi_i`` (a vector of size
``m``) and a covariance ``P_i`` (``m x m``) that says how sure it is. Agent
``i`` treats the states it hears from its neighbours as noisy measurements of
the unknown consensus value and runs one Kalman filter on them:

* discrete time, Ren et al. eqs. (4)-(5)::

      P_i[k+1]  = [ (P_i + Q)^-1 + sum_j g_ij (P_j + Omega_ij)^-1 ]^-1
      xi_i[k+1] = xi_i + P_i[k+1] sum_j g_ij (P_j + Omega_ij)^-1 (xi_j + nu_ij - xi_i)

* continuous time, eqs. (1)-(3)::

      dP_i/dt  = -P_i [ sum_j g_ij(t) (P_j + Omega_ij)^-1 ] P_i + Q
      K_ij     = P_i (P_j + Omega_ij)^-1
      dxi_i/dt = sum_j g_ij(t) K_ij (xi_j + nu_ij - xi_i)

The sums run over ``j = 1..n`` *including* ``j = i`` with ``g_ii = 1``, as the
paper defines (its proof of Theorem 3.2 uses the self term to bound ``P_i``
from above). The self term adds information to ``P_i`` but nothing to
``xi_i`` (its innovation is zero); pass ``include_self=False`` to drop it.
Communication noise ``nu_ij ~ N(0, Omega_ij)`` is drawn only for messages that
are actually received (``j != i``, ``g_ij = 1``); an agent reads its own state
without noise.

Conventions
-----------
* Topologies follow :mod:`mascore.graphs`: ``G[i, j] > 0`` means agent ``i``
  hears agent ``j`` (``g_ij = 1``); the diagonal must be zero (``g_ii = 1`` is
  implied). Positive weights are read as ``g_ij = 1`` (the derivation needs
  boolean links).
* States: a scalar problem uses ``xi`` of shape ``(n,)`` and ``P`` of shape
  ``(n,)``; a vector problem uses ``(n, m)`` and ``(n, m, m)``. Leading batch
  axes (independent Monte Carlo runs) are allowed on both: ``(..., n)`` /
  ``(..., n)`` or ``(..., n, m)`` / ``(..., n, m, m)``.
* A switching topology in discrete time is an array ``(K, n, n)`` (or
  ``(K, ..., n, n)`` for one topology per batch member), a single ``(n, n)``
  graph, or a function ``k -> (n, n)``. In continuous time it is a
  :class:`SwitchingTopology`, a single graph, or a function ``t -> (n, n)``
  held constant between given switching times.
* Directed graphs are fine everywhere (Ren et al. use directed switching
  graphs); the theorems need a spanning tree in the union over bounded
  windows, not symmetry (:func:`union_condition_holds`).

Input checks and degenerate cases
---------------------------------
Every public function checks its arguments and raises a ``ValueError`` (bad
value or shape) or ``TypeError`` (wrong type) that names the argument. A graph
Laplacian passed where an adjacency is expected is named as such. The long runs
pay the checks once, then call unchecked private kernels.

* One agent (``n = 1``) and an isolated agent (a zero row of ``G``) are
  defined: such an agent hears nobody, keeps its state, and its covariance
  follows eq. (4) with the self term only.
* Zero communication noise (``Omega`` singular) is accepted, but every message
  then counts as exact and ``P`` shrinks geometrically: after a few hundred
  steps it underflows double precision. The runs then raise
  :class:`~mascore.exceptions.ConsensusBreakdownError`, naming the step, instead of returning NaN.
* Horizons are bounded: at most :data:`MAX_STEPS` steps (discrete time and
  Euler-Maruyama) and at most :data:`ODE_MAX_EVALUATIONS` right-hand-side
  evaluations of the ODE solver; a longer run raises a ``ValueError`` naming
  ``n_steps`` or ``t_final`` instead of hanging.

Units: time in s (``t``, ``dt``, ``t_final``, dwell times); the consensus states ``xi`` in the
user's state unit; ``Q`` and ``Omega`` are noise *covariances* per step, in (state unit)^2 (in the
continuous-time functions, intensities in (state unit)^2/s); the filters' ``P`` in (state unit)^2;
adjacency weights and gains in 1/s (continuous time) or dimensionless (per step).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._validation import (
    MAX_STEPS,
    Frozen,
    check_covariance,
    check_fits_in_memory,
    check_generator,
    check_positive,
    check_positive_int,
    check_steps,
    frozen_copy,
    symmetric_part,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .exceptions import ConsensusBreakdownError
from .graphs import has_spanning_tree, unions_over_windows

__all__ = [
    "ConsensusResult",
    "MAX_STEPS",
    "MAX_STORED",
    "ODE_MAX_EVALUATIONS",
    "SwitchingTopology",
    "average_consensus",
    "central_fusion",
    "consensus_matrix",
    "error_covariance",
    "kalman_consensus_continuous",
    "kalman_consensus_discrete",
    "kalman_consensus_step",
    "periodic_sequence",
    "random_pairings",
    "spanning_tree_windows",
    "spread",
    "union_condition_holds",
]


# MAX_STEPS (from mascore._validation): the largest number of steps of a discrete run or of an Euler-Maruyama
# integration ("absurdly many" beyond).
#: Largest number of stored numbers in a returned trajectory (8 bytes each: 2 GB).
MAX_STORED = 250_000_000
#: Largest number of right-hand-side evaluations of the ODE solver in one continuous run.
ODE_MAX_EVALUATIONS = 1_000_000
#: A continuous run is stopped early when the solver's pace so far projects more than this many
#: times :data:`ODE_MAX_EVALUATIONS` (``t_final = 1e300`` is refused in a fraction of a second).
_ODE_PROJECTION_FACTOR = 10_000
_ODE_CHECK_EVERY = 10_000


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class ConsensusResult:
    """Trajectory of a consensus run.

    A run's output: its arrays are the caller's, writeable and shared with no model or filter.

    Parameters
    ----------
    t : (T,) ndarray
        Step indices (discrete time) or times in s (continuous time).
    xi : (T, ..., n) or (T, ..., n, m) ndarray
        Information states.
    P : (T, ..., n) or (T, ..., n, m, m) ndarray, or None
        Covariances (None for ordinary average consensus).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> run = consensus.kalman_consensus_discrete([0.0, 2.0], [1.0, 1.0], graphs.complete_graph(2), 0.0, 0.1, n_steps=3)
    >>> run.t, run.scalar
    (array([0, 1, 2, 3]), True)
    """

    t: np.ndarray
    xi: np.ndarray
    P: np.ndarray | None

    @property
    def scalar(self) -> bool:
        """True for a scalar information state (``xi`` has no ``m`` axis)."""
        return self.P is None or self.P.ndim == self.xi.ndim

    @property
    def spread(self) -> np.ndarray:
        """Largest pairwise disagreement ``max_ij ||xi_i - xi_j||_inf`` at each time, shape (T, ...)."""
        return spread(self.xi if not self.scalar else self.xi[..., None])

    @property
    def final_value(self) -> np.ndarray:
        """Mean of the agents' final states, shape (...) or (..., m)."""
        return self.xi[-1].mean(axis=-1 if self.scalar else -2)


@dataclass(frozen=True, eq=False)
class SwitchingTopology(Frozen):
    """A piecewise-constant topology ``G(t)`` for continuous-time consensus.

    Graph ``graphs[k]`` is active on ``[times[k], times[k+1])``; the last one
    stays active for ever.

    Parameters
    ----------
    times : (S,) array_like
        Increasing switching times (s), ``times[0]`` the start.
    graphs : (S, n, n) array_like
        Adjacency matrices (``G[i, j] > 0``: ``i`` hears ``j``).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> topo = consensus.SwitchingTopology([0.0, 1.0], [graphs.path_graph(3), graphs.ring_graph(3)])
    >>> topo.n_agents
    3
    """

    times: np.ndarray
    graphs: np.ndarray

    def __post_init__(self):
        times = _float_array(self.times, "times")
        graphs = _check_topologies(self.graphs, None, "graphs", stacked=True)
        if times.ndim != 1 or times.shape[0] != graphs.shape[0]:
            raise ValueError(
                f"times must be 1-D with one entry per graph ({graphs.shape[0]}); got shape {times.shape}"
            )
        if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise ValueError("times must be finite and strictly increasing")
        if graphs.ndim != 3:
            raise ValueError(f"graphs must have shape (S, n, n) (one graph per switching time); got {graphs.shape}")
        self._set(times=frozen_copy(times), graphs=frozen_copy(graphs))

    @property
    def n_agents(self) -> int:
        """Number of agents n."""
        return self.graphs.shape[-1]

    def at(self, t: float) -> np.ndarray:
        """The graph active at time `t`.

        Parameters
        ----------
        t : float
            Time (s).

        Returns
        -------
        (n, n) ndarray
            ``graphs[k]`` with ``times[k] <= t < times[k+1]``.

        Examples
        --------
        >>> from mascore import consensus, graphs
        >>> topo = consensus.SwitchingTopology([0.0, 1.0], [graphs.path_graph(3), graphs.ring_graph(3)])
        >>> int(topo.at(0.5).sum()), int(topo.at(2.0).sum())
        (4, 6)
        """
        if isinstance(t, bool) or not isinstance(t, (int, float, np.integer, np.floating)) or not np.isfinite(t):
            raise ValueError(f"t must be a finite time (s); got {t!r}")
        k = int(np.searchsorted(self.times, t, side="right")) - 1
        return self.graphs[max(k, 0)]

    @classmethod
    def periodic(cls, graphs: ArrayLike, dwell: float, t_final: float, t0: float = 0.0) -> SwitchingTopology:
        """Cycle through `graphs`, each held for `dwell` s, from `t0` up to `t_final`.

        Parameters
        ----------
        graphs : (S, n, n) array_like
            The graphs to cycle through.
        dwell : float
            Time each graph is held (s).
        t_final : float
            End of the schedule (s).
        t0 : float
            Start (s).

        Returns
        -------
        SwitchingTopology
            The schedule.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import consensus, graphs
        >>> topo = consensus.SwitchingTopology.periodic(np.stack([graphs.path_graph(3), graphs.ring_graph(3)]), 0.5, 2.0)
        >>> topo.times
        array([0. , 0.5, 1. , 1.5])
        """
        graphs = _check_topologies(graphs, None, "graphs", stacked=True)
        dwell = check_positive(dwell, "dwell", "s")
        t_final = _finite_number(t_final, "t_final")
        t0 = _finite_number(t0, "t0")
        if t_final <= t0:
            raise ValueError(f"t_final must be later than t0 = {t0:g} s; got {t_final:g}")
        if (t_final - t0) / dwell > MAX_STEPS:
            raise ValueError(f"dwell = {dwell:g} s over [t0, t_final] = [{t0:g}, {t_final:g}] s gives more than "
                             f"{MAX_STEPS} switches; use a longer dwell or a shorter t_final")
        times = np.arange(t0, t_final, dwell)
        return cls(times, graphs[np.arange(times.size) % graphs.shape[0]])


# --------------------------------------------------------------------------- discrete time


def kalman_consensus_step(
    xi: ArrayLike,
    P: ArrayLike,
    G: ArrayLike,
    Q: ArrayLike,
    Omega: ArrayLike,
    rng: np.random.Generator | int | None = None,
    include_self: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """One step of discrete-time Kalman consensus, Ren et al. eqs. (4)-(5).

    Parameters
    ----------
    xi : (..., n) or (..., n, m) array_like
        Information states ``xi[k]``.
    P : (..., n) or (..., n, m, m) array_like
        Covariances ``P[k]`` (symmetric positive definite).
    G : (n, n) or (..., n, n) array_like
        Topology at step k (``G[i, j] > 0``: ``i`` hears ``j``), zero diagonal.
    Q : float, (m, m) or (n, m, m) array_like
        Process-noise covariance of the consensus value per step (per agent if (n, m, m)), in
        (state unit)^2.
    Omega : float, (m, m) or (n, n, m, m) array_like
        Communication-noise covariance ``Omega_ij`` of a received state (common or per link), in
        (state unit)^2.
    rng : numpy.random.Generator or int, optional
        If given, communication noise ``nu_ij ~ N(0, Omega_ij)`` is drawn and
        added to every received state; if None the messages are noise-free
        (``Omega`` still weights them, as in the paper's Fig. 1).
    include_self : bool
        Keep the ``g_ii = 1`` term of eq. (4) (default, as in the paper).

    Returns
    -------
    xi_next : ndarray
        ``xi[k+1]``, the shape of `xi`.
    P_next : ndarray
        ``P[k+1]``, the shape of `P`.

    Raises
    ------
    ConsensusBreakdownError
        If ``P_next`` underflows to zero or the result overflows (e.g. ``Omega = 0``
        after a long run made ``P`` tiny).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> xi, P = consensus.kalman_consensus_step([0.0, 4.0], [1.0, 3.0], graphs.complete_graph(2), Q=0.0, Omega=0.0)
    >>> np.round(xi, 3)                            # agent 0 (P = 1) is more confident: it moves less
    array([0.571, 1.6  ])
    """
    scalar, xi_v, P_m = _as_state(xi, P, "xi", "P")
    n, m = xi_v.shape[-2], xi_v.shape[-1]
    g = _check_topologies(G, n, "G", stacked=False, states="xi and P")
    _check_batch(g.shape[:-2], xi_v.shape[:-2], "G")
    Q_, Om = _expand_Q(Q, n, m), _expand_omega(Omega, n, m)
    gen = None if rng is None else check_generator(rng)
    _check_bool(include_self, "include_self")
    try:
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            xi_next, P_next = _step(xi_v, P_m, g, Q_, Om, gen, include_self)
    except np.linalg.LinAlgError:
        xi_next, P_next = np.full_like(xi_v, np.nan), np.full_like(P_m, np.nan)
    _check_trajectory(np.stack([xi_v, xi_next]), np.stack([P_m, P_next]), Om, "step", "kalman_consensus_step")
    return _from_state(scalar, xi_next, P_next)


def kalman_consensus_discrete(
    xi0: ArrayLike,
    P0: ArrayLike,
    topologies: ArrayLike | Callable[[int], ArrayLike],
    Q: ArrayLike,
    Omega: ArrayLike,
    n_steps: int | None = None,
    rng: np.random.Generator | int | None = None,
    include_self: bool = True,
) -> ConsensusResult:
    """Run discrete-time Kalman consensus, Ren et al. eqs. (4)-(5).

    Parameters
    ----------
    xi0 : (..., n) or (..., n, m) array_like
        Initial information states, as `xi` of :func:`kalman_consensus_step`.
    P0 : (..., n) or (..., n, m, m) array_like
        Initial covariances, as `P` of :func:`kalman_consensus_step`.
    topologies : (K, n, n) or (K, ..., n, n) array_like, (n, n) array_like, or callable
        ``g_ij[k]`` for ``k = 0..K-1``: a sequence (one graph per step, or one
        per step and batch member), a fixed graph, or a function ``k -> (n, n)``.
    Q : float, (m, m) or (n, m, m) array_like
        Process-noise covariance per step, in (state unit)^2, as in :func:`kalman_consensus_step`.
    Omega : float, (m, m) or (n, n, m, m) array_like
        Communication-noise covariance, in (state unit)^2, as in :func:`kalman_consensus_step`.
    n_steps : int, optional
        Number of steps; defaults to ``K`` for a sequence, required otherwise.
    rng : numpy.random.Generator or int, optional
        Source of communication noise; None for noise-free messages.
    include_self : bool
        Keep the ``g_ii = 1`` term.

    Returns
    -------
    ConsensusResult
        ``t = 0..n_steps``; ``xi`` and ``P`` with a leading time axis of length ``n_steps + 1``.

    Raises
    ------
    ConsensusBreakdownError
        If ``P`` underflows to zero or a value overflows during the run. With
        zero communication noise (``Omega = 0``) every message counts as exact
        and ``P`` shrinks geometrically (by about ``1 / (1 + d_i)`` a step): on
        a ring of 5 agents it leaves double precision at step 512. The message
        names the step; the states have agreed to machine precision long before.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> run = consensus.kalman_consensus_discrete([0.0, 2.0, 4.0], [1.0, 1.0, 1.0], graphs.path_graph(3),
    ...                                         Q=0.01, Omega=0.1, n_steps=60)
    >>> bool(run.spread[-1] < 1e-3 * run.spread[0]), run.xi.shape
    (True, (61, 3))
    """
    scalar, xi, P = _as_state(xi0, P0, "xi0", "P0")
    n, m = xi.shape[-2], xi.shape[-1]
    Q_, Om = _expand_Q(Q, n, m), _expand_omega(Omega, n, m)
    gen = None if rng is None else check_generator(rng)
    _check_bool(include_self, "include_self")
    graph_at, n_steps = _discrete_topology(topologies, n, n_steps, xi.shape[:-2])
    _check_storage(n_steps, xi.size + P.size, "n_steps")
    return _run_discrete(scalar, xi, P, graph_at, n_steps, Q_, Om, gen, include_self, "kalman_consensus_discrete")


def _run_discrete(scalar, xi, P, graph_at, n_steps, Q_, Om, gen, include_self, who):
    """The loop of :func:`kalman_consensus_discrete` on checked arguments; the trajectory is checked at the end."""
    xs, Ps = [xi], [P]
    try:
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            for k in range(n_steps):
                xi, P = _step(xi, P, graph_at(k), Q_, Om, gen, include_self)
                xs.append(xi)
                Ps.append(P)
    except np.linalg.LinAlgError:  # a covariance became exactly singular: the step that failed is len(xs)
        xs.append(np.full_like(xs[-1], np.nan))
        Ps.append(np.full_like(Ps[-1], np.nan))
    xs, Ps = np.stack(xs), np.stack(Ps)
    _check_trajectory(xs, Ps, Om, "step", who)
    xi_t, P_t = _from_state(scalar, xs, Ps)
    return ConsensusResult(np.arange(n_steps + 1), xi_t, P_t)


def consensus_matrix(
    P: ArrayLike, G: ArrayLike, Q: ArrayLike, Omega: ArrayLike, include_self: bool = True
) -> np.ndarray:
    """The matrix ``D[k]`` of Ren et al. eq. (8): ``xi[k+1] = D[k] xi[k]`` without noise.

    Parameters
    ----------
    P : (n,) or (n, m, m) array_like
        Covariances ``P[k]``.
    G : (n, n) array_like
        Topology at step k.
    Q : float, (m, m) or (n, m, m) array_like
        Process-noise covariance per step, in (state unit)^2, as in :func:`kalman_consensus_step`.
    Omega : float, (m, m) or (n, n, m, m) array_like
        Communication-noise covariance, in (state unit)^2, as in :func:`kalman_consensus_step`.
    include_self : bool
        Keep the ``g_ii = 1`` term.

    Returns
    -------
    D : (n, n) ndarray for a scalar state, else (n*m, n*m) with (m, m) blocks
        Off-diagonal block ``D_ij = g_ij P_i[k+1] (P_j[k] + Omega_ij)^-1``,
        diagonal block ``D_ii = I - sum_{j != i} D_ij``: block rows sum to the
        identity (row-stochastic with positive diagonal in the scalar case).
        The stacked state is ``xi.reshape(n*m)`` (agent-major).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> D = consensus.consensus_matrix([1.0, 2.0, 0.5], graphs.path_graph(3), Q=0.0, Omega=0.1)
    >>> np.round(D.sum(axis=1), 12)                # row-stochastic
    array([1., 1., 1.])
    """
    P_arr = _single_run_P(P, "P")
    scalar = P_arr.ndim == 1
    P_m = P_arr[:, None, None] if scalar else P_arr
    n, m = P_m.shape[0], P_m.shape[-1]
    g = _check_topologies(G, n, "G", stacked=False, states="P")
    Om, Q_ = _expand_omega(Omega, n, m), _expand_Q(Q, n, m)
    _check_bool(include_self, "include_self")
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        D = _consensus_matrix(P_m, g, Q_, Om, include_self)
    if not np.all(np.isfinite(D)):
        raise ConsensusBreakdownError(
            "consensus_matrix: P is too small (or too large) to invert in double precision "
            f"(smallest variance {_min_variance(P_m):.3g}); the matrix D is not representable"
        )
    return D


def _consensus_matrix(P_m, g, Q_, Om, include_self):
    """:func:`consensus_matrix` on checked arguments (P as (n, m, m), g boolean)."""
    n, m = P_m.shape[0], P_m.shape[-1]
    g = g.astype(float)
    S = _inv_sum(P_m, Om)  # S[i, j] = (P_j + Omega_ij)^-1
    P_next = _covariance_update(P_m, g, S, Q_, include_self)
    blocks = np.einsum("iab,ij,ijbc->ijac", P_next, g, S)
    blocks[np.arange(n), np.arange(n)] = np.eye(m) - blocks.sum(axis=1)
    D = blocks.transpose(0, 2, 1, 3).reshape(n * m, n * m)
    return D


def error_covariance(
    P0: ArrayLike,
    topologies: ArrayLike | Callable[[int], ArrayLike],
    Q: ArrayLike,
    Omega: ArrayLike,
    n_steps: int | None = None,
    include_self: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """The actual error covariances of noise-free discrete Kalman consensus, next to the believed ones.

    If the initial estimates are ``xi_i[0] = xi* + e_i`` with independent errors
    ``e_i ~ (0, P0_i)`` and the true value ``xi*`` is constant, then
    ``xi[k] = Phi[k] xi[0]`` with ``Phi[k] = D[k-1] ... D[0]`` (eq. (8)); its
    rows sum to the identity, so the error is ``Phi[k] e`` with covariance
    ``Phi[k] blockdiag(P0) Phi[k]^T``. The scheme's own ``P_i[k]`` (eq. (4))
    assumes the agents' errors stay uncorrelated; comparing the two shows what
    that assumption costs.

    Parameters
    ----------
    P0 : (n,) or (n, m, m) array_like
        Initial covariances (a single run).
    topologies : (K, n, n) array_like, (n, n) array_like or callable
        As in :func:`kalman_consensus_discrete`.
    Q : float, (m, m) or (n, m, m) array_like
        Process-noise covariance per step, in (state unit)^2, as in :func:`kalman_consensus_step`.
    Omega : float, (m, m) or (n, n, m, m) array_like
        Communication-noise covariance, in (state unit)^2 (messages are noise-free).
    n_steps : int, optional
        As in :func:`kalman_consensus_discrete`.
    include_self : bool
        Keep the ``g_ii = 1`` term.

    Returns
    -------
    actual : (K+1, n) or (K+1, n, m, m) ndarray
        Diagonal (blocks) of ``Phi[k] blockdiag(P0) Phi[k]^T``.
    believed : (K+1, n) or (K+1, n, m, m) ndarray
        ``P_i[k]`` of eq. (4).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> actual, believed = consensus.error_covariance([1.0, 1.0, 1.0], graphs.complete_graph(3), 0.0, 0.1, n_steps=5)
    >>> bool(np.all(actual[-1] >= believed[-1]))    # correlated errors: the belief is optimistic
    True
    """
    P_arr = _single_run_P(P0, "P0")
    scalar = P_arr.ndim == 1
    n = P_arr.shape[0]
    m = 1 if scalar else P_arr.shape[-1]
    xi0 = np.zeros(n) if scalar else np.zeros((n, m))
    _, xi, P = _as_state(xi0, P_arr, "xi0", "P0")
    Q_, Om = _expand_Q(Q, n, m), _expand_omega(Omega, n, m)
    _check_bool(include_self, "include_self")
    graph_at, n_steps = _discrete_topology(topologies, n, n_steps, (), "P0")
    _check_storage(n_steps, (n * m) ** 2 + xi.size + P.size, "n_steps")
    run = _run_discrete(scalar, xi, P, graph_at, n_steps, Q_, Om, None, include_self, "error_covariance")
    P_blocks = run.P[:, :, None, None] if scalar else run.P
    cov0 = np.zeros((n, m, n, m))
    cov0[np.arange(n), :, np.arange(n), :] = P_blocks[0]
    cov0 = cov0.reshape(n * m, n * m)
    Phi = np.eye(n * m)
    actual = [P_blocks[0]]
    for k in range(n_steps):
        P_k = run.P[k]
        P_k = P_k[:, None, None] if scalar else P_k
        Phi = _consensus_matrix(P_k, graph_at(k), Q_, Om, include_self) @ Phi
        C = (Phi @ cov0 @ Phi.T).reshape(n, m, n, m)
        actual.append(C[np.arange(n), :, np.arange(n), :])
    actual = np.stack(actual)
    if not np.all(np.isfinite(actual)):
        raise ConsensusBreakdownError("error_covariance: the actual covariances overflowed; rescale P0")
    return (actual[..., 0, 0], run.P) if scalar else (actual, run.P)


# --------------------------------------------------------------------------- continuous time


def kalman_consensus_continuous(
    xi0: ArrayLike,
    P0: ArrayLike,
    topology: SwitchingTopology | ArrayLike | Callable[[float], ArrayLike],
    t_final: float,
    Q: ArrayLike,
    Omega: ArrayLike,
    t_eval: ArrayLike | None = None,
    switch_times: Sequence[float] | None = None,
    rng: np.random.Generator | int | None = None,
    dt: float = 1e-3,
    include_self: bool = True,
    rtol: float = 1e-8,
    atol: float = 1e-10,
) -> ConsensusResult:
    """Run continuous-time Kalman consensus, Ren et al. eqs. (1)-(3).

    Without communication noise (``rng=None``) the ODEs are integrated with
    :func:`scipy.integrate.solve_ivp` (RK45) restarted at every topology
    switch. With noise (``rng`` given) eq. (3) is an SDE,
    ``dxi_i = sum_j g_ij K_ij (xi_j - xi_i) dt + sum_{j != i} g_ij K_ij Omega_ij^(1/2) dW_ij``
    (``nu_ij`` white with intensity ``Omega_ij``), integrated by Euler-Maruyama
    with step `dt` together with eq. (1).

    Parameters
    ----------
    xi0 : (..., n) or (..., n, m) array_like
        Initial information states; leading batch axes are independent runs on
        the same topology (e.g. Monte Carlo paths of the noisy SDE).
    P0 : (..., n) or (..., n, m, m) array_like
        Initial covariances (positive definite).
    topology : SwitchingTopology, (n, n) array_like or callable ``t -> (n, n)``
        The interaction graph ``g_ij(t)``. A callable is held constant between
        consecutive `switch_times` (default: the `t_eval` grid) and sampled at
        the start of each interval.
    t_final : float
        End time (s), finite and > 0; the run starts at 0. Without noise the
        ODE solver may use at most :data:`ODE_MAX_EVALUATIONS` right-hand-side
        evaluations (a ``ValueError`` naming `t_final` otherwise, raised early
        when the pace so far shows the horizon is out of reach); with noise
        ``t_final / dt`` may be at most :data:`MAX_STEPS`.
    Q : float, (m, m) or (n, m, m) array_like
        Process-noise intensity: the covariance per unit time of the continuous-time white noise on the
        information state, in (state unit)^2/s (the paper assumes Q > 0; Q = 0 is accepted).
    Omega : float, (m, m) or (n, n, m, m) array_like
        Communication-noise intensity: the covariance per unit time of the noise on each received
        state, in (state unit)^2/s.
    t_eval : (T,) array_like, optional
        Output times in ``[0, t_final]``; default 201 points.
    switch_times : sequence of float, optional
        Switching times of a callable topology.
    rng : numpy.random.Generator or int, optional
        Turns communication noise on (Euler-Maruyama).
    dt : float
        Euler-Maruyama step (s), used only with noise. Eq. (1) is stepped by
        explicit Euler too; a step too large for it raises RuntimeError
        instead of returning a non-positive covariance.
    include_self : bool
        Keep the ``g_ii = 1`` term of eq. (1).
    rtol, atol : float
        Tolerances of the ODE solver (finite, > 0).

    Returns
    -------
    ConsensusResult

    Raises
    ------
    ConsensusBreakdownError
        If ``P`` leaves double precision (zero communication noise makes it
        decay exponentially) or loses positivity in the ODE solution.
    RuntimeError
        If the Euler-Maruyama step `dt` is too large for eq. (1).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> run = consensus.kalman_consensus_continuous([0.0, 2.0, 4.0], [1.0, 1.0, 1.0], graphs.ring_graph(3),
    ...                                           t_final=20.0, Q=0.01, Omega=0.1)
    >>> bool(run.spread[-1] < 1e-3 * run.spread[0])
    True
    """
    scalar, xi, P = _as_state(xi0, P0, "xi0", "P0")
    n, m = xi.shape[-2], xi.shape[-1]
    t_final = check_positive(t_final, "t_final", "s")
    Q_, Om = _expand_Q(Q, n, m), _expand_omega(Omega, n, m)
    if t_eval is None:
        t_eval = np.linspace(0.0, t_final, 201)
    else:
        t_eval = _float_array(t_eval, "t_eval")
        if t_eval.ndim != 1 or t_eval.size == 0 or not np.all(np.isfinite(t_eval)):
            raise ValueError(f"t_eval must be a finite, non-empty 1-D grid of times; got shape {t_eval.shape}")
    if t_eval[0] < 0 or t_eval[-1] > t_final or np.any(np.diff(t_eval) < 0):
        raise ValueError("t_eval must be a non-decreasing 1-D grid inside [0, t_final]")
    _check_storage(t_eval.size, xi.size + P.size, "t_eval")
    if switch_times is not None:
        if not callable(topology):
            raise ValueError("switch_times is only used with a callable topology; "
                             "a SwitchingTopology carries its own times")
        switch_times = _float_array(switch_times, "switch_times")
        if switch_times.ndim != 1 or not np.all(np.isfinite(switch_times)):
            raise ValueError(f"switch_times must be a finite 1-D sequence of times; got shape {switch_times.shape}")
    _check_bool(include_self, "include_self")
    rtol = check_positive(rtol, "rtol")
    atol = check_positive(atol, "atol")
    dt = check_positive(dt, "dt", "s")
    gen = None if rng is None else check_generator(rng)
    if gen is not None and t_eval[-1] / dt > MAX_STEPS:
        raise ValueError(f"t_final / dt = {t_eval[-1] / dt:.3g} Euler-Maruyama steps is more than MAX_STEPS = "
                         f"{MAX_STEPS}; use a shorter t_final or a larger dt")
    breaks, graphs = _continuous_topology(topology, n, t_final, t_eval, switch_times)
    if gen is None:
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            xs, Ps = _integrate_ode(xi, P, breaks, graphs, Q_, Om, t_eval, include_self, rtol, atol)
        _check_trajectory(xs, Ps, Om, "time", "kalman_consensus_continuous", t_eval)
    else:
        xs, Ps = _integrate_em(xi, P, breaks, graphs, Q_, Om, t_eval, include_self, gen, dt)
    xi_t, P_t = _from_state(scalar, xs, Ps)
    return ConsensusResult(t_eval, xi_t, P_t)


# --------------------------------------------------------------------------- comparison and tools


def average_consensus(
    xi0: ArrayLike,
    topologies: ArrayLike | Callable[[int], ArrayLike],
    n_steps: int | None = None,
    step_size: float | None = None,
) -> ConsensusResult:
    """Ordinary (equal-weight) discrete consensus ``xi_i += eps sum_j g_ij (xi_j - xi_i)``.

    Parameters
    ----------
    xi0 : (..., n) array_like
        Scalar initial states (batch axes allowed).
    topologies : (K, n, n) array_like, (n, n) array_like or callable
        As in :func:`kalman_consensus_discrete`.
    n_steps : int, optional
        Required unless `topologies` is a sequence.
    step_size : float, optional
        ``eps``; default ``1 / (1 + d_max)`` with ``d_max`` the largest in-degree
        of each step's graph, so that on a one-to-one pairing every pair
        averages exactly (``eps = 1/2``) and the team average is preserved.

    Returns
    -------
    ConsensusResult
        With ``P = None``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> run = consensus.average_consensus([0.0, 3.0, 6.0], graphs.complete_graph(3), n_steps=20)
    >>> np.round(run.xi[-1], 6)                    # everyone meets at the average
    array([3., 3., 3.])
    """
    xi = _float_array(xi0, "xi0")
    if xi.ndim < 1 or xi.shape[-1] == 0:
        raise ValueError(f"xi0 must have shape (..., n) with at least one agent; got shape {xi.shape}")
    _finite(xi, "xi0")
    if step_size is not None:
        step_size = check_positive(step_size, "step_size")
    n = xi.shape[-1]
    graph_at, n_steps = _discrete_topology(topologies, n, n_steps, xi.shape[:-1], "xi0")
    _check_storage(n_steps, xi.size, "n_steps")
    xs = [xi]
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(n_steps):
            g = graph_at(k).astype(float)
            deg = g.sum(axis=-1)
            eps = step_size if step_size is not None else 1.0 / (1.0 + deg.max(axis=-1, keepdims=True))
            xi = xi + eps * (np.einsum("...ij,...j->...i", g, xi) - deg * xi)
            xs.append(xi)
    xs = np.stack(xs)
    if not np.all(np.isfinite(xs)):
        k = int(np.argmin(np.isfinite(xs).reshape(xs.shape[0], -1).all(axis=1)))
        raise ValueError(
            f"average_consensus overflowed at step {k}: "
            + ("step_size is too large for these graphs (the iteration is stable for step_size < 2 / "
               "(largest Laplacian eigenvalue)); use a smaller step_size or the default"
               if step_size is not None else "xi0 is too large for floating point; rescale xi0")
        )
    return ConsensusResult(np.arange(n_steps + 1), xs, None)


def central_fusion(xi0: ArrayLike, P0: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """What a fusion centre would compute: the inverse-covariance weighted mean.

    ``P_f = (sum_i P_i^-1)^-1``, ``xi_f = P_f sum_i P_i^-1 xi_i`` (the
    maximum-likelihood value for independent Gaussian estimates).

    Parameters
    ----------
    xi0 : (..., n) or (..., n, m) array_like
        The agents' estimates.
    P0 : (..., n) or (..., n, m, m) array_like
        Their covariances (positive definite).

    Returns
    -------
    xi_f : (...) or (..., m) ndarray
        The fused estimate.
    P_f : (...) or (..., m, m) ndarray
        Its covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> xi, P = consensus.central_fusion([0.0, 3.0], [1.0, 2.0])     # weights 1/P
    >>> float(xi), round(float(P), 4)
    (1.0, 0.6667)
    """
    scalar, xi, P = _as_state(xi0, P0, "xi0", "P0")
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        info = _inv(P)
        P_f = _inv(info.sum(axis=-3))
        xi_f = np.einsum("...ab,...b->...a", P_f, np.einsum("...iab,...ib->...a", info, xi))
    if not (np.all(np.isfinite(P_f)) and np.all(np.isfinite(xi_f))):
        raise ValueError(
            "central_fusion: the fused estimate is not representable in floating point: P0 is too small to "
            f"invert (smallest variance {_min_variance(P):.3g}) or xi0 too large; rescale the problem"
        )
    if scalar:
        return xi_f[..., 0], P_f[..., 0, 0]
    return xi_f, P_f


def random_pairings(
    n_agents: int,
    n_steps: int,
    rng: np.random.Generator | int,
    max_duration: int = 5,
    min_duration: int = 1,
    size: int | None = None,
) -> np.ndarray:
    """Random one-to-one pairings held for random durations (Ren et al., Sec. II-C).

    At the start of an epoch the agents are shuffled and paired (with an odd
    `n_agents` one agent sits out); each pair talks both ways for a duration
    drawn uniformly from ``min_duration..max_duration`` steps (the same for
    the whole epoch), then a new epoch starts.

    Parameters
    ----------
    n_agents : int
        Team size n >= 2 (a pairing needs two agents; one agent has nobody to meet).
    n_steps : int
        Number of steps K.
    rng : numpy.random.Generator or int
        Source of randomness (or a non-negative integer seed).
    max_duration : int
        Longest epoch (steps).
    min_duration : int
        Shortest epoch (steps), at least 1.
    size : int, optional
        Number of independent schedules R (Monte Carlo runs).

    Returns
    -------
    G : (K, n, n) or (K, R, n, n) ndarray of float
        Symmetric 0/1 adjacency, one perfect (or near-perfect) matching per step.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> G = consensus.random_pairings(4, n_steps=10, rng=np.random.default_rng(0))
    >>> G.shape, bool(np.all(G.sum(axis=-1) == 1))     # everyone has exactly one partner
    ((10, 4, 4), True)
    """
    gen = check_generator(rng)
    if isinstance(n_agents, (int, np.integer)) and not isinstance(n_agents, bool) and n_agents == 1:
        raise ValueError("n_agents must be an integer >= 2: one agent has nobody to pair with "
                         "(its graph would be empty at every step); got 1")
    n_agents = check_positive_int(n_agents, "n_agents", minimum=2)
    n_steps = check_steps(n_steps)
    min_duration = check_positive_int(min_duration, "min_duration", minimum=1)
    if isinstance(max_duration, bool) or not isinstance(max_duration, (int, np.integer)):
        raise TypeError(f"max_duration must be an integer >= min_duration ({min_duration}); "
                        f"got {type(max_duration).__name__} {max_duration!r}")
    if max_duration < min_duration:
        raise ValueError(f"max_duration must be an integer >= min_duration ({min_duration}); got {max_duration!r}")
    R = 1 if size is None else check_positive_int(size, "size", minimum=1)
    _check_storage(n_steps, R * (n_agents**2 + n_agents + 1), "n_steps")
    # epoch starts: a new epoch begins after each drawn duration (at most n_steps epochs)
    durations = gen.integers(min_duration, max_duration + 1, size=(R, n_steps))
    starts = np.cumsum(durations, axis=1) - durations  # start step of each epoch
    new_epoch = np.zeros((R, n_steps), dtype=bool)
    rows, cols = np.nonzero(starts < n_steps)
    new_epoch[rows, starts[rows, cols]] = True
    epoch_start = np.maximum.accumulate(np.where(new_epoch, np.arange(n_steps), 0), axis=1)  # (R, K)
    perms = np.argsort(gen.random((R, n_steps, n_agents)), axis=-1)  # a shuffle per (run, step)
    perm = np.take_along_axis(perms, epoch_start[:, :, None], axis=1)  # (R, K, n)
    half = n_agents // 2
    a, b = perm[..., 0 : 2 * half : 2], perm[..., 1 : 2 * half : 2]
    G = np.zeros((R, n_steps, n_agents, n_agents))
    r_idx, k_idx = np.meshgrid(np.arange(R), np.arange(n_steps), indexing="ij")
    r_idx, k_idx = r_idx[..., None], k_idx[..., None]
    G[r_idx, k_idx, a, b] = 1.0
    G[r_idx, k_idx, b, a] = 1.0
    G = np.moveaxis(G, 0, 1)  # (K, R, n, n)
    return G[:, 0] if size is None else G


def periodic_sequence(graphs: ArrayLike, dwell: int, n_steps: int) -> np.ndarray:
    """Cycle through `graphs`, each held for `dwell` steps.

    Parameters
    ----------
    graphs : (S, n, n) array_like
        The graphs to cycle through.
    dwell : int
        Steps each graph is held (>= 1).
    n_steps : int
        Length K of the sequence.

    Returns
    -------
    (K, n, n) ndarray
        One graph per step, for :func:`kalman_consensus_discrete`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> consensus.periodic_sequence(np.stack([graphs.path_graph(3), graphs.ring_graph(3)]), dwell=2, n_steps=5).shape
    (5, 3, 3)
    """
    graphs = _check_topologies(graphs, None, "graphs", stacked=True).astype(float)
    dwell = check_positive_int(dwell, "dwell", minimum=1)
    n_steps = check_steps(n_steps)
    _check_storage(n_steps, graphs[0].size, "n_steps")
    return graphs[(np.arange(n_steps) // dwell) % graphs.shape[0]]


def spanning_tree_windows(adjacencies: ArrayLike, window: int) -> np.ndarray:
    """Does the union of each window of `window` consecutive graphs have a spanning tree?

    Parameters
    ----------
    adjacencies : (K, n, n) array_like
        A switching sequence.
    window : int
        Window length (steps); windows are consecutive and non-overlapping.

    Returns
    -------
    (ceil(K / window),) ndarray of bool

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> a = graphs.adjacency_from_edges(3, [(0, 1)], directed=True)
    >>> b = graphs.adjacency_from_edges(3, [(1, 2)], directed=True)
    >>> consensus.spanning_tree_windows(np.stack([a, b, a, a]), window=2)
    array([ True, False])
    """
    stack = _check_topologies(adjacencies, None, "adjacencies", stacked=True).astype(float)
    if stack.ndim != 3:
        raise ValueError(f"adjacencies must be one switching sequence of shape (K, n, n); got {stack.shape}")
    window = check_positive_int(window, "window", minimum=1)
    return np.array([has_spanning_tree(U) for U in unions_over_windows(stack, window)])


def union_condition_holds(adjacencies: ArrayLike, window: int, drop_partial: bool = True) -> bool:
    """The hypothesis of Theorems 3.2 and 3.9 on a finite sequence.

    True iff the union of every consecutive window of `window` graphs contains a
    directed spanning tree ("infinitely many consecutive uniformly bounded
    intervals", checked over the horizon given). A trailing window shorter
    than `window` is ignored when `drop_partial` is True.

    Parameters
    ----------
    adjacencies : (K, n, n) array_like
        A switching sequence.
    window : int
        Window length (steps).
    drop_partial : bool
        Ignore a trailing window shorter than `window`.

    Returns
    -------
    bool
        Whether every window's union has a directed spanning tree.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> a = graphs.adjacency_from_edges(3, [(0, 1)], directed=True)
    >>> b = graphs.adjacency_from_edges(3, [(1, 2)], directed=True)
    >>> consensus.union_condition_holds(np.stack([a, b] * 4), window=2), consensus.union_condition_holds(np.stack([a] * 8), 2)
    (True, False)
    """
    _check_bool(drop_partial, "drop_partial")
    ok = spanning_tree_windows(adjacencies, window)
    K = np.shape(adjacencies)[0]
    if drop_partial and K % window and ok.size > 1:
        ok = ok[:-1]
    return bool(np.all(ok))


def spread(xi: ArrayLike) -> np.ndarray:
    """Largest disagreement ``max_{i,j} ||xi_i - xi_j||_inf`` over the agent axis.

    Parameters
    ----------
    xi : (..., n, m) array_like
        Information states, agents on the second-to-last axis.

    Returns
    -------
    (...) ndarray
        The largest disagreement.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import consensus, graphs
    >>> float(consensus.spread([[1.0], [4.0], [2.0]]))
    3.0
    """
    xi = _float_array(xi, "xi")
    if xi.ndim < 2 or xi.shape[-2] == 0 or xi.shape[-1] == 0:
        raise ValueError(f"xi must have shape (..., n, m) with n, m >= 1; got shape {xi.shape}")
    _finite(xi, "xi")
    with np.errstate(over="ignore"):
        out = (xi.max(axis=-2) - xi.min(axis=-2)).max(axis=-1)
    if not np.all(np.isfinite(out)):
        raise ValueError("spread overflowed: xi holds values too far apart for floating point; rescale xi")
    return out


# --------------------------------------------------------------------------- private helpers


def _inv(M: np.ndarray) -> np.ndarray:
    if M.shape[-1] == 1:
        return 1.0 / M
    return np.linalg.inv(M)


def _inv_sum(P: np.ndarray, Om: np.ndarray) -> np.ndarray:
    """S[..., i, j] = (P_j + Omega_ij)^-1 as a (..., n, n, m, m) array (a broadcast view if Omega is common)."""
    n, m = P.shape[-3], P.shape[-1]
    if Om.ndim == 2:  # common Omega: only n inverses
        S = _inv(P + Om)[..., None, :, :, :]
    else:
        S = _inv(P[..., None, :, :, :] + Om)
    return np.broadcast_to(S, P.shape[:-3] + (n, n, m, m))


def _sqrt_psd(M: np.ndarray) -> np.ndarray:
    """Symmetric square root of a stack of PSD matrices."""
    w, V = np.linalg.eigh(M)
    return np.einsum("...ab,...b,...cb->...ac", V, np.sqrt(np.clip(w, 0.0, None)), V)


def _covariance_update(P, g, S, Q, include_self):
    """Eq. (4): P_i+ = [(P_i + Q)^-1 + sum_j g_ij S_ij]^-1 (g_ii = 1 if include_self)."""
    info = _inv(P + Q) + np.einsum("...ij,...ijab->...iab", g, S)
    if include_self:
        n = P.shape[-3]
        info = info + S[..., np.arange(n), np.arange(n), :, :]
    return symmetric_part(_inv(info))


def _step(xi, P, g, Q, Om, gen, include_self):
    g = g.astype(float)
    S = _inv_sum(P, Om)  # S[..., i, j] = (P_j + Omega_ij)^-1, eq. (4)
    P_next = _covariance_update(P, g, S, Q, include_self)
    innov = xi[..., None, :, :] - xi[..., :, None, :]  # xi_j - xi_i at [..., i, j]
    if gen is not None:
        innov = innov + _draw_noise(gen, Om, innov.shape)
    corr = np.einsum("...ij,...ijab,...ijb->...ia", g, S, innov)
    xi_next = xi + np.einsum("...iab,...ib->...ia", P_next, corr)  # eq. (5)
    return xi_next, P_next


def _draw_noise(gen, Om, shape):
    """nu_ij ~ N(0, Omega_ij), shape (..., n, n, m); the diagonal (self) is zero."""
    n, m = shape[-2], shape[-1]
    L = np.broadcast_to(_sqrt_psd(Om), (n, n, m, m))
    nu = np.einsum("ijab,...ijb->...ija", L, gen.standard_normal(shape))
    nu[..., np.arange(n), np.arange(n), :] = 0.0
    return nu


def _rhs(xi, P, g, Q, Om, include_self):
    """Right-hand sides of eqs. (1) and (3) without noise, for states (..., n, m).

    Also returns ``S``: ``S_j = (P_j + Omega)^-1`` as (..., n, m, m) for a common
    Omega, ``S_ij = (P_j + Omega_ij)^-1`` as (..., n, n, m, m) per link.
    """
    n, m = xi.shape[-2], xi.shape[-1]
    # (m, m) blocks times blocks / vectors; for m = 1 plain products (the ODE calls this thousands of times)
    mat, vec = (np.multiply, _scalar_matvec) if m == 1 else (np.matmul, _matvec)
    if Om.ndim == 2:  # common Omega: n inverses, sums over j as matrix products with g
        S = _inv(P + Om)
        A = (g @ S.reshape(S.shape[:-3] + (n, m * m))).reshape(S.shape)  # sum_j g_ij S_j
        b = g @ vec(S, xi)  # sum_j g_ij S_j xi_j
        S_self = S
    else:
        S = _inv(P[..., None, :, :, :] + Om)
        A = np.einsum("ij,...ijab->...iab", g, S)
        b = np.einsum("ij,...ijab,...jb->...ia", g, S, xi)
        S_self = S[..., np.arange(n), np.arange(n), :, :]
    info = A + S_self if include_self else A  # sum_j g_ij (P_j + Omega_ij)^-1 with g_ii = 1
    dP = Q - mat(mat(P, info), P)  # eq. (1)
    # eqs. (2)-(3): sum_j g_ij K_ij (xi_j - xi_i) = P_i [sum_j g_ij S_ij xi_j - (sum_j g_ij S_ij) xi_i]
    return vec(P, b - vec(A, xi)), (dP if m == 1 else symmetric_part(dP)), S


def _matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Stacked matrix-vector product (..., m, m) x (..., m) -> (..., m)."""
    return (M @ v[..., None])[..., 0]


def _scalar_matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`_matvec` for m = 1: (..., 1, 1) x (..., 1) -> (..., 1)."""
    return M[..., 0] * v


def _integrate_ode(xi, P, breaks, graphs, Q, Om, t_eval, include_self, rtol, atol):
    from scipy.integrate import solve_ivp  # the continuous-time runs only: the discrete steps load no ODE solver

    split = xi.size
    t_final = breaks[-1]
    count = [0]
    latest = [breaks[0], None]  # where the solver last evaluated eqs. (1)-(3): what a failure reports
    zero_noise = bool(np.any(np.linalg.eigvalsh(Om) <= 0))

    def fun(_t, y, g):
        count[0] += 1
        latest[0], latest[1] = _t, y
        if count[0] % _ODE_CHECK_EVERY == 0:
            _ode_budget(count[0], _t, t_final, y[split:].reshape(P.shape), zero_noise)
        dxi, dP, _ = _rhs(y[:split].reshape(xi.shape), y[split:].reshape(P.shape), g, Q, Om, include_self)
        return np.concatenate([dxi.ravel(), dP.ravel()])

    y = np.concatenate([xi.ravel(), P.ravel()])
    out = np.empty((t_eval.size, y.size))
    done = t_eval < breaks[0]
    out[done] = y
    for (t0, t1), g in zip(zip(breaks[:-1], breaks[1:]), graphs):
        last = t1 == breaks[-1]
        sel = (t_eval >= t0) & ((t_eval <= t1) if last else (t_eval < t1))
        pts = np.unique(np.append(t_eval[sel], t1))  # always end on t1 to hand the state on
        sol = solve_ivp(fun, (t0, t1), y, method="RK45", t_eval=pts, args=(g.astype(float),),
                        rtol=rtol, atol=atol)
        if not sol.success:  # e.g. a step below the spacing of floating-point numbers: a stiff run
            P_now = (y if latest[1] is None else latest[1])[split:].reshape(P.shape)
            _ode_out_of_reach(count[0], latest[0], t_final, P_now, zero_noise,
                              f"the solver stopped ({sol.message.rstrip('.')})")
        out[sel] = sol.y[:, np.searchsorted(pts, t_eval[sel])].T
        y = sol.y[:, -1]
    return out[:, :split].reshape((-1,) + xi.shape), symmetric_part(out[:, split:].reshape((-1,) + P.shape))


def _ode_budget(count, t, t_final, P, zero_noise):
    """Stop a continuous run that has used, or at its pace so far would use, too many evaluations."""
    limit = ODE_MAX_EVALUATIONS
    projected = count * t_final / t if t > 0 else np.inf
    if count < limit and projected <= _ODE_PROJECTION_FACTOR * limit:
        return
    reach = (f"at its pace so far it would need about {projected:.3g}" if count < limit
             else f"it has used {count}")
    _ode_out_of_reach(count, t, t_final, P, zero_noise, f"{reach} evaluations (ODE_MAX_EVALUATIONS = {limit})")


def _ode_out_of_reach(count, t, t_final, P, zero_noise, why):
    """Raise the ValueError of a continuous run the ODE solver cannot finish (`why`: the budget, or its failure)."""
    with np.errstate(invalid="ignore"):
        p_min = _min_variance(P)
    raise ValueError(
        f"t_final = {t_final:.4g} s is out of reach of the ODE solver: after {count} evaluations of eqs. (1)-(3) "
        f"it is at t = {t:.4g} s, and {why}. Either t_final is "
        f"far longer than the time the run takes to settle, or the equations are stiff (smallest variance now "
        f"{p_min:.3g}"
        + ("; with zero communication noise (singular Omega) P collapses and the rates P_i / P_j explode); "
           "shorten t_final or give Omega > 0" if zero_noise else "); shorten t_final or loosen rtol/atol")
    )


def _integrate_em(xi, P, breaks, graphs, Q, Om, t_eval, include_self, gen, dt):
    n, m = xi.shape[-2], xi.shape[-1]
    L = _sqrt_psd(Om)  # Omega^(1/2), (m, m) or (n, n, m, m)
    off = 1.0 - np.eye(n)  # no noise on an agent's own state
    xs = np.empty((t_eval.size,) + xi.shape)
    Ps = np.empty((t_eval.size,) + P.shape)
    t, idx = 0.0, 0
    while idx < t_eval.size and t_eval[idx] <= t + 1e-12:
        xs[idx], Ps[idx] = xi, P
        idx += 1
    t_end = t_eval[-1]
    while idx < t_eval.size:
        h = min(dt, t_end - t)
        k = int(np.searchsorted(breaks, t + 0.5 * h, side="right")) - 1
        g = graphs[min(max(k, 0), len(graphs) - 1)].astype(float)
        dxi, dP, S = _rhs(xi, P, g, Q, Om, include_self)
        dW = gen.standard_normal(xi.shape[:-1] + (n, m)) * np.sqrt(h)  # (..., n, n, m): one per link i <- j
        # sum_{j != i} g_ij K_ij Omega_ij^(1/2) dW_ij with K_ij = P_i S_ij, eq. (3)
        SL = S @ L
        if Om.ndim == 2:
            u = np.einsum("ij,...jab,...ijb->...ia", g * off, SL, dW)
        else:
            u = np.einsum("ij,...ijab,...ijb->...ia", g * off, SL, dW)
        xi = xi + dxi * h + np.einsum("...iab,...ib->...ia", P, u)
        P = symmetric_part(P + dP * h)
        if np.any(np.diagonal(P, axis1=-2, axis2=-1) <= 0) or not np.all(np.isfinite(xi)):
            raise RuntimeError(f"Euler-Maruyama step dt = {dt} is too large for eq. (1): the covariance lost "
                               f"positive definiteness at t = {t + h:.4g} s; use a smaller dt")
        t += h
        while idx < t_eval.size and t_eval[idx] <= t + 1e-9:
            xs[idx], Ps[idx] = xi, P
            idx += 1
    return xs, Ps


def _ndim(value) -> int | None:
    """Number of axes of an array-like, or None for a ragged sequence (reported by the shape check)."""
    try:
        return np.ndim(value)
    except ValueError:
        return None


def _continuous_topology(topology, n, t_final, t_eval, switch_times):
    if isinstance(topology, SwitchingTopology):
        if topology.n_agents != n:
            raise ValueError(f"topology has {topology.n_agents} agents; the states have {n} "
                             "(xi0 and P0 hold one row per agent)")
        keep = topology.times < t_final
        times, graphs = topology.times[keep], topology.graphs[keep]
        if times.size == 0 or times[0] > 0:
            raise ValueError("the SwitchingTopology must start at or before t = 0")
        times = times.copy()
        times[0] = 0.0
        return np.append(times, t_final), graphs
    if callable(topology):
        pts = np.asarray(t_eval if switch_times is None else switch_times, dtype=float)
        breaks = np.unique(np.concatenate([[0.0], pts[(pts > 0) & (pts < t_final)], [t_final]]))
        graphs = np.stack([_check_topologies(topology(t), n, "topology(t)", stacked=False, states="xi0 and P0")
                           for t in breaks[:-1]])
        return breaks, graphs
    if _ndim(topology) == 3:
        raise ValueError(
            f"topology has shape {np.shape(topology)}: a stack of graphs needs its switching times in continuous "
            "time; pass SwitchingTopology(times, graphs) (graphs[k] active from times[k]) or a callable t -> (n, n). "
            "kalman_consensus_discrete takes one graph per step as a (K, n, n) array"
        )
    g = _check_topologies(topology, n, "topology", stacked=False, states="xi0 and P0")
    return np.array([0.0, t_final]), g[None]


def _discrete_topology(topologies, n, n_steps, batch, states="xi0 and P0"):
    if callable(topologies):
        if n_steps is None:
            raise ValueError("n_steps is required when topologies is a function of k")
        n_steps = check_steps(n_steps)
        return (lambda k: _check_topologies(topologies(k), n, f"topologies({k})", stacked=False, states=states)), \
            n_steps
    if isinstance(topologies, np.ndarray):  # e.g. a broadcast view: its float copy must fit before it is made
        check_fits_in_memory(8.0 * topologies.size, "topologies", "the graphs as floats (one per step)")
    arr = _float_array(topologies, "topologies")
    if arr.ndim == 2:
        g = _check_topologies(arr, n, "topologies", stacked=False, states=states)
        if n_steps is None:
            raise ValueError("n_steps is required when topologies is a single (n, n) graph")
        return (lambda k: g), check_steps(n_steps)
    g = _check_topologies(arr, n, "topologies", stacked=True, states=states)
    _check_batch(g.shape[1:-2], batch, "topologies")
    if n_steps is None:
        n_steps = g.shape[0]
    n_steps = check_steps(n_steps)
    if n_steps > g.shape[0]:
        raise ValueError(f"topologies holds {g.shape[0]} graphs but n_steps = {n_steps}")
    return (lambda k: g[k]), n_steps


def _check_batch(graph_batch, state_batch, name):
    """One graph per run: the graphs' batch axes must broadcast against the states' batch axes."""
    try:
        np.broadcast_shapes(graph_batch, state_batch)
    except ValueError:
        raise ValueError(
            f"{name} has batch axes {graph_batch} (one graph per run) that do not match the states' batch "
            f"axes {state_batch}"
        ) from None


def _check_storage(n_rows, per_row, name):
    """Refuse a trajectory of more than :data:`MAX_STORED` numbers (``n_rows + 1`` rows of `per_row`)."""
    total = (int(n_rows) + 1) * int(per_row)
    if total > MAX_STORED:
        raise ValueError(
            f"{name} = {n_rows} would store {total:.3g} numbers ({8 * total / 1e9:.3g} GB), more than "
            f"MAX_STORED = {MAX_STORED:.3g}; run fewer steps or fewer runs at a time"
        )




def _finite_number(x, name):
    if isinstance(x, np.ndarray) and x.ndim == 0:
        x = x[()]
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number; got {type(x).__name__} {x!r}")
    if not np.isfinite(x):
        raise ValueError(f"{name} must be a finite number; got {x!r}")
    return float(x)


def _check_bool(value, name):
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False; got {type(value).__name__} {value!r}")


def _check_topologies(G, n, name, stacked, states="the states"):
    """Return boolean adjacency g_ij (i hears j); (n, n) or (K, ..., n, n) if `stacked`.

    Directed graphs are accepted (the scheme and its theorems allow them).
    """
    arr = _float_array(G, name)
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2] or arr.shape[-1] == 0:
        raise ValueError(f"{name} must be a square (n, n) adjacency (or a stack of them); got shape {arr.shape}")
    if stacked and arr.ndim < 3:
        raise ValueError(f"{name} must be a switching sequence of shape (K, n, n); got shape {arr.shape}")
    if stacked and arr.shape[0] == 0:
        raise ValueError(f"{name} must hold at least one graph; got shape {arr.shape}")
    if n is not None and arr.shape[-1] != n:
        raise ValueError(f"{name} is a graph on {arr.shape[-1]} agents; expected {n}, the number of agents in "
                         f"{states} (shape {arr.shape})")
    _finite(arr, name)
    diag = np.diagonal(arr, axis1=-2, axis2=-1)
    if np.any(arr < 0):
        if np.all(diag >= 0) and np.any(diag > 0) and np.allclose(arr.sum(axis=-1), 0.0):
            raise ValueError(
                f"{name} looks like a graph Laplacian (negative off-diagonal entries, rows summing to zero); "
                "pass the adjacency matrix instead (A = diag(diag(L)) - L)"
            )
        raise ValueError(f"{name} must have finite, non-negative entries (G[i, j] > 0: i hears j); "
                         f"smallest entry is {arr.min():.3g}")
    if np.any(diag != 0):
        raise ValueError(f"{name} must have a zero diagonal (g_ii = 1 is implied by the scheme)")
    return arr > 0


def _single_run_P(P, name):
    """Covariances of a single run: (n,) positive variances or (n, m, m) positive definite."""
    P_arr = _float_array(P, name)
    if P_arr.ndim not in (1, 3) or P_arr.shape[0] == 0:
        raise ValueError(f"{name} must be (n,) or (n, m, m) for a single run; got shape {P_arr.shape}")
    if P_arr.ndim == 1:
        _finite(P_arr, name)
        if np.any(P_arr <= 0):
            raise ValueError(f"{name} must hold positive variances; smallest is {P_arr.min():.3g}")
    else:
        check_covariance(P_arr, name, definite=True)
    return P_arr


def _as_state(xi, P, xi_name, P_name):
    """Bring (xi, P) to the vector form (..., n, m), (..., n, m, m); report if scalar."""
    xi = _float_array(xi, xi_name)
    P = _float_array(P, P_name)
    if xi.ndim < 1 or xi.shape[-1] == 0:
        raise ValueError(f"{xi_name} must have shape (..., n) or (..., n, m) with at least one agent; "
                         f"got shape {xi.shape}")
    _finite(xi, xi_name)
    if P.ndim == xi.ndim:  # scalar information states
        if P.shape != xi.shape:
            raise ValueError(f"{P_name} must have the shape of {xi_name} {xi.shape} for scalar states; "
                             f"got shape {P.shape}")
        _finite(P, P_name)
        if np.any(P <= 0):
            raise ValueError(f"{P_name} must hold positive variances; smallest is {P.min():.3g}")
        return True, xi[..., None], P[..., None, None]
    if P.ndim == xi.ndim + 1:
        if xi.ndim < 2 or xi.shape[-2] == 0:
            raise ValueError(
                f"{xi_name} of shape {xi.shape} is a scalar state per agent: {P_name} must then have the same "
                f"shape (one variance per agent); got shape {P.shape}"
            )
        m = xi.shape[-1]
        if P.shape != xi.shape + (m,):
            raise ValueError(f"{P_name} must have shape {xi.shape + (m,)} to match {xi_name} of shape {xi.shape}; "
                             f"got shape {P.shape}")
        check_covariance(P, P_name, definite=True)
        return False, xi, P
    raise ValueError(
        f"{P_name} must have shape (..., n) (scalar states) or (..., n, m, m); got shape {P.shape} for "
        f"{xi_name} of shape {xi.shape}"
    )


def _from_state(scalar, xi, P):
    if scalar:
        return xi[..., 0], P[..., 0, 0]
    return xi, P


def _expand_Q(Q, n, m):
    Q = _float_array(Q, "Q")
    if Q.ndim == 0:
        Q = Q * np.eye(m)
    if Q.shape not in ((m, m), (n, m, m)):
        raise ValueError(
            f"Incompatible dimensions of Q; expected a scalar, ({m}, {m}) or ({n}, {m}, {m}); got {Q.shape}"
        )
    return check_covariance(Q, "Q")


def _expand_omega(Omega, n, m):
    Om = _float_array(Omega, "Omega")
    if Om.ndim == 0:
        Om = Om * np.eye(m)
    if Om.shape not in ((m, m), (n, n, m, m)):
        raise ValueError(
            f"Incompatible dimensions of Omega; expected a scalar, ({m}, {m}) or ({n}, {n}, {m}, {m}); got {Om.shape}"
        )
    return check_covariance(Om, "Omega")


def _min_variance(P):
    with np.errstate(invalid="ignore"):
        d = np.diagonal(P, axis1=-2, axis2=-1)
        return float(np.nanmin(d)) if np.any(np.isfinite(d)) else float("nan")


def _check_trajectory(xs, Ps, Om, unit, who, times=None):
    """Raise :class:`~mascore.exceptions.ConsensusBreakdownError` at the first row of (xs, Ps) that is not finite
    or has P_ii <= 0.

    xs : (T, ..., n, m), Ps : (T, ..., n, m, m) in vector form; `unit` is "step" or "time".
    """
    with np.errstate(over="ignore", invalid="ignore"):  # fast path: a NaN/inf or P_ii <= 0 spoils one of these
        if (np.isfinite(xs.sum()) and np.isfinite(Ps.sum())
                and np.diagonal(Ps, axis1=-2, axis2=-1).min() > 0):
            return
    T = xs.shape[0]
    ok = np.isfinite(xs).reshape(T, -1).all(axis=1) & np.isfinite(Ps).reshape(T, -1).all(axis=1)
    with np.errstate(invalid="ignore"):
        ok &= (np.diagonal(Ps, axis1=-2, axis2=-1) > 0).reshape(T, -1).all(axis=1)
    if ok.all():
        return
    k = int(np.argmin(ok))
    where = f"step {k}" if times is None else f"t = {times[k]:.4g} s"
    last = f"step {k - 1}" if times is None else f"t = {times[k - 1]:.4g} s"
    prev = Ps[k - 1] if k > 0 else Ps[0]
    agree = float(np.max(spread(xs[k - 1]))) if k > 0 and np.all(np.isfinite(xs[k - 1])) else float("nan")
    with np.errstate(invalid="ignore"):
        P_bad = not (np.all(np.isfinite(Ps[k])) and np.all(np.diagonal(Ps[k], axis1=-2, axis2=-1) > 0))
    if not P_bad:
        raise ConsensusBreakdownError(f"{who}: the information states overflowed at {where}: xi0 is too large "
                                      "for floating point; rescale xi0")
    if who == "kalman_consensus_step":
        earlier = ""
    elif times is None:
        earlier = f", or stop earlier (n_steps <= {k - 1})"
    else:
        earlier = f", or stop earlier (t_final <= {times[k - 1]:.4g} s)"
    if bool(np.any(np.linalg.eigvalsh(Om) <= 0)):
        cause = (
            "Omega is singular (zero communication noise), so every received state counts as exact and P "
            + ("shrinks geometrically" if times is None else "decays exponentially")
            + f"; the smallest variance was {_min_variance(prev):.3g} at {last}"
            + ("" if np.isnan(agree) else f", when the states agreed to {agree:.3g}")
            + f". Give Omega > 0 (a little communication noise){earlier}"
        )
    else:
        cause = (f"the smallest variance was {_min_variance(prev):.3g} at {last}: P0, Q and Omega span too many "
                 "orders of magnitude for double precision; rescale the problem"
                 + ("" if times is None else " or tighten atol"))
    raise ConsensusBreakdownError(
        f"{who}: the covariances P left double precision at {where} (P underflowed to zero, lost positivity "
        f"or overflowed): {cause}"
    )
