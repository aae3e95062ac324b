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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from . import graphs
from ._validation import as_matrix, as_vector, check_covariance, check_square

__all__ = [
    "SyncDesign",
    "bound_eq21",
    "check_assumption4",
    "circle_contains",
    "closed_loop_matrices",
    "design_synchronization",
    "exponential_bound_ratio",
    "fit_alpha",
    "lemma2_r",
    "local_control",
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
    A : (n, n), B : (n, m) with full column rank, Q : (n, n) positive definite

    Raises
    ------
    ValueError
        B lacks full column rank, (A, B) not stabilizable, or no PD solution found.
    """
    A = check_square(A, "A")
    n = A.shape[0]
    B = as_matrix(B, "B", (n, None))
    Q = check_covariance(Q, "Q", n, definite=True)
    if np.linalg.matrix_rank(B) < B.shape[1]:
        raise ValueError(f"Assumption 3 fails: B must have full column rank; rank {np.linalg.matrix_rank(B)} < {B.shape[1]}")
    _check_stabilizable(A, B)
    scale = max(1.0, float(np.abs(Q).max()))
    P = None
    try:
        P = scipy.linalg.solve_discrete_are(A, B, Q, np.zeros((B.shape[1], B.shape[1])))
    except (np.linalg.LinAlgError, ValueError):
        P = None
    if P is None or riccati_like_residual(A, B, Q, P) > rtol * scale:
        P = Q.copy()
        for _ in range(100_000):
            new = A.T @ P @ A + Q - A.T @ P @ B @ np.linalg.solve(B.T @ P @ B, B.T @ P @ A)
            new = 0.5 * (new + new.T)
            if np.max(np.abs(new - P)) <= 1e-14 * max(1.0, np.abs(new).max()):
                P = new
                break
            P = new
    P = 0.5 * (P + P.T)
    res = riccati_like_residual(A, B, Q, P)
    if res > rtol * scale or np.linalg.eigvalsh(P)[0] <= 0:
        raise ValueError(f"eq. (16) has no positive definite solution found (residual {res:.3g})")
    return P


def riccati_like_residual(A: ArrayLike, B: ArrayLike, Q: ArrayLike, P: ArrayLike) -> float:
    """Largest absolute entry of the left-hand side of eq. (16)."""
    A, B, Q, P = (np.asarray(M, dtype=float) for M in (A, B, Q, P))
    lhs = A.T @ P @ A - P + Q - A.T @ P @ B @ np.linalg.solve(B.T @ P @ B, B.T @ P @ A)
    return float(np.max(np.abs(lhs)))


def riccati_gain(A: ArrayLike, B: ArrayLike, P: ArrayLike) -> np.ndarray:
    """``K = (B^T P B)^{-1} B^T P A`` of Lemma 2; shape (m, n)."""
    A, B, P = (np.asarray(M, dtype=float) for M in (A, B, P))
    return np.linalg.solve(B.T @ P @ B, B.T @ P @ A)


def lemma2_r(A: ArrayLike, B: ArrayLike, Q: ArrayLike, P: ArrayLike) -> float:
    """``r = sigma_max(Q^{-1/2} A^T P B (B^T P B)^{-1} B^T P A Q^{-1/2})^{-1/2}`` (Lemma 2)."""
    A, B, Q, P = (np.asarray(M, dtype=float) for M in (A, B, Q, P))
    w, V = np.linalg.eigh(Q)
    Qmh = (V / np.sqrt(w)) @ V.T
    M = Qmh @ A.T @ P @ B @ np.linalg.solve(B.T @ P @ B, B.T @ P @ A) @ Qmh
    smax = float(np.linalg.norm(M, 2))
    return np.inf if smax == 0 else smax**-0.5


def check_assumption4(adjacency: ArrayLike, pinning: ArrayLike) -> None:
    """Raise ValueError unless Assumption 4 holds.

    The interaction graph must contain a directed spanning tree and at least one
    of its root nodes must be pinned to the leader (``g_root > 0``).
    """
    Aadj = check_square(adjacency, "adjacency")
    g = as_vector(pinning, "pinning", Aadj.shape[0])
    if np.any(g < 0) or np.any(Aadj < 0):
        raise ValueError("adjacency weights and pinning gains must be non-negative")
    roots = graphs.spanning_tree_roots(Aadj)
    if roots.size == 0:
        raise ValueError("Assumption 4 fails: the interaction graph has no directed spanning tree")
    if not np.any(g[roots] > 0):
        raise ValueError(
            f"Assumption 4 fails: no root of a spanning tree (agents {roots.tolist()}, 0-based) is "
            f"pinned to the leader; pinning gains are {g.tolist()}"
        )


def pinned_interaction_matrix(adjacency: ArrayLike, pinning: ArrayLike) -> np.ndarray:
    """``Gamma = (I_N + D + G_pin)^{-1} (L + G_pin)`` of eq. (15); checks Assumption 4."""
    check_assumption4(adjacency, pinning)
    Aadj = np.asarray(adjacency, dtype=float)
    g = np.asarray(pinning, dtype=float)
    L = graphs.laplacian(Aadj)
    d = Aadj.sum(axis=1)
    return (L + np.diag(g)) / (1.0 + d + g)[:, None]


def circle_contains(points: ArrayLike, c0: float, r0: float) -> np.ndarray:
    """Whether complex points lie in the open circle ``C(c0, r0)`` (``|z - c0| < r0``)."""
    return np.abs(np.asarray(points) - c0) < r0


def closed_loop_matrices(
    A: ArrayLike, B: ArrayLike, K: ArrayLike, c: float, Gamma: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """``A_c = I_N (x) A - c Gamma (x) B K`` and ``B_c = c Gamma (x) B K`` (eq. (15))."""
    A, B, K, Gamma = (np.asarray(M, dtype=float) for M in (A, B, K, Gamma))
    Bc = c * np.kron(Gamma, B @ K)
    return np.kron(np.eye(Gamma.shape[0]), A) - Bc, Bc


def spectral_radius(M: ArrayLike) -> float:
    """``rho(M) = max |eig(M)|``."""
    return float(np.max(np.abs(np.linalg.eigvals(np.asarray(M)))))


def power_norms(M: ArrayLike, k_max: int) -> np.ndarray:
    """Induced 2-norms ``|M^k|`` for k = 0..k_max; shape (k_max + 1,)."""
    M = check_square(M, "M")
    out = np.empty(k_max + 1)
    Mk = np.eye(M.shape[0])
    for k in range(k_max + 1):
        out[k] = np.linalg.norm(Mk, 2)
        Mk = Mk @ M
    return out


def fit_alpha(M: ArrayLike, mu: float, k_max: int | None = None) -> float:
    """Smallest alpha with ``|M^k| <= alpha mu^k`` for k = 0..k_max (needs ``rho(M) < mu < 1``).

    By default k_max is long enough that ``mu^k`` has fallen below 1e-12, beyond
    which the geometric decay at rate rho(M) < mu cannot catch up in practice.
    """
    rho = spectral_radius(M)
    if not rho < mu < 1:
        raise ValueError(f"need rho(A_c) = {rho:.4g} < mu = {mu} < 1")
    k_max = k_max if k_max is not None else int(np.ceil(np.log(1e-12) / np.log(mu)))
    norms = power_norms(M, k_max)
    return float(np.max(norms / mu ** np.arange(k_max + 1)))


def exponential_bound_ratio(M: ArrayLike, alpha: float, mu: float, k_max: int) -> float:
    """``max_k |M^k| / (alpha mu^k)`` over k = 0..k_max (<= 1 iff the bound holds there)."""
    norms = power_norms(M, k_max)
    return float(np.max(norms / (alpha * mu ** np.arange(k_max + 1))))


def mu_bar(alpha: float, mu: float, n_agents: int) -> float:
    """Normalization ``mu_bar = alpha sqrt(N) / (1 - mu)`` of Corollary 1."""
    return alpha * np.sqrt(n_agents) / (1.0 - mu)


def bound_eq21(Bc: ArrayLike, G_dist: ArrayLike, p0: float, q_bar: float) -> float:
    """Limit bound of eq. (21): ``|B_c| sqrt(p0) + |G| sqrt(q_bar)`` (G: disturbance matrix)."""
    return float(np.linalg.norm(np.asarray(Bc, dtype=float), 2) * np.sqrt(p0)
                 + np.linalg.norm(np.asarray(G_dist, dtype=float), 2) * np.sqrt(q_bar))


@dataclass(frozen=True)
class SyncDesign:
    """Result of :func:`design_synchronization` (Lemma 2).

    Attributes
    ----------
    P : (n, n) solution of eq. (16);  residual : its largest residual entry
    K : (m, n) control gain;  c : coupling gain ``1 / c0``
    r : Lemma 2's r;  c0, r0 : the circle;  Gamma : (N, N);  eigs : (N,) complex
    in_circle : (N,) bool;  A_c, B_c : (nN, nN) of eq. (15);  rho : rho(A_c)
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


def design_synchronization(
    A: ArrayLike, B: ArrayLike, Q: ArrayLike, adjacency: ArrayLike, pinning: ArrayLike,
    c0: float, r0: float,
) -> SyncDesign:
    """Lemma 2: P from eq. (16), K, c = 1/c0, after checking the circle conditions.

    Raises
    ------
    ValueError
        Assumption 3 or 4 fails, an eigenvalue of Gamma lies outside C(c0, r0),
        or ``r0 / c0 >= r``.
    """
    if not (c0 > 0 and r0 > 0):
        raise ValueError(f"c0 and r0 must be positive; got c0={c0}, r0={r0}")
    P = riccati_like(A, B, Q)
    r = lemma2_r(A, B, Q, P)
    K = riccati_gain(A, B, P)
    Gamma = pinned_interaction_matrix(adjacency, pinning)
    eigs = np.linalg.eigvals(Gamma)
    inside = circle_contains(eigs, c0, r0)
    if not np.all(inside):
        raise ValueError(f"Lemma 2: eigenvalues {eigs[~inside]} of Gamma lie outside C({c0}, {r0})")
    if not r0 / c0 < r:
        raise ValueError(f"Lemma 2: r0/c0 = {r0 / c0:.4g} is not below r = {r:.4g}")
    c = 1.0 / c0
    Ac, Bc = closed_loop_matrices(A, B, K, c, Gamma)
    return SyncDesign(P=P, residual=riccati_like_residual(A, B, Q, P), K=K, c=c, r=r, c0=c0, r0=r0,
                      Gamma=Gamma, eigs=eigs, in_circle=inside, A_c=Ac, B_c=Bc, rho=spectral_radius(Ac))


def local_control(
    xhat: ArrayLike, x_leader: ArrayLike, adjacency: ArrayLike, pinning: ArrayLike, K: ArrayLike, c: float
) -> np.ndarray:
    """The law of Sec. 4.2 for all agents, batched.

    Parameters
    ----------
    xhat : (..., N, n) corrected estimates ``xhat^{(i)}_{k|k}``
    x_leader : (..., n) leader state ``x^{(0)}_k``
    adjacency : (N, N);  pinning : (N,) gains g_i;  K : (m, n);  c : float

    Returns
    -------
    (..., N, m) ndarray
        ``u^{(i)} = c (1 + d_i + g_i)^{-1} K eps^{(i)}``.
    """
    xhat = np.asarray(xhat, dtype=float)
    Aadj = np.asarray(adjacency, dtype=float)
    g = np.asarray(pinning, dtype=float)
    d = Aadj.sum(axis=1)
    Lp = graphs.laplacian(Aadj) + np.diag(g)
    eps = -(Lp @ xhat) + g[:, None] * np.asarray(x_leader, dtype=float)[..., None, :]
    return (c / (1.0 + d + g))[:, None] * (eps @ np.asarray(K, dtype=float).T)


def _check_stabilizable(A: np.ndarray, B: np.ndarray) -> None:
    """PBH test: rank [A - lambda I, B] = n for every eigenvalue with |lambda| >= 1."""
    n = A.shape[0]
    for lam in np.linalg.eigvals(A):
        if abs(lam) >= 1 - 1e-12:
            if np.linalg.matrix_rank(np.hstack([A - lam * np.eye(n), B]), tol=1e-9) < n:
                raise ValueError(f"Assumption 3 fails: (A, B) is not stabilizable (mode lambda = {lam:.4g})")
