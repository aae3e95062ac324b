"""Plain reference steps of the whole-team filters of Song et al. (2023), straight from the equations.

Written with explicit dense ``F_1``, ``F_2``, ``H_i`` and ``G_i`` and loops
over agents and agent pairs (``O(N^6 m^3)`` for the estimation-based step):
the independent implementation that the tests, the benchmark and
:func:`mascore.papers.song2023.estimator_step_seconds` compare
:mod:`mascore.distributed_kf`'s structured recursions with. Not part of the
public API: import the steps from this module.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ._validation import check_adjacency_stack, check_covariance, check_square, finite_result
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .graphs import laplacian as graph_laplacian
from .sensing import selection_matrices, sensing_mask, team_noise_covariance
from .team_model import closed_loop_matrices

__all__ = ["plain_estimation_based_step", "plain_estimation_based_kernel", "plain_measurement_based_step"]


def plain_estimation_based_step(
    X_hat: ArrayLike,
    Sigma: ArrayLike,
    A: ArrayLike,
    BK: ArrayLike,
    Q: ArrayLike,
    R: ArrayLike,
    adjacency: ArrayLike,
    z: list[np.ndarray],
    adjacency_next: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One step of eqs. (14), (29)-(34), (16)-(20) with explicit dense matrices.

    A loop over agent pairs, for tests and benchmarks only (``O(N^6 m^3)``).

    Parameters
    ----------
    X_hat : (N, m N) array_like
        Row ``i`` is ``X̂_i[k]``.
    Sigma : (m N^2, m N^2) array_like
        Full (unreduced) augmented covariance ``Σ[k]``.
    A, BK, Q : (m, m) array_like
    R : (m N, m N) array_like
        Covariance of ``nu_i``.
    adjacency : (N, N) array_like
        Topology at step k (defines ``F_1``, ``F_2``).
    z : list of N arrays
        ``z_i[k+1]`` stacked as in eq. (3).
    adjacency_next : (N, N) array_like, optional
        Topology at k+1 (defines ``H_i[k+1]``); default `adjacency`.

    Returns
    -------
    X_hat_next : (N, m N) ndarray
    Sigma_next : (m N^2, m N^2) ndarray
    """
    X_hat, A, BK, Q, R, Adj, z = _check_plain_step(X_hat, A, BK, Q, R, adjacency, z)
    N, m = X_hat.shape[0], A.shape[0]
    M = m * N
    Sig = check_covariance(_float_array(Sigma, "Sigma"), "Sigma", size=M * N)
    if Sig.ndim != 2:
        raise ValueError(f"Sigma must be the full ({M * N}, {M * N}) augmented covariance; got shape {Sig.shape}")
    Adj_next = Adj if adjacency_next is None else _check_plain_adjacency(adjacency_next, N, "adjacency_next")
    z = _check_plain_z(z, Adj_next, m)
    out = plain_estimation_based_kernel(X_hat, Sig, A, BK, Q, R, Adj, z, Adj_next)
    return finite_result("estimation-based step", *out)


def plain_estimation_based_kernel(X_hat, Sig, A, BK, Q, R, Adj, z, Adj_next):
    """:func:`plain_estimation_based_step` on checked arguments (the recursion alone, for benchmarks).

    Examples
    --------
    >>> from mascore.graphs import ring_graph
    >>> A, BK, N = np.eye(2), 0.1 * np.eye(2), 3
    >>> z = [np.zeros(6)] * N
    >>> X, S = plain_estimation_based_kernel(np.zeros((N, 6)), np.eye(18), A, BK, np.eye(2), np.eye(6),
    ...                                      ring_graph(N), z, ring_graph(N))
    >>> X.shape, S.shape
    ((3, 6), (18, 18))
    """
    N, m = X_hat.shape[0], A.shape[0]
    M = m * N
    L = graph_laplacian(Adj)
    F1, F2 = closed_loop_matrices(A, BK, L)
    Qc = np.kron(np.eye(N), Q)
    H = selection_matrices(Adj_next, m)
    blk = lambda i: slice(i * M, (i + 1) * M)  # noqa: E731
    # eq. (34) (eq. (32) for i = j)
    F2S = F2 @ Sig @ F2.T
    cross = [F1 @ Sig[blk(i), :] @ F2.T for i in range(N)]  # F_1 E[e_i e^T] F_2^T
    Sig_pred = np.empty_like(Sig)
    for i in range(N):
        for j in range(N):  # F_2 E[e e_j^T] F_1^T = (F_1 E[e_j e^T] F_2^T)^T
            Sig_pred[blk(i), blk(j)] = F1 @ Sig[blk(i), blk(j)] @ F1.T + F2S + cross[i] + cross[j].T + Qc
    X_pred = X_hat @ F1.T  # eq. (14)
    G, X_next = [], np.empty_like(X_hat)
    for i in range(N):
        P = Sig_pred[blk(i), blk(i)]
        S_i = H[i] @ P @ H[i].T + H[i] @ R @ H[i].T  # eq. (17)
        G.append(P @ H[i].T @ np.linalg.inv(S_i))  # eq. (19)
        X_next[i] = X_pred[i] + G[i] @ (z[i] - H[i] @ X_pred[i])  # eqs. (16), (18)
    Sig_next = np.empty_like(Sig)
    for i in range(N):
        for j in range(N):
            P = Sig_pred[blk(i), blk(j)]
            if i == j:
                Sig_next[blk(i), blk(j)] = (np.eye(M) - G[i] @ H[i]) @ P  # eq. (20)
            else:  # eq. (33)
                Sig_next[blk(i), blk(j)] = (
                    -G[i] @ H[i] @ P - P @ H[j].T @ G[j].T + G[i] @ H[i] @ P @ H[j].T @ G[j].T + P
                )
    return X_next, 0.5 * (Sig_next + Sig_next.T)




