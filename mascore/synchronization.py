"""Riccati-designed leader-follower synchronization (Hengster-Movric et al. 2013; Bhattacharjee and Subbarao 2021, Sec. 4).

N identical agents ``x^{(i)}_{k+1} = A x^{(i)}_k + B u^{(i)}_k + G w^{(i)}_k`` track a
leader ``x^{(0)}_{k+1} = A x^{(0)}_k`` (eq. (10)) with the local law::

    u^{(i)}_k = c (1 + d_i + g_i)^{-1} K eps^{(i)}_k,
    eps^{(i)}_k = sum_j a_ij (xhat^{(j)} - xhat^{(i)}) + g_i (x^{(0)} - xhat^{(i)}),

where ``g_i >= 0`` are the *pinning gains* (the paper's calligraphic G =
diag(g_i); here always called ``pinning``, never ``G``, which in mascore is the
disturbance matrix of the agents). The global error obeys eq. (14) with

    A_c = I_N (x) A - c Gamma (x) B K,   B_c = c Gamma (x) B K,
    Gamma = (I_N + D + G_pin)^{-1} (L + G_pin)                      (eq. (15)).

Lemma 2 designs ``K = (B^T P B)^{-1} B^T P A`` from the Riccati-like equation
(16) and ``c = 1 / c0`` for a circle ``C(c0, r0)`` holding the eigenvalues of
Gamma with ``r0 / c0 < r``. Corollary 1 bounds the normalized error, eq. (21).

Adjacency convention (as in :mod:`mascore.graphs`): ``adjacency[i, j] > 0``
means agent i receives from agent j.

Graphs may be directed (the paper's example is a directed ring pinned at one
agent): nothing here uses a Laplacian eigen-decomposition. What the theory needs
is checked instead: Assumption 4 (a directed spanning tree with a pinned root)
wherever Gamma is formed. Every public function checks its arguments and names
the one at fault; :class:`SynchronizationLaw` checks the constant graph and gains
once, when it is built, and then each call checks only the estimates it is given.

Units: discrete time, step index ``k``; ``A``, ``B``, ``K`` map one step (``K`` in (input unit)/(state
unit)); ``Q`` of eq. (16) is a design *weight* (not a covariance) in 1/(state unit)^2 like ``P``;
``Gamma``, the coupling ``c``, the circle ``C(c0, r0)``, Lemma 2's ``r``, the pinning gains and the
adjacency weights are dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from . import graphs
from ._validation import (
    Frozen,
    as_vector,
    check_adjacency,
    check_covariance,
    check_positive,
    check_positive_int,
    frozen_copy,
    require_finite,
)
from ._validation import as_matrix as _matrix
from ._validation import check_square as _square
from ._validation import float_array as _float_array
from .agents import is_system, system_matrices

__all__ = [
    "SyncDesign",
    "bound_eq21",
    "check_assumption4",
    "circle_contains",
    "closed_loop_matrices",
    "default_circle",
    "design_synchronization",
    "exponential_bound_ratio",
    "fit_alpha",
    "lemma2_r",
    "local_control",
    "SynchronizationLaw",
    "mu_bar",
    "pinned_interaction_matrix",
    "power_norms",
    "riccati_gain",
    "riccati_like",
    "riccati_like_residual",
    "spectral_radius",
]


def riccati_like(A: ArrayLike, B: ArrayLike, Q: ArrayLike, rtol: float = 1e-8) -> np.ndarray:
    """Positive definite solution P of the Riccati-like equation (16).

    ``A^T P A - P + Q - A^T P B (B^T P B)^{-1} B^T P A = 0``: a discrete
    algebraic Riccati equation with zero input weight. Solved with
    :func:`scipy.linalg.solve_discrete_are` (``R = 0``; the generalized
    eigenvalue method handles the singular weight), falling back to the
    Riccati difference iteration from ``P = Q``; the residual is checked.

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    B : (n, m) array_like
        Agent input matrix, full column rank.
    Q : (n, n) array_like
        Design weight of the Riccati-like equation (16), positive definite: a weight, not a covariance,
        in the units of ``P`` (x^T P x is unit-free: 1/(state unit)^2).
    rtol : float
        Accepted residual relative to ``max(1, max |Q|)``; finite, > 0.

    Returns
    -------
    (n, n) ndarray
        P, symmetric positive definite.

    Raises
    ------
    ValueError
        B lacks full column rank, (A, B) not stabilizable, or no PD solution found.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> P = sync.riccati_like(np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2))
    >>> np.round(P, 6)                                         # B = I: P = Q (Bhattacharjee and Subbarao, Sec. 5)
    array([[0.1, 0. ],
           [0. , 0.1]])
    """
    A, B, Q = _check_system(A, B, Q)
    check_positive(rtol, "rtol")
    if np.linalg.matrix_rank(B) < B.shape[1]:
        raise ValueError(f"Assumption 3 fails: B must have full column rank; rank {np.linalg.matrix_rank(B)} < {B.shape[1]}")
    _check_stabilizable(A, B)
    scale = max(1.0, float(np.abs(Q).max()))
    P = None
    try:
        P = scipy.linalg.solve_discrete_are(A, B, Q, np.zeros((B.shape[1], B.shape[1])))
    except (np.linalg.LinAlgError, ValueError):
        P = None
    if P is None or not np.all(np.isfinite(P)) or _residual(A, B, Q, P) > rtol * scale:
        P = Q.copy()
        for _ in range(100_000):
            try:
                new = A.T @ P @ A + Q - A.T @ P @ B @ np.linalg.solve(B.T @ P @ B, B.T @ P @ A)
            except np.linalg.LinAlgError:
                break
            new = 0.5 * (new + new.T)
            if not np.all(np.isfinite(new)):
                break
            if np.max(np.abs(new - P)) <= 1e-14 * max(1.0, np.abs(new).max()):
                P = new
                break
            P = new
    P = 0.5 * (P + P.T)
    res = _residual(A, B, Q, P) if np.all(np.isfinite(P)) else np.inf
    if not res <= rtol * scale or np.linalg.eigvalsh(P)[0] <= 0:
        raise ValueError(f"eq. (16) has no positive definite solution found (residual {res:.3g})")
    return P


def riccati_like_residual(A: ArrayLike, B: ArrayLike, Q: ArrayLike, P: ArrayLike) -> float:
    """Largest absolute entry of the left-hand side of eq. (16).

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    B : (n, m) array_like
        Agent input matrix, full column rank.
    Q : (n, n) array_like
        Design weight of the Riccati-like equation (16), symmetric positive definite: a weight, not a
        covariance, in 1/(state unit)^2 like ``P``.
    P : (n, n) array_like
        Candidate solution, symmetric positive definite (so that ``B^T P B`` is invertible).

    Returns
    -------
    float
        The residual (0 for the solution).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)
    >>> sync.riccati_like_residual(A, B, Q, sync.riccati_like(A, B, Q)) < 1e-12
    True
    """
    A, B, Q = _check_system(A, B, Q)
    P = _check_P(P, B)
    return _finite_float(_residual(A, B, Q, P), "residual of eq. (16)")


def _residual(A, B, Q, P) -> float:
    """:func:`riccati_like_residual` on checked arrays."""
    lhs = A.T @ P @ A - P + Q - A.T @ P @ B @ np.linalg.solve(B.T @ P @ B, B.T @ P @ A)
    return float(np.max(np.abs(lhs)))


def riccati_gain(A: ArrayLike, B: ArrayLike, P: ArrayLike) -> np.ndarray:
    """``K = (B^T P B)^{-1} B^T P A`` of Lemma 2.

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    B : (n, m) array_like
        Agent input matrix, full column rank.
    P : (n, n) array_like
        Symmetric positive definite.

    Returns
    -------
    (m, n) ndarray
        The gain: it minimizes ``(A x + B u)^T P (A x + B u)`` over ``u = -K x``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> A = np.array([[0.0, -1.0], [1.0, 0.0]])
    >>> bool(np.allclose(sync.riccati_gain(A, np.eye(2), np.eye(2)), A))   # B = I: K = A
    True
    """
    A = _square(A, "A")
    B = _matrix(B, "B", (A.shape[0], None))
    P = _check_P(P, B)
    return _finite_array(np.linalg.solve(B.T @ P @ B, B.T @ P @ A), "gain K")


def lemma2_r(A: ArrayLike, B: ArrayLike, Q: ArrayLike, P: ArrayLike) -> float:
    """The radius r of Lemma 2, which the circle's ``r0 / c0`` must stay below.

    ``r = sigma_max(Q^{-1/2} A^T P B (B^T P B)^{-1} B^T P A Q^{-1/2})^{-1/2}``. Returns ``inf`` when the
    matrix is zero (e.g. ``A = 0``): Lemma 2's condition ``r0 / c0 < r`` then holds for every circle.

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    B : (n, m) array_like
        Agent input matrix, full column rank.
    Q : (n, n) array_like
        Design weight of the Riccati-like equation (16), symmetric positive definite: a weight, not a
        covariance, in 1/(state unit)^2 like ``P``.
    P : (n, n) array_like
        Solution of eq. (16), symmetric positive definite.

    Returns
    -------
    float
        Lemma 2's r.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)
    >>> round(sync.lemma2_r(A, B, Q, sync.riccati_like(A, B, Q)), 6)
    1.0
    """
    A, B, Q = _check_system(A, B, Q)
    P = _check_P(P, B)
    w, V = np.linalg.eigh(Q)
    Qmh = (V / np.sqrt(w)) @ V.T
    M = Qmh @ A.T @ P @ B @ np.linalg.solve(B.T @ P @ B, B.T @ P @ A) @ Qmh
    smax = float(np.linalg.norm(M, 2))
    return np.inf if smax == 0 else smax**-0.5


def check_assumption4(adjacency: ArrayLike, pinning: ArrayLike) -> None:
    """Raise ValueError unless Assumption 4 holds.

    The interaction graph must contain a directed spanning tree and at least one
    of its root nodes must be pinned to the leader (``g_root > 0``).

    Parameters
    ----------
    adjacency : (N, N) array_like
        Finite, non-negative weights, no self-loops, directed allowed.
    pinning : (N,) array_like
        Pinning gains, finite, non-negative.

    Raises
    ------
    ValueError
        No spanning tree, or no root pinned.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, synchronization as sync
    >>> A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)      # eq. (23)
    >>> ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)   # eq. (24)
    >>> pin = np.array([1.0, 0.0, 0.0, 0.0])                                            # agent 1 hears the leader
    >>> sync.check_assumption4(ring, pin)                    # passes silently
    >>> try:
    ...     sync.check_assumption4(ring, np.zeros(4))
    ... except ValueError:
    ...     print("no agent hears the leader")
    no agent hears the leader
    """
    Aadj, g = _check_graph(adjacency, pinning)
    roots = graphs.spanning_tree_roots(Aadj)
    if roots.size == 0:
        comps = graphs.connected_components(Aadj)
        if len(comps) > 1:
            raise ValueError(f"Assumption 4 fails: the interaction graph has no directed spanning tree (adjacency "
                             f"is a disconnected graph, {len(comps)} components: {[c.tolist() for c in comps]}): the "
                             "leader's information cannot reach every agent")
        raise ValueError("Assumption 4 fails: the interaction graph has no directed spanning tree "
                         "(adjacency[i, j] > 0 means agent i receives from agent j)")
    if not np.any(g[roots] > 0):
        raise ValueError(
            f"Assumption 4 fails: no root of a spanning tree (agents {roots.tolist()}, 0-based) is "
            f"pinned to the leader; pinning gains are {g.tolist()}"
        )


def pinned_interaction_matrix(adjacency: ArrayLike, pinning: ArrayLike) -> np.ndarray:
    """``Gamma = (I_N + D + G_pin)^{-1} (L + G_pin)`` of eq. (15); checks Assumption 4.

    Parameters
    ----------
    adjacency : (N, N) array_like
        Interaction graph.
    pinning : (N,) array_like
        Pinning gains.

    Returns
    -------
    (N, N) ndarray
        Gamma.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, synchronization as sync
    >>> A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)      # eq. (23)
    >>> ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)   # eq. (24)
    >>> pin = np.array([1.0, 0.0, 0.0, 0.0])                                            # agent 1 hears the leader
    >>> Gamma = sync.pinned_interaction_matrix(ring, pin)
    >>> bool(np.linalg.eigvals(Gamma).real.min() > 0)          # all eigenvalues in the right half-plane
    True
    """
    check_assumption4(adjacency, pinning)
    Aadj, g = _check_graph(adjacency, pinning)  # arrays (a networkx graph becomes its adjacency)
    L = graphs.laplacian(Aadj)
    d = Aadj.sum(axis=1)
    return (L + np.diag(g)) / (1.0 + d + g)[:, None]


def circle_contains(points: ArrayLike, c0: float, r0: float) -> np.ndarray:
    """Whether complex points lie in the open circle ``C(c0, r0)`` (``|z - c0| < r0``).

    Parameters
    ----------
    points : array_like
        Finite real or complex points.
    c0 : float
        Finite real centre.
    r0 : float
        Finite radius > 0.

    Returns
    -------
    ndarray of bool
        One entry per point.

    Examples
    --------
    >>> from mascore import synchronization as sync
    >>> sync.circle_contains([0.5, 1.5 + 0.1j], c0=2 / 3, r0=0.6)
    array([ True, False])
    """
    z = _numeric(points, "points")
    c0 = _real(c0, "c0")
    check_positive(r0, "r0")
    return np.abs(z - c0) < r0


def closed_loop_matrices(
    A: ArrayLike, B: ArrayLike, K: ArrayLike, c: float, Gamma: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """``A_c = I_N (x) A - c Gamma (x) B K`` and ``B_c = c Gamma (x) B K`` (eq. (15)).

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    B : (n, m) array_like
        Agent input matrix.
    K : (m, n) array_like
        Control gain.
    c : float
        Coupling gain.
    Gamma : (N, N) array_like
        Pinned interaction matrix.

    Returns
    -------
    A_c : (n N, n N) ndarray
        Closed-loop matrix of the synchronization error.
    B_c : (n N, n N) ndarray
        How estimation errors enter it.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> Ac, Bc = sync.closed_loop_matrices(np.eye(2), np.eye(2), np.eye(2), 0.5, np.eye(3))
    >>> bool(np.allclose(Ac + Bc, np.eye(6)))                  # A_c + B_c = I (x) A
    True
    """
    A = _square(A, "A")
    n = A.shape[0]
    B = _matrix(B, "B", (n, None))
    K = _matrix(K, "K", (B.shape[1], n))
    Gamma = _square(Gamma, "Gamma")
    _real(c, "c")
    Bc = c * np.kron(Gamma, B @ K)
    return _finite_array(np.kron(np.eye(Gamma.shape[0]), A) - Bc, "A_c"), _finite_array(Bc, "B_c")


def spectral_radius(M: ArrayLike) -> float:
    """``rho(M) = max |eig(M)|`` of a finite square (real or complex) matrix.

    Parameters
    ----------
    M : (n, n) array_like
        The matrix.

    Returns
    -------
    float
        The spectral radius.

    Examples
    --------
    >>> from mascore import synchronization as sync
    >>> sync.spectral_radius([[0.0, -2.0], [2.0, 0.0]])
    2.0
    """
    M = _numeric(M, "M")
    if M.ndim != 2 or M.shape[0] != M.shape[1] or M.shape[0] == 0:
        raise ValueError(f"M must be a non-empty square matrix; got shape {M.shape}")
    return _finite_float(float(np.max(np.abs(np.linalg.eigvals(M)))), "spectral radius")


def power_norms(M: ArrayLike, k_max: int) -> np.ndarray:
    """Induced 2-norms ``|M^k|`` for k = 0..k_max.

    Parameters
    ----------
    M : (n, n) array_like
        Finite square matrix.
    k_max : int
        Last power (>= 1).

    Returns
    -------
    (k_max + 1,) ndarray
        The norms.

    Raises
    ------
    ValueError
        If ``|M^k|`` overflows.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> sync.power_norms(0.5 * np.eye(2), 3)
    array([1.   , 0.5  , 0.25 , 0.125])
    """
    M = _square(M, "M")
    k_max = check_positive_int(k_max, "k_max")
    out = np.empty(k_max + 1)
    Mk = np.eye(M.shape[0])
    for k in range(k_max + 1):
        out[k] = np.linalg.norm(Mk, 2)
        Mk = Mk @ M
    if not np.all(np.isfinite(out)):
        k_bad = int(np.argmin(np.isfinite(out)))
        raise ValueError(f"|M^k| overflowed at k = {k_bad} (rho(M) > 1 and k_max = {k_max} too large)")
    return out


def fit_alpha(M: ArrayLike, mu: float, k_max: int | None = None) -> float:
    """Smallest alpha with ``|M^k| <= alpha mu^k`` for k = 0..k_max (needs ``rho(M) < mu < 1``).

    By default k_max is long enough that ``mu^k`` has fallen below 1e-12, beyond
    which the geometric decay at rate rho(M) < mu cannot catch up in practice.

    Parameters
    ----------
    M : (n, n) array_like
        Finite square matrix.
    mu : float
        The rate, ``rho(M) < mu < 1``.
    k_max : int, optional
        Last power checked.

    Returns
    -------
    float
        The smallest alpha.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> round(sync.fit_alpha(np.array([[0.5, 1.0], [0.0, 0.5]]), mu=0.8), 3)
    1.655
    """
    M = _square(M, "M")
    _real(mu, "mu")
    if k_max is not None:
        k_max = check_positive_int(k_max, "k_max")
    rho = spectral_radius(M)
    if not rho < mu < 1:
        raise ValueError(f"need rho(A_c) = {rho:.4g} < mu = {mu} < 1")
    k_max = k_max if k_max is not None else int(np.ceil(np.log(1e-12) / np.log(mu)))
    norms = power_norms(M, k_max)
    return _finite_float(float(np.max(norms / mu ** np.arange(k_max + 1))), "alpha")


def exponential_bound_ratio(M: ArrayLike, alpha: float, mu: float, k_max: int) -> float:
    """``max_k |M^k| / (alpha mu^k)`` over k = 0..k_max (at most 1 iff the bound holds there).

    Parameters
    ----------
    M : (n, n) array_like
        Finite square matrix.
    alpha : float
        Constant of the bound, > 0.
    mu : float
        Rate of the bound, > 0.
    k_max : int
        Last power checked (>= 1).

    Returns
    -------
    float
        The largest ratio.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> sync.exponential_bound_ratio(0.5 * np.eye(2), alpha=1.0, mu=0.5, k_max=10)
    1.0
    """
    M = _square(M, "M")
    check_positive(alpha, "alpha")
    check_positive(mu, "mu")
    k_max = check_positive_int(k_max, "k_max")
    norms = power_norms(M, k_max)
    with np.errstate(over="ignore", divide="ignore", under="ignore"):
        ratio = float(np.max(norms / (alpha * mu ** np.arange(k_max + 1))))
    if not np.isfinite(ratio):
        raise ValueError(f"alpha mu^k under- or overflowed for alpha = {alpha!r}, mu = {mu!r} over k <= {k_max}; "
                         "the ratio cannot be represented")
    return ratio


def mu_bar(alpha: float, mu: float, n_agents: int) -> float:
    """Normalization ``mu_bar = alpha sqrt(N) / (1 - mu)`` of Corollary 1.

    Parameters
    ----------
    alpha : float
        Constant of the exponential bound, > 0.
    mu : float
        Its rate, in (0, 1).
    n_agents : int
        Team size N.

    Returns
    -------
    float
        ``mu_bar``.

    Examples
    --------
    >>> from mascore import synchronization as sync
    >>> round(float(sync.mu_bar(1.1, 0.9, 4)), 6)
    22.0
    """
    check_positive(alpha, "alpha")
    check_positive(mu, "mu")
    if not mu < 1:
        raise ValueError(f"mu must lie in (0, 1) (the decay rate of |A_c^k| <= alpha mu^k); got {mu!r}")
    check_positive_int(n_agents, "n_agents")
    return _finite_float(alpha * np.sqrt(n_agents) / (1.0 - mu), "mu_bar")


def bound_eq21(Bc: ArrayLike, G_dist: ArrayLike, p0: float, q_bar: float) -> float:
    """Limit bound of eq. (21): ``|B_c| sqrt(p0) + |G| sqrt(q_bar)``.

    Parameters
    ----------
    Bc : array_like
        ``B_c`` of eq. (15), finite.
    G_dist : array_like
        Disturbance matrix, finite.
    p0 : float
        Bound on the estimation error (finite, >= 0).
    q_bar : float
        Bound on the disturbance (finite, >= 0).

    Returns
    -------
    float
        The bound.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import synchronization as sync
    >>> sync.bound_eq21(np.eye(2), np.eye(2), p0=4.0, q_bar=1.0)
    3.0
    """
    Bc = _matrix(Bc, "Bc")
    G_dist = _matrix(G_dist, "G_dist")
    check_positive(p0, "p0", allow_zero=True)
    check_positive(q_bar, "q_bar", allow_zero=True)
    return _finite_float(float(np.linalg.norm(Bc, 2) * np.sqrt(p0) + np.linalg.norm(G_dist, 2) * np.sqrt(q_bar)),
                         "bound of eq. (21)")


@dataclass(frozen=True, eq=False)
class SyncDesign(Frozen):
    """Result of :func:`design_synchronization` (Lemma 2).

    Parameters
    ----------
    P : (n, n) ndarray
        Solution of eq. (16).
    residual : float
        Its largest residual entry.
    K : (m, n) ndarray
        Control gain.
    c : float
        Coupling gain ``1 / c0``.
    r : float
        Lemma 2's r.
    c0 : float
        Centre of the circle.
    r0 : float
        Radius of the circle.
    Gamma : (N, N) ndarray
        Pinned interaction matrix of eq. (15).
    eigs : (N,) complex ndarray
        Eigenvalues of Gamma.
    in_circle : (N,) bool ndarray
        Which eigenvalues lie in ``C(c0, r0)``.
    A_c : (n N, n N) ndarray
        Closed-loop matrix of eq. (15).
    B_c : (n N, n N) ndarray
        Input matrix of eq. (15).
    rho : float
        Spectral radius of ``A_c``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, synchronization as sync
    >>> A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)      # eq. (23)
    >>> ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)   # eq. (24)
    >>> pin = np.array([1.0, 0.0, 0.0, 0.0])                                            # agent 1 hears the leader
    >>> d = sync.design_synchronization(A, B, Q, ring, pin, c0=2 / 3, r0=0.6)
    >>> float(d.c), round(float(d.r), 6), bool(d.rho < 1)
    (1.5, 1.0, True)
    """

    P: np.ndarray
    residual: float
    K: np.ndarray
    c: float
    r: float
    c0: float
    r0: float
    Gamma: np.ndarray
    eigs: np.ndarray
    in_circle: np.ndarray
    A_c: np.ndarray
    B_c: np.ndarray
    rho: float

    def __post_init__(self) -> None:
        self._freeze_arrays()


def default_circle(adjacency: ArrayLike, pinning: ArrayLike) -> tuple[float, float]:
    """The circle ``C(c0, r0)`` of Lemma 2 computed from the spectrum of Gamma: smallest ``r0 / c0``.

    Lemma 2 needs every eigenvalue ``lambda_i`` of Gamma (eq. (15)) inside ``C(c0, r0)``
    and ``r0 / c0 < r``; the circle here minimizes ``r0 / c0 = max_i |lambda_i / c0 - 1|``
    (a convex problem in ``1 / c0``), so it is the one most likely to pass the second
    test. For real eigenvalues in ``[a, b]`` it is ``c0 = (a + b) / 2``, ``r0 = (b - a) / 2``.
    ``r0`` is enlarged by a relative ``1e-6`` so the eigenvalues lie strictly inside.

    Parameters
    ----------
    adjacency : (N, N) array_like or networkx graph
        Interaction graph (directed allowed).
    pinning : (N,) array_like
        Pinning gains to the leader (dimensionless, >= 0).

    Returns
    -------
    c0, r0 : float
        Centre and radius (dimensionless, like the eigenvalues of Gamma).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, synchronization as sync
    >>> ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)   # eq. (24)
    >>> c0, r0 = sync.default_circle(ring, [1.0, 0.0, 0.0, 0.0])
    >>> round(c0, 3), round(r0 / c0, 3)                  # the paper's C(2/3, 0.6) has r0 / c0 = 0.9
    (0.542, 0.844)
    """
    from scipy.optimize import minimize_scalar

    eigs = np.linalg.eigvals(pinned_interaction_matrix(adjacency, pinning))
    ratio = lambda inv_c0: float(np.max(np.abs(inv_c0 * eigs - 1.0)))  # noqa: E731
    hi = float(np.min(2.0 * eigs.real / np.abs(eigs) ** 2))  # beyond it some |s lambda - 1| >= 1
    best = minimize_scalar(ratio, bounds=(0.0, hi), method="bounded", options={"xatol": 1e-12 * hi})
    c0 = 1.0 / float(best.x)
    r0 = float(np.max(np.abs(eigs - c0))) * (1.0 + 1e-6) + 1e-12 * c0
    return c0, r0


def design_synchronization(
    A: ArrayLike, B: ArrayLike | None = None, Q: ArrayLike | None = None, adjacency: ArrayLike | None = None,
    pinning: ArrayLike | None = None, c0: float | None = None, r0: float | None = None,
) -> SyncDesign:
    """Lemma 2: P from eq. (16), K, c = 1/c0, after checking the circle conditions.

    Without `c0` and `r0` the circle is computed from the spectrum of Gamma by
    :func:`default_circle` (the smallest ``r0 / c0``); pass both to override it
    (the paper's example uses ``C(2/3, 0.6)``), or `c0` alone to get the smallest
    radius about that centre.

    Call as ``design_synchronization(A, B, Q, adjacency, pinning)`` or with a system
    in place of ``(A, B)``: ``design_synchronization(sys, Q, adjacency, pinning)``,
    ``sys`` a discrete-time python-control ``StateSpace`` (e.g. from ``control.c2d``)
    or an :class:`mascore.agents.LTIAgent`; a continuous-time one is refused.

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix (discrete time, one sampling period), or the agent itself.
    B : (n, m) array_like
        Agent input matrix, full column rank.
    Q : (n, n) array_like
        Weight of the Riccati-like equation (16), symmetric positive definite: a
        design weight (not a covariance), in (cost unit)/(state unit)^2.
    adjacency : (N, N) array_like or networkx graph
        Interaction graph (directed allowed), dimensionless weights.
    pinning : (N,) array_like
        Pinning gains to the leader (dimensionless, >= 0).
    c0 : float, optional
        Centre of the circle that must hold the eigenvalues of Gamma (dimensionless).
    r0 : float, optional
        Its radius (only with `c0`).

    Returns
    -------
    SyncDesign
        The design and its checks (its ``r`` is ``inf`` when the matrix of :func:`lemma2_r` is
        zero, e.g. ``A = 0``: then any circle passes).

    Raises
    ------
    ValueError
        Assumption 3 or 4 fails, an eigenvalue of Gamma lies outside C(c0, r0),
        or ``r0 / c0 >= r``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, synchronization as sync
    >>> A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)      # eq. (23)
    >>> ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)   # eq. (24)
    >>> pin = np.array([1.0, 0.0, 0.0, 0.0])                                            # agent 1 hears the leader
    >>> d = sync.design_synchronization(A, B, Q, ring, pin, c0=2 / 3, r0=0.6)
    >>> bool(d.in_circle.all()), bool(np.allclose(d.K, A))     # with B = I the gain is A
    (True, True)
    >>> auto = sync.design_synchronization(A, B, Q, ring, pin)  # circle from the spectrum of Gamma
    >>> bool(auto.r0 / auto.c0 < d.r0 / d.c0), bool(auto.rho < 1)
    (True, True)
    """
    if is_system(A):
        A_sys, B_sys, _ = system_matrices(A, "discrete", name="A", needed_by="design_synchronization (Lemma 2)")
        if pinning is None:  # (sys, Q, adjacency, pinning) positionally
            B, Q, adjacency, pinning = None, B, Q, adjacency
        elif B is not None:
            raise TypeError("design_synchronization(sys, Q, adjacency, pinning): B is the system's; do not pass it")
        A, B = A_sys, B_sys
    for name, value in (("B", B), ("Q", Q), ("adjacency", adjacency), ("pinning", pinning)):
        if value is None:
            raise TypeError(f"design_synchronization needs {name}: call (A, B, Q, adjacency, pinning) or "
                            "(sys, Q, adjacency, pinning)")
    if c0 is None:
        if r0 is not None:
            raise ValueError("r0 was given without c0: pass both (the circle C(c0, r0)), c0 alone, or neither "
                             "(the circle is then computed from the spectrum of Gamma)")
        c0, r0 = default_circle(adjacency, pinning)
    elif r0 is None:
        check_positive(c0, "c0")
        eigs0 = np.linalg.eigvals(pinned_interaction_matrix(adjacency, pinning))
        r0 = float(np.max(np.abs(eigs0 - c0))) * (1.0 + 1e-6) + 1e-12 * c0
    check_positive(c0, "c0")
    check_positive(r0, "r0")
    P = riccati_like(A, B, Q)
    r = lemma2_r(A, B, Q, P)
    K = riccati_gain(A, B, P)
    Gamma = pinned_interaction_matrix(adjacency, pinning)
    eigs = np.linalg.eigvals(Gamma)
    inside = circle_contains(eigs, c0, r0)
    if not np.all(inside):
        raise ValueError(f"Lemma 2: eigenvalues {eigs[~inside]} of Gamma (eq. (15), from adjacency and pinning) "
                         f"lie outside C({c0}, {r0}); pass a larger r0, or leave c0 and r0 out to have the circle "
                         f"computed from the spectrum of Gamma")
    if not r0 / c0 < r:
        raise ValueError(
            f"Lemma 2: r0/c0 = {r0 / c0:.4g} is not below r = {r:.4g}. r0/c0 comes from the graph (the eigenvalues "
            f"of Gamma = (I + D + G_pin)^-1 (L + G_pin), eq. (15)): pin more agents, raise the pinning gains or "
            f"add edges to shrink it. "
            f"r comes from the agent (A, B) and the shape of Q only: scaling Q does not change r (P scales with "
            f"it)" + _agent_remedy(A))
    c = 1.0 / c0
    Ac, Bc = closed_loop_matrices(A, B, K, c, Gamma)
    return SyncDesign(P=P, residual=riccati_like_residual(A, B, Q, P), K=K, c=c, r=r, c0=c0, r0=r0,
                      Gamma=Gamma, eigs=eigs, in_circle=inside, A_c=Ac, B_c=Bc, rho=spectral_radius(Ac))


def _agent_remedy(A: np.ndarray) -> str:
    """The end of Lemma 2's message: what the agent's discrete-time `A` says about raising r."""
    lam = np.linalg.eigvals(A)
    continuous = lam[(lam.real < 0) & (np.abs(lam) > 1)]
    if continuous.size:  # expm(A_c dt) has such an eigenvalue only for an unstable mode sampled < 4 times a period
        shown = ", ".join(f"{v:.3g}" for v in continuous[:4])
        return (f". A has eigenvalues with a negative real part outside the unit circle ({shown}), as a "
                f"continuous-time matrix has and a sampled one rarely does: Lemma 2 is for discrete time, so if "
                f"A is continuous time, sample it first (control.c2d(sys, dt), or LTIAgent.from_continuous)")
    if np.max(np.abs(lam)) > 1:
        return "; a less unstable A (e.g. a shorter sampling time) raises it"
    return ""


class SynchronizationLaw(Frozen):
    """The law of Sec. 4.2 on a fixed graph and gain, checked once.

    The graph may be directed; it is checked (finite, non-negative, no self-loops) but
    Assumption 4 is not required here (it is a property of the design, checked by
    :func:`design_synchronization`). The constructor checks `adjacency`, `pinning`,
    `K` and `c` and keeps read-only copies; a call checks only the shapes and
    finiteness of `xhat` and `x_leader`. Safe to share between threads.

    Parameters
    ----------
    adjacency : (N, N) array_like
        Interaction graph (``a_ij > 0``: agent i hears agent j).
    pinning : (N,) array_like
        Pinning gains ``g_i >= 0`` (``g_i > 0``: agent i hears the leader).
    K : (m, n) array_like
        Control gain.
    c : float
        Coupling gain, ``c >= 0`` (dimensionless).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, synchronization as sync
    >>> ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)   # eq. (24)
    >>> law = sync.SynchronizationLaw(ring, [1.0, 0.0, 0.0, 0.0], np.eye(2), 1.5)
    >>> law(np.zeros((4, 2)), np.ones(2))[0]                  # c (1 + d_1 + g_1)^-1 = 1.5 / 3
    array([0.5, 0.5])
    """

    __slots__ = ("adjacency", "g", "K", "c", "_Lp", "_scale")

    def __init__(self, adjacency: ArrayLike, pinning: ArrayLike, K: ArrayLike, c: float) -> None:
        c = _real(c, "c")
        if c < 0:
            raise ValueError(f"c (the coupling gain) must be >= 0; got {c}")
        Aadj, g = _check_graph(adjacency, pinning)
        K = _matrix(K, "K")
        self._set(adjacency=frozen_copy(Aadj), g=frozen_copy(g), K=frozen_copy(K), c=c,
                  _Lp=frozen_copy(graphs.laplacian(Aadj) + np.diag(g)),  # L + diag(g)
                  _scale=frozen_copy(c / (1.0 + Aadj.sum(axis=1) + g)))  # c / (1 + d_i + g_i)

    def _args(self) -> tuple:
        return (self.adjacency, self.g, self.K, self.c)

    def __call__(self, xhat: ArrayLike, x_leader: ArrayLike) -> np.ndarray:
        """The inputs of all agents, batched.

        Parameters
        ----------
        xhat : (..., N, n) array_like
            Corrected estimates ``xhat^{(i)}_{k|k}``.
        x_leader : (..., n) array_like
            Leader state ``x^{(0)}_k``.

        Returns
        -------
        (..., N, m) ndarray
            ``u^{(i)} = c (1 + d_i + g_i)^{-1} K eps^{(i)}``.
        """
        N, n = self.g.shape[0], self.K.shape[1]
        xhat = _float_array(xhat, "xhat")
        if xhat.ndim < 2 or xhat.shape[-2:] != (N, n):
            raise ValueError(f"xhat must have shape (..., N, n) = (..., {N}, {n}); got {xhat.shape}")
        x_leader = _float_array(x_leader, "x_leader")
        if x_leader.ndim < 1 or x_leader.shape[-1] != n:
            raise ValueError(f"x_leader must have shape (..., n) = (..., {n}); got {x_leader.shape}")
        if x_leader.ndim > 1:
            try:
                np.broadcast_shapes(xhat.shape[:-2], x_leader.shape[:-1])
            except ValueError:
                raise ValueError(f"the batch dimensions of xhat {xhat.shape} and x_leader {x_leader.shape} "
                                 "do not broadcast") from None
        require_finite(xhat, "xhat")
        require_finite(x_leader, "x_leader")
        eps = -(self._Lp @ xhat) + self.g[:, None] * x_leader[..., None, :]
        u = self._scale[:, None] * (eps @ self.K.T)
        if not np.isfinite(u).all():
            raise ValueError("the control overflowed (NaN or inf) although every input is finite; rescale the problem")
        return u


def local_control(
    xhat: ArrayLike, x_leader: ArrayLike, adjacency: ArrayLike, pinning: ArrayLike, K: ArrayLike, c: float
) -> np.ndarray:
    """The law of Sec. 4.2 for all agents, batched (plain arrays, checked in full on every call).

    In a loop, build :class:`SynchronizationLaw` once and call it: the same numbers,
    the constant arguments checked once.

    Parameters
    ----------
    xhat : (..., N, n) array_like
        Corrected estimates ``xhat^{(i)}_{k|k}``.
    x_leader : (..., n) array_like
        Leader state ``x^{(0)}_k``.
    adjacency : (N, N) array_like
        Interaction graph.
    pinning : (N,) array_like
        Pinning gains ``g_i``.
    K : (m, n) array_like
        Control gain.
    c : float
        Coupling gain, ``c >= 0``.

    Returns
    -------
    (..., N, m) ndarray
        ``u^{(i)} = c (1 + d_i + g_i)^{-1} K eps^{(i)}``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, synchronization as sync
    >>> A, B, Q = np.array([[0.0, -1.0], [1.0, 0.0]]), np.eye(2), 0.1 * np.eye(2)      # eq. (23)
    >>> ring = graphs.adjacency_from_edges(4, [(3, 0), (0, 1), (1, 2), (2, 3)], directed=True)   # eq. (24)
    >>> pin = np.array([1.0, 0.0, 0.0, 0.0])                                            # agent 1 hears the leader
    >>> u = sync.local_control(np.zeros((4, 2)), np.zeros(2), ring, pin, A, 1.5)
    >>> bool(np.all(u == 0))                                   # everyone on the leader: no input
    True
    """
    return SynchronizationLaw(adjacency, pinning, K, c)(xhat, x_leader)


def _check_stabilizable(A: np.ndarray, B: np.ndarray) -> None:
    """PBH test: rank [A - lambda I, B] = n for every eigenvalue with |lambda| >= 1."""
    n = A.shape[0]
    for lam in np.linalg.eigvals(A):
        if abs(lam) >= 1 - 1e-12:
            if np.linalg.matrix_rank(np.hstack([A - lam * np.eye(n), B]), tol=1e-9) < n:
                raise ValueError(f"Assumption 3 fails: (A, B) is not stabilizable (mode lambda = {lam:.4g})")


# --------------------------------------------------------------------------- argument checks


def _real(x, name) -> float:
    """A finite real number (any sign)."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number; got {type(x).__name__} {x!r}")
    if not math.isfinite(float(x)):
        raise ValueError(f"{name} must be finite; got {x!r}")
    return float(x)


