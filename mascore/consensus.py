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
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.integrate import solve_ivp

from ._validation import check_covariance, check_generator
from .graphs import has_spanning_tree, unions_over_windows

__all__ = [
    "ConsensusResult",
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


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class ConsensusResult:
    """Trajectory of a consensus run.

    Attributes
    ----------
    t : (T,) ndarray
        Step indices (discrete time) or times in s (continuous time).
    xi : (T, ..., n) or (T, ..., n, m) ndarray
        Information states.
    P : (T, ..., n) or (T, ..., n, m, m) ndarray, or None
        Covariances (None for ordinary average consensus).
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


@dataclass(frozen=True)
class SwitchingTopology:
    """A piecewise-constant topology ``G(t)`` for continuous-time consensus.

    Graph ``graphs[k]`` is active on ``[times[k], times[k+1])``; the last one
    stays active for ever.

    Parameters
    ----------
    times : (S,) array_like
        Increasing switching times (s), ``times[0]`` the start.
    graphs : (S, n, n) array_like
        Adjacency matrices (``G[i, j] > 0``: ``i`` hears ``j``).
    """

    times: np.ndarray
    graphs: np.ndarray

    def __post_init__(self):
        times = np.asarray(self.times, dtype=float)
        graphs = _check_topologies(self.graphs, None, "graphs", stacked=True)
        if times.ndim != 1 or times.shape[0] != graphs.shape[0]:
            raise ValueError(
                f"times must be 1-D with one entry per graph ({graphs.shape[0]}); got shape {times.shape}"
            )
        if not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
            raise ValueError("times must be finite and strictly increasing")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "graphs", graphs)

    @property
    def n_agents(self) -> int:
        """Number of agents n."""
        return self.graphs.shape[-1]

    def at(self, t: float) -> np.ndarray:
        """The graph active at time `t`."""
        k = int(np.searchsorted(self.times, t, side="right")) - 1
        return self.graphs[max(k, 0)]

    @classmethod
    def periodic(cls, graphs: ArrayLike, dwell: float, t_final: float, t0: float = 0.0) -> "SwitchingTopology":
        """Cycle through `graphs`, each held for `dwell` s, from `t0` up to `t_final`."""
        graphs = np.asarray(graphs, dtype=float)
        if not dwell > 0:
            raise ValueError(f"dwell must be positive; got {dwell}")
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
        Process-noise covariance of the consensus value (per agent if (n, m, m)).
    Omega : float, (m, m) or (n, n, m, m) array_like
        Communication-noise covariance ``Omega_ij`` (common or per link).
    rng : numpy.random.Generator or int, optional
        If given, communication noise ``nu_ij ~ N(0, Omega_ij)`` is drawn and
        added to every received state; if None the messages are noise-free
        (``Omega`` still weights them, as in the paper's Fig. 1).
    include_self : bool
        Keep the ``g_ii = 1`` term of eq. (4) (default, as in the paper).

    Returns
    -------
    xi_next, P_next : arrays of the shapes of `xi` and `P`
    """
    scalar, xi_v, P_m = _as_state(xi, P)
    n, m = xi_v.shape[-2], xi_v.shape[-1]
    g = _check_topologies(G, n, "G", stacked=False)
    _check_batch(g.shape[:-2], xi_v.shape[:-2], "G")
    gen = None if rng is None else check_generator(rng)
    xi_next, P_next = _step(xi_v, P_m, g, _expand_Q(Q, n, m), _expand_omega(Omega, n, m), gen, include_self)
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
    xi0, P0 : initial states and covariances
        Shapes as in :func:`kalman_consensus_step`.
    topologies : (K, n, n) or (K, ..., n, n) array_like, (n, n) array_like, or callable
        ``g_ij[k]`` for ``k = 0..K-1``: a sequence (one graph per step, or one
        per step and batch member), a fixed graph, or a function ``k -> (n, n)``.
    Q, Omega : covariances
        As in :func:`kalman_consensus_step`.
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
    """
    scalar, xi, P = _as_state(xi0, P0)
    n, m = xi.shape[-2], xi.shape[-1]
    Q_, Om = _expand_Q(Q, n, m), _expand_omega(Omega, n, m)
    gen = None if rng is None else check_generator(rng)
    graph_at, n_steps = _discrete_topology(topologies, n, n_steps, xi.shape[:-2])
    xs, Ps = [xi], [P]
    for k in range(n_steps):
        xi, P = _step(xi, P, graph_at(k), Q_, Om, gen, include_self)
        xs.append(xi)
        Ps.append(P)
    xi_t, P_t = _from_state(scalar, np.stack(xs), np.stack(Ps))
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
    Q, Omega : covariances
        As in :func:`kalman_consensus_step`.

    Returns
    -------
    D : (n, n) ndarray for a scalar state, else (n*m, n*m) with (m, m) blocks
        Off-diagonal block ``D_ij = g_ij P_i[k+1] (P_j[k] + Omega_ij)^-1``,
        diagonal block ``D_ii = I - sum_{j != i} D_ij``: block rows sum to the
        identity (row-stochastic with positive diagonal in the scalar case).
        The stacked state is ``xi.reshape(n*m)`` (agent-major).
    """
    P_arr = np.asarray(P, dtype=float)
    scalar = P_arr.ndim == 1
    P_m = _check_P(P_arr[:, None, None] if scalar else P_arr, "P")
    n, m = P_m.shape[0], P_m.shape[-1]
    g = _check_topologies(G, n, "G", stacked=False).astype(float)
    S = _inv_sum(P_m, _expand_omega(Omega, n, m))  # S[i, j] = (P_j + Omega_ij)^-1
    P_next = _covariance_update(P_m, g, S, _expand_Q(Q, n, m), include_self)
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
    topologies, n_steps : as in :func:`kalman_consensus_discrete`
    Q, Omega : covariances
        As in :func:`kalman_consensus_step` (messages are noise-free).
    include_self : bool
        Keep the ``g_ii = 1`` term.

    Returns
    -------
    actual : (K+1, n) or (K+1, n, m, m) ndarray
        Diagonal (blocks) of ``Phi[k] blockdiag(P0) Phi[k]^T``.
    believed : (K+1, n) or (K+1, n, m, m) ndarray
        ``P_i[k]`` of eq. (4).
    """
    P_arr = np.asarray(P0, dtype=float)
    if P_arr.ndim not in (1, 3):
        raise ValueError(f"P0 must be (n,) or (n, m, m) for a single run; got shape {P_arr.shape}")
    scalar = P_arr.ndim == 1
    n = P_arr.shape[0]
    m = 1 if scalar else P_arr.shape[-1]
    xi0 = np.zeros(n) if scalar else np.zeros((n, m))
    run = kalman_consensus_discrete(xi0, P_arr, topologies, Q, Omega, n_steps=n_steps, include_self=include_self)
    graph_at, n_steps = _discrete_topology(topologies, n, n_steps, ())
    P_blocks = run.P[:, :, None, None] if scalar else run.P
    cov0 = np.zeros((n, m, n, m))
    cov0[np.arange(n), :, np.arange(n), :] = P_blocks[0]
    cov0 = cov0.reshape(n * m, n * m)
    Phi = np.eye(n * m)
    actual = [P_blocks[0]]
    for k in range(n_steps):
        Phi = consensus_matrix(run.P[k], graph_at(k), Q, Omega, include_self=include_self) @ Phi
        C = (Phi @ cov0 @ Phi.T).reshape(n, m, n, m)
        actual.append(C[np.arange(n), :, np.arange(n), :])
    actual = np.stack(actual)
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
        End time (s); the run starts at 0.
    Q : float, (m, m) or (n, m, m) array_like
        Process-noise intensity (the paper assumes Q > 0; Q = 0 is accepted).
    Omega : float, (m, m) or (n, n, m, m) array_like
        Communication-noise intensity.
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
        Tolerances of the ODE solver.

    Returns
    -------
    ConsensusResult
    """
    scalar, xi, P = _as_state(xi0, P0)
    n, m = xi.shape[-2], xi.shape[-1]
    if not (np.isfinite(t_final) and t_final > 0):
        raise ValueError(f"t_final must be a positive number; got {t_final}")
    Q_, Om = _expand_Q(Q, n, m), _expand_omega(Omega, n, m)
    t_eval = np.linspace(0.0, t_final, 201) if t_eval is None else np.asarray(t_eval, dtype=float)
    if t_eval.ndim != 1 or t_eval[0] < 0 or t_eval[-1] > t_final or np.any(np.diff(t_eval) < 0):
        raise ValueError("t_eval must be a non-decreasing 1-D grid inside [0, t_final]")
    if switch_times is not None and not callable(topology):
        raise ValueError("switch_times is only used with a callable topology; "
                         "a SwitchingTopology carries its own times")
    breaks, graphs = _continuous_topology(topology, n, t_final, t_eval, switch_times)
    if rng is None:
        xs, Ps = _integrate_ode(xi, P, breaks, graphs, Q_, Om, t_eval, include_self, rtol, atol)
    else:
        if not dt > 0:
            raise ValueError(f"dt must be positive; got {dt}")
        xs, Ps = _integrate_em(xi, P, breaks, graphs, Q_, Om, t_eval, include_self, check_generator(rng), dt)
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
    topologies : as in :func:`kalman_consensus_discrete`
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
    """
    xi = np.asarray(xi0, dtype=float)
    if xi.ndim < 1 or not np.all(np.isfinite(xi)):
        raise ValueError(f"xi0 must be a finite array of shape (..., n); got shape {xi.shape}")
    if step_size is not None and not step_size > 0:
        raise ValueError(f"step_size must be positive; got {step_size}")
    n = xi.shape[-1]
    graph_at, n_steps = _discrete_topology(topologies, n, n_steps, xi.shape[:-1])
    xs = [xi]
    for k in range(n_steps):
        g = graph_at(k).astype(float)
        deg = g.sum(axis=-1)
        eps = step_size if step_size is not None else 1.0 / (1.0 + deg.max(axis=-1, keepdims=True))
        xi = xi + eps * (np.einsum("...ij,...j->...i", g, xi) - deg * xi)
        xs.append(xi)
    return ConsensusResult(np.arange(n_steps + 1), np.stack(xs), None)


def central_fusion(xi0: ArrayLike, P0: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """What a fusion centre would compute: the inverse-covariance weighted mean.

    ``P_f = (sum_i P_i^-1)^-1``, ``xi_f = P_f sum_i P_i^-1 xi_i`` (the
    maximum-likelihood value for independent Gaussian estimates).

    Parameters
    ----------
    xi0 : (..., n) or (..., n, m) array_like
    P0 : (..., n) or (..., n, m, m) array_like

    Returns
    -------
    xi_f : (...) or (..., m) ndarray
    P_f : (...) or (..., m, m) ndarray
    """
    scalar, xi, P = _as_state(xi0, P0)
    info = _inv(P)
    P_f = _inv(info.sum(axis=-3))
    xi_f = np.einsum("...ab,...b->...a", P_f, np.einsum("...iab,...ib->...a", info, xi))
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
        Team size n >= 2.
    n_steps : int
        Number of steps K.
    rng : numpy.random.Generator or int
    max_duration, min_duration : int
        Range of the epoch length (steps).
    size : int, optional
        Number of independent schedules R (Monte Carlo runs).

    Returns
    -------
    G : (K, n, n) or (K, R, n, n) ndarray of float
        Symmetric 0/1 adjacency, one perfect (or near-perfect) matching per step.
    """
    gen = check_generator(rng)
    for name, val, low in (("n_agents", n_agents, 2), ("n_steps", n_steps, 1), ("min_duration", min_duration, 1)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < low:
            raise ValueError(f"{name} must be an integer >= {low}; got {val!r}")
    if not isinstance(max_duration, (int, np.integer)) or max_duration < min_duration:
        raise ValueError(f"max_duration must be an integer >= min_duration ({min_duration}); got {max_duration!r}")
    R = 1 if size is None else int(size)
    if R < 1:
        raise ValueError(f"size must be a positive integer; got {size!r}")
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
    """Cycle through `graphs`, each held for `dwell` steps: a (n_steps, n, n) sequence."""
    graphs = _check_topologies(graphs, None, "graphs", stacked=True).astype(float)
    if isinstance(dwell, bool) or not isinstance(dwell, (int, np.integer)) or dwell < 1:
        raise ValueError(f"dwell must be a positive integer; got {dwell!r}")
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
    """
    stack = _check_topologies(adjacencies, None, "adjacencies", stacked=True).astype(float)
    return np.array([has_spanning_tree(U) for U in unions_over_windows(stack, window)])


def union_condition_holds(adjacencies: ArrayLike, window: int, drop_partial: bool = True) -> bool:
    """The hypothesis of Theorems 3.2 and 3.9 on a finite sequence.

    True iff the union of every consecutive window of `window` graphs contains a
    directed spanning tree ("infinitely many consecutive uniformly bounded
    intervals", checked over the horizon given). A trailing window shorter
    than `window` is ignored when `drop_partial` is True.
    """
    ok = spanning_tree_windows(adjacencies, window)
    K = np.asarray(adjacencies).shape[0]
    if drop_partial and K % window and ok.size > 1:
        ok = ok[:-1]
    return bool(np.all(ok))


def spread(xi: ArrayLike) -> np.ndarray:
    """Largest disagreement ``max_{i,j} ||xi_i - xi_j||_inf`` over the agent axis.

    Parameters
    ----------
    xi : (..., n, m) array_like

    Returns
    -------
    (...) ndarray
    """
    xi = np.asarray(xi, dtype=float)
    return (xi.max(axis=-2) - xi.min(axis=-2)).max(axis=-1)


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


def _sym(M: np.ndarray) -> np.ndarray:
    return 0.5 * (M + np.swapaxes(M, -1, -2))


def _covariance_update(P, g, S, Q, include_self):
    """Eq. (4): P_i+ = [(P_i + Q)^-1 + sum_j g_ij S_ij]^-1 (g_ii = 1 if include_self)."""
    info = _inv(P + Q) + np.einsum("...ij,...ijab->...iab", g, S)
    if include_self:
        n = P.shape[-3]
        info = info + S[..., np.arange(n), np.arange(n), :, :]
    return _sym(_inv(info))


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
    return vec(P, b - vec(A, xi)), (dP if m == 1 else _sym(dP)), S


def _matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Stacked matrix-vector product (..., m, m) x (..., m) -> (..., m)."""
    return (M @ v[..., None])[..., 0]


def _scalar_matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`_matvec` for m = 1: (..., 1, 1) x (..., 1) -> (..., 1)."""
    return M[..., 0] * v


def _integrate_ode(xi, P, breaks, graphs, Q, Om, t_eval, include_self, rtol, atol):
    split = xi.size

    def fun(_t, y, g):
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
        if not sol.success:
            raise RuntimeError(f"ODE solver failed on [{t0}, {t1}]: {sol.message}")
        out[sel] = sol.y[:, np.searchsorted(pts, t_eval[sel])].T
        y = sol.y[:, -1]
    return out[:, :split].reshape((-1,) + xi.shape), _sym(out[:, split:].reshape((-1,) + P.shape))


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
        P = _sym(P + dP * h)
        if np.any(np.diagonal(P, axis1=-2, axis2=-1) <= 0) or not np.all(np.isfinite(xi)):
            raise RuntimeError(f"Euler-Maruyama step dt = {dt} is too large for eq. (1): the covariance lost "
                               f"positive definiteness at t = {t + h:.4g} s; use a smaller dt")
        t += h
        while idx < t_eval.size and t_eval[idx] <= t + 1e-9:
            xs[idx], Ps[idx] = xi, P
            idx += 1
    return xs, Ps


def _continuous_topology(topology, n, t_final, t_eval, switch_times):
    if isinstance(topology, SwitchingTopology):
        if topology.n_agents != n:
            raise ValueError(f"topology has {topology.n_agents} agents; the states have {n}")
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
        graphs = np.stack([_check_topologies(topology(t), n, "topology(t)", stacked=False) for t in breaks[:-1]])
        return breaks, graphs
    g = _check_topologies(topology, n, "topology", stacked=False)
    return np.array([0.0, t_final]), g[None]


def _discrete_topology(topologies, n, n_steps, batch):
    if callable(topologies):
        if n_steps is None:
            raise ValueError("n_steps is required when topologies is a function of k")
        n_steps = _check_steps(n_steps)
        return (lambda k: _check_topologies(topologies(k), n, f"topologies({k})", stacked=False)), n_steps
    arr = np.asarray(topologies, dtype=float)
    if arr.ndim == 2:
        g = _check_topologies(arr, n, "topologies", stacked=False)
        if n_steps is None:
            raise ValueError("n_steps is required when topologies is a single (n, n) graph")
        return (lambda k: g), _check_steps(n_steps)
    g = _check_topologies(arr, n, "topologies", stacked=True)
    _check_batch(g.shape[1:-2], batch, "topologies")
    if n_steps is None:
        n_steps = g.shape[0]
    n_steps = _check_steps(n_steps)
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


def _check_steps(n_steps):
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 0:
        raise ValueError(f"n_steps must be a non-negative integer; got {n_steps!r}")
    return int(n_steps)


def _check_topologies(G, n, name, stacked):
    """Return boolean adjacency g_ij (i hears j); (n, n) or (K, ..., n, n) if `stacked`."""
    arr = np.asarray(G, dtype=float)
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
        raise ValueError(f"{name} must be a square (n, n) adjacency (or a stack of them); got shape {arr.shape}")
    if stacked and arr.ndim < 3:
        raise ValueError(f"{name} must be a switching sequence of shape (K, n, n); got shape {arr.shape}")
    if n is not None and arr.shape[-1] != n:
        raise ValueError(f"{name} is a graph on {arr.shape[-1]} agents; expected {n} (shape {arr.shape})")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must have finite, non-negative entries")
    if np.any(np.diagonal(arr, axis1=-2, axis2=-1) != 0):
        raise ValueError(f"{name} must have a zero diagonal (g_ii = 1 is implied by the scheme)")
    return arr > 0


def _check_P(P, name):
    check_covariance(P, name, definite=True)
    return P


def _as_state(xi, P):
    """Bring (xi, P) to the vector form (..., n, m), (..., n, m, m); report if scalar."""
    xi = np.asarray(xi, dtype=float)
    P = np.asarray(P, dtype=float)
    if xi.ndim < 1 or not np.all(np.isfinite(xi)):
        raise ValueError(f"xi must be a finite array of shape (..., n) or (..., n, m); got shape {xi.shape}")
    if P.ndim == xi.ndim:  # scalar information states
        if P.shape != xi.shape:
            raise ValueError(f"P must have the shape of xi {xi.shape} for scalar states; got {P.shape}")
        if not np.all(np.isfinite(P)) or np.any(P <= 0):
            raise ValueError("P must hold positive, finite variances")
        return True, xi[..., None], P[..., None, None]
    if P.ndim == xi.ndim + 1:
        m = xi.shape[-1]
        if P.shape != xi.shape + (m,):
            raise ValueError(f"P must have shape {xi.shape + (m,)} for states of shape {xi.shape}; got {P.shape}")
        return False, xi, _check_P(P, "P")
    raise ValueError(
        f"P must have shape (..., n) (scalar states) or (..., n, m, m); got {P.shape} for xi of shape {xi.shape}"
    )


def _from_state(scalar, xi, P):
    if scalar:
        return xi[..., 0], P[..., 0, 0]
    return xi, P


def _expand_Q(Q, n, m):
    Q = np.asarray(Q, dtype=float)
    if Q.ndim == 0:
        Q = Q * np.eye(m)
    if Q.shape not in ((m, m), (n, m, m)):
        raise ValueError(f"Incompatible dimensions of Q; expected a scalar, ({m}, {m}) or ({n}, {m}, {m}); got {Q.shape}")
    check_covariance(Q, "Q")
    return Q


def _expand_omega(Omega, n, m):
    Om = np.asarray(Omega, dtype=float)
    if Om.ndim == 0:
        Om = Om * np.eye(m)
    if Om.shape not in ((m, m), (n, n, m, m)):
        raise ValueError(
            f"Incompatible dimensions of Omega; expected a scalar, ({m}, {m}) or ({n}, {n}, {m}, {m}); got {Om.shape}"
        )
    check_covariance(Om, "Omega")
    return Om