def plain_measurement_based_step(
    X_hat: ArrayLike,
    Sigma: ArrayLike,
    A: ArrayLike,
    BK: ArrayLike,
    Q: ArrayLike,
    R: ArrayLike,
    adjacency: ArrayLike,
    z: list[np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """One step of eqs. (14)-(20) per agent with dense matrices (reference).

    Parameters
    ----------
    X_hat : (N, m N), Sigma : (N, m N, m N) per-agent covariances.

    Returns
    -------
    X_hat_next : (N, m N), Sigma_next : (N, m N, m N)
    """
    X_hat, A, BK, Q, R, Adj, z = _check_plain_step(X_hat, A, BK, Q, R, adjacency, z)
    N, m = X_hat.shape[0], A.shape[0]
    z = _check_plain_z(z, Adj, m)
    Sigma = check_covariance(_float_array(Sigma, "Sigma"), "Sigma", size=m * N)
    if Sigma.shape != (N, m * N, m * N):
        raise ValueError(f"Incompatible dimensions of Sigma; expected ({N}, {m * N}, {m * N}) but found {Sigma.shape}")
    L = graph_laplacian(Adj)
    F1, _ = closed_loop_matrices(A, BK, L)
    Qc = np.kron(np.eye(N), Q)
    Ebar = np.zeros((m * N, m * N))
    for i in range(N):
        Li = np.kron(L[i:i + 1], np.eye(m))
        Ebar[i * m:(i + 1) * m, i * m:(i + 1) * m] = Li @ R @ Li.T
    IBK = np.kron(np.eye(N), BK)
    H = selection_matrices(Adj, m)
    X_next, S_next = np.empty_like(X_hat), np.empty((N, m * N, m * N))
    for i in range(N):
        P = F1 @ Sigma[i] @ F1.T + IBK @ Ebar @ IBK.T + Qc  # eq. (15)
        x = F1 @ X_hat[i]  # eq. (14)
        S_i = H[i] @ P @ H[i].T + H[i] @ R @ H[i].T
        G = P @ H[i].T @ np.linalg.inv(S_i)
        X_next[i] = x + G @ (z[i] - H[i] @ x)
        S_next[i] = (np.eye(m * N) - G @ H[i]) @ P
    return finite_result("measurement-based step", X_next, 0.5 * (S_next + np.swapaxes(S_next, -1, -2)))


def _check_plain_adjacency(adjacency: ArrayLike, N: int, name: str = "adjacency") -> np.ndarray:
    Adj = check_adjacency_stack(adjacency, name)
    if Adj.shape != (N, N):
        raise ValueError(f"Incompatible dimensions of {name}; expected ({N}, {N}) for {N} agents but found {Adj.shape}")
    sensing_mask(Adj)  # an isolated agent has no H_i: refused here, naming the agent
    return Adj


def _check_plain_step(X_hat, A, BK, Q, R, adjacency, z) -> tuple:
    """Arguments of the plain reference steps (z is checked separately, against its topology)."""
    A = check_square(_float_array(A, "A"), "A")
    m = A.shape[0]
    if m == 0:
        raise ValueError("A must be at least 1 x 1 (an agent with no state)")
    X_hat = _finite(_float_array(X_hat, "X_hat"), "X_hat")
    if X_hat.ndim != 2 or X_hat.shape[0] == 0 or X_hat.shape[1] != m * X_hat.shape[0]:
        raise ValueError(f"X_hat must have shape (N, {m} N) (row i: agent i's team estimate); got {X_hat.shape}")
    N = X_hat.shape[0]
    BK = check_square(_float_array(BK, "BK"), "BK", m)
    Q = check_covariance(_float_array(Q, "Q"), "Q", size=m)
    if Q.ndim != 2:
        raise ValueError(f"Q must be a single ({m}, {m}) matrix; got shape {Q.shape}")
    R = team_noise_covariance(R, N, m)
    check_covariance(R, "R", definite=True)
    Adj = _check_plain_adjacency(adjacency, N)
    return X_hat, A, BK, Q, R, Adj, z


def _check_plain_z(z: object, Adj: np.ndarray, m: int) -> list[np.ndarray]:
    """The stacked measurements ``z_i`` (eq. (3)) of every agent for topology `Adj`."""
    N = Adj.shape[0]
    if isinstance(z, (str, bytes)) or not hasattr(z, "__len__"):
        raise TypeError(f"z must be a list of {N} measurement vectors (one per agent); got {type(z).__name__}")
    if len(z) != N:
        raise ValueError(f"z must hold {N} measurement vectors (one per agent); got {len(z)}")
    sizes = m * (1 + np.count_nonzero(Adj > 0, axis=1))
    out = []
    for i, zi in enumerate(z):
        zi = _finite(_float_array(zi, f"z[{i}]"), f"z[{i}]")
        if zi.shape != (sizes[i],):
            raise ValueError(
                f"Incompatible dimensions of z[{i}]; expected ({sizes[i]},) (in this adjacency agent {i} senses "
                f"{sizes[i] // m} agents of {m} states, itself included) but found {zi.shape}"
            )
        out.append(zi)
    return out