def _numeric(x, name) -> np.ndarray:
    """A finite real or complex array."""
    if isinstance(x, (str, bytes)) or x is None:
        raise TypeError(f"{name} must be an array of numbers; got {type(x).__name__} {x!r}")
    arr = np.asarray(x)
    if arr.dtype.kind not in "biufc":
        raise TypeError(f"{name} must be an array of numbers; got dtype {arr.dtype}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or infinite entries")
    return arr


def _check_system(A, B, Q):
    """A (n, n), B (n, m) with m >= 1, Q (n, n) symmetric positive definite."""
    A = _square(A, "A")
    n = A.shape[0]
    B = _matrix(B, "B", (n, None))
    if B.shape[1] == 0:
        raise ValueError(f"B must have at least one column; got shape {B.shape}")
    Q = check_covariance(_float_array(Q, "Q"), "Q", n, definite=True)
    return A, B, Q


def _check_P(P, B) -> np.ndarray:
    """P (n, n) symmetric positive definite, and ``B^T P B`` invertible (B of full column rank)."""
    P = check_covariance(_float_array(P, "P"), "P", B.shape[0], definite=True)
    if np.linalg.matrix_rank(B) < B.shape[1]:
        raise ValueError(f"B must have full column rank (Assumption 3) so that B^T P B is invertible; "
                         f"rank {np.linalg.matrix_rank(B)} < {B.shape[1]}")
    return P


def _check_graph(adjacency, pinning):
    """Adjacency (directed allowed) and pinning gains: finite, non-negative, no self-loops."""
    Aadj = check_adjacency(_float_array(adjacency, "adjacency"), "adjacency")
    if Aadj.shape[0] == 0:
        raise ValueError("adjacency must describe at least one agent; got shape (0, 0)")
    g = as_vector(_float_array(pinning, "pinning"), "pinning", Aadj.shape[0])
    if np.any(g < 0):
        raise ValueError(f"pinning gains must be non-negative; got {g.tolist()}")
    return Aadj, g


def _finite_float(x: float, what: str) -> float:
    if not math.isfinite(x):
        raise ValueError(f"the {what} overflowed (NaN or inf) although every input is finite; rescale the problem")
    return x


def _finite_array(x: np.ndarray, what: str) -> np.ndarray:
    if not np.isfinite(x).all():
        raise ValueError(f"the {what} overflowed (NaN or inf) although every input is finite; rescale the problem")
    return x
