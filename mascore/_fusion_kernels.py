"""The kernels the fusion filters share (no checks of their own: callers check).

Used by :mod:`mascore.sensor_network` and :mod:`mascore.fusion`: weighted mixes over the
agent axis, information-form updates, consensus rounds, covariance-intersection weights; and the
factor of a covariance that the samplers draw with (:func:`mascore.noise.psd_factor` checks, then calls it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ._validation import symmetric_part


def metropolis(links: np.ndarray) -> np.ndarray:
    deg = links.sum(axis=1)
    W = np.where(links, 1.0 / (1.0 + np.maximum(deg[:, None], deg[None, :])), 0.0)
    W[np.diag_indices_from(W)] = 1.0 - W.sum(axis=1)
    return W


def ci_objective(infos: np.ndarray, criterion: str):
    """The criterion ``f(w)`` (trace of ``P`` or ``-log det P^{-1}``) of weights ``(..., k)`` and its gradient."""
    def f(w):
        info = np.einsum("...k,...kij->...ij", w, infos)
        if criterion == "det":
            sign, logdet = np.linalg.slogdet(info)
            return np.where(sign > 0, -logdet, np.inf)
        return np.trace(np.linalg.inv(info), axis1=-2, axis2=-1)

    def grad(w):
        inv = np.linalg.inv(np.einsum("...k,...kij->...ij", w, infos))
        if criterion == "det":  # d(-log det) / dw_k = -tr(Om^{-1} Om_k)
            return -np.einsum("...ij,...kji->...k", inv, infos)
        return -np.einsum("...ij,...kjl,...li->...k", inv, infos, inv)  # d tr(Om^{-1}) / dw_k = -tr(Om^-1 Om_k Om^-1)

    return f, grad


#: Curvature of the criterion, relative to the largest, below which a direction of the weights counts as flat.
_FLAT = 1e-10

#: Newton iterations of :func:`ci_weights` (each one step to the optimum of a face, or onto a smaller face).
CI_MAX_ITER = 100


def ci_weights(infos: np.ndarray, criterion: str, valid: np.ndarray | None = None) -> np.ndarray:
    """The simplex weights minimizing trace or det of the fused covariance (a convex problem), for a batch.

    Parameters
    ----------
    infos : (..., k, n, n) ndarray
        Information matrices ``P_j^{-1}`` (symmetric positive definite), one problem per leading index.
    criterion : {"trace", "det"}
        ``trace(P)`` or ``-log det(P^{-1})``, ``P^{-1} = sum_j w_j P_j^{-1}``.
    valid : (..., k) bool ndarray, optional
        Which entries take part (the others get weight 0: padding of problems of fewer than k estimates).

    Returns
    -------
    (..., k) ndarray
        The optimal weights: Newton's method on the simplex with an active set, every problem of the batch at
        once (a step to the optimum of the current face, cut where a weight reaches 0; a weight at 0 freed when
        its Lagrange multiplier says so), each problem stopped when its step and its multipliers vanish. Equal
        weights are kept unless they are beaten (a flat criterion gives ``1/k``: the result does not depend on
        where the search stopped).
    """
    shape = infos.shape[:-3]
    k, n = infos.shape[-3], infos.shape[-1]
    Om = infos.reshape(-1, k, n, n)
    B = Om.shape[0]
    ok = np.ones((B, k), bool) if valid is None else np.broadcast_to(valid, (*shape, k)).reshape(B, k)
    w0 = ok / ok.sum(axis=1, keepdims=True)
    f = ci_objective(Om, criterion)[0](w0)
    w, free, live = w0.copy(), ok.copy(), np.ones(B, bool)
    for _ in range(CI_MAX_ITER):
        b = np.flatnonzero(live)
        if b.size == 0:
            break
        w[b], free[b], live[b] = _ci_iteration(Om[b], w[b], free[b], ok[b], criterion)
    better = ci_objective(Om, criterion)[0](w) < f * (1 - 1e-12)
    return np.where(better[:, None], w, w0).reshape(*shape, k)


def _ci_iteration(Om, w, free, ok, criterion):
    """One Newton iteration of :func:`ci_weights` for a batch: the new weights, free set and unfinished problems."""
    d, lam, g = _ci_newton(Om, w, free, criterion)
    f = ci_objective(Om, criterion)[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        limit = np.where(free & (d < 0), -w / d, np.inf)  # where a free weight would reach 0
    alpha = np.minimum(1.0, limit.min(axis=1))
    f0, big = f(w), np.abs(d).max(axis=1) > 1e-9
    for _ in range(60):  # far from the optimum, halve the step until the criterion decreases
        trial = np.where(free, w + alpha[:, None] * d, 0.0)
        worse = big & ~(f(trial) <= f0)
        if not worse.any():
            break
        alpha = np.where(worse, alpha / 2, alpha)
    hit = free & (limit <= alpha[:, None] * (1 + 1e-9))  # weights that reached 0 (together: ties) leave the face
    w = np.where(hit, 0.0, trial)
    w /= w.sum(axis=1, keepdims=True)
    free = free & ~hit
    moving = (np.abs(alpha[:, None] * d).max(axis=1) > 1e-12) | hit.any(axis=1)
    # on the optimum of its face: free the fixed weights of most negative multiplier g_j + lambda (ties
    # together, so that equal estimates keep equal weights), or stop
    mult = np.where(ok & ~free, g + lam[:, None], np.inf)
    tol = 1e-9 * np.abs(g).max(axis=1, keepdims=True)
    freeing = ~moving[:, None] & (mult < -tol) & (mult <= mult.min(axis=1, keepdims=True) + tol)
    free |= freeing
    return w, free, moving | freeing.any(axis=1)


def _ci_newton(Om, w, free, criterion):
    """Newton step ``d`` on the face of the free weights (``sum d = 0``), its multiplier and the gradient.

    Where the criterion is flat along some weights (estimates with equal covariances, or more than
    ``n (n + 1) / 2`` of them: the optimal fused covariance is unique, its weights are not), the step is the
    least-norm one, which leaves the weights along a flat direction as they are (equal, from the start).
    """
    B, k, n, _ = Om.shape
    inv = np.linalg.inv(np.einsum("bk,bkij->bij", w, Om))
    Bk = np.einsum("bij,bkjl->bkil", inv, Om)  # Om^{-1} Om_k
    if criterion == "det":  # f = -log det: g_k = -tr(Om^-1 Om_k), H_kl = tr(Om^-1 Om_k Om^-1 Om_l)
        g = -np.trace(Bk, axis1=-2, axis2=-1)
        H = np.einsum("bkij,blji->bkl", Bk, Bk)
    else:  # f = tr(Om^-1): g_k = -tr(Om^-1 Om_k Om^-1), H_kl = 2 tr(Om^-1 Om_k Om^-1 Om_l Om^-1)
        Ck = np.einsum("bkij,bjl->bkil", Bk, inv)
        g = -np.trace(Ck, axis1=-2, axis2=-1)
        H = 2.0 * np.einsum("bkij,blji->bkl", Bk, Ck)
    scale = np.where(free, np.abs(np.diagonal(H, axis1=1, axis2=2)), 0.0).max(axis=1)  # H / scale: entries ~1
    K = np.zeros((B, k + 1, k + 1))
    both = free[:, :, None] & free[:, None, :]
    K[:, :k, :k] = np.where(both, H / scale[:, None, None], 0.0)
    K[:, np.arange(k), np.arange(k)] += ~free  # fixed weights: d = 0
    K[:, :k, k] = K[:, k, :k] = free
    rhs = np.zeros((B, k + 1))
    rhs[:, :k] = np.where(free, -g / scale[:, None], 0.0)
    e, U = np.linalg.eigh(K)  # K symmetric: the least-norm solution, flat directions (|e| ~ 0) left alone
    inv_e = np.zeros_like(e)
    np.divide(1.0, e, out=inv_e, where=np.abs(e) > _FLAT * np.abs(e).max(axis=1, keepdims=True))
    sol = np.einsum("bij,bj,bkj,bk->bi", U, inv_e, U, rhs)
    sol[:, k] *= scale
    return np.where(free, sol[:, :k], 0.0), sol[:, k], g


def mix(W: np.ndarray, X: np.ndarray, axes: int) -> np.ndarray:
    """``Y_i = sum_j W[i, j] X_j`` over the agent axis of X ``(..., N, *rest)``, rest of `axes` (1 or 2) axes."""
    rest = X.shape[X.ndim - axes:]
    flat = X.reshape(*X.shape[:X.ndim - axes], -1)
    return (W @ flat).reshape(*flat.shape[:-2], W.shape[0], *rest)


def information_update(x, P, S, i):
    """``P+ = (P^{-1} + S)^{-1} = (I + P S)^{-1} P``, ``x+ = x + P+ (i - S x)`` (no inverse of P)."""
    n = x.shape[-1]
    P_new = symmetric_part(np.linalg.solve(np.eye(n) + P @ S, P))
    r = i - (S @ x[..., None])[..., 0]
    return x + (P_new @ r[..., None])[..., 0], P_new


def consensus_rounds(W: np.ndarray, pairs: list, nbrs: np.ndarray, rounds: int) -> tuple:
    """The neighbours' pairs of each consensus round, from the team's initial pairs (round l: after l mixes)."""
    out = []
    for _ in range(rounds):
        out.append(tuple((M[nbrs].copy(), v[nbrs].copy()) for M, v in pairs))
        pairs = [(mix(W, M, 2), mix(W, v, 1)) for M, v in pairs]
    return tuple(out)


def consensus_agent(pairs: list, rounds: Sequence, w_self: float, w_nb: np.ndarray) -> list:
    """One agent's consensus rounds: its own pairs weighted, plus its neighbours' received pairs, per round."""
    for received in rounds:
        pairs = [(w_self * M + np.einsum("k,kab->ab", w_nb, Mn), w_self * v + w_nb @ vn)
                 for (M, v), (Mn, vn) in zip(pairs, received)]
    return pairs


def information_pair(x, P):
    """``(P^{-1}, P^{-1} x)``."""
    Om = symmetric_part(np.linalg.inv(P))
    return Om, _times_vectors(Om, x)


def from_information(Om, q):
    """``(Om^{-1} q, Om^{-1})``."""
    P = symmetric_part(np.linalg.inv(Om))
    return _times_vectors(P, q), P


def _times_vectors(M, v):
    """``M v`` for one vector (one agent's step) or stacks ``(..., n, n)`` times ``(..., n)``."""
    return M @ v if v.ndim == 1 else (M @ v[..., None])[..., 0]


def psd_factor(M: np.ndarray, cholesky_first: bool = False) -> np.ndarray:
    """:func:`mascore.noise.psd_factor` on a checked `M`: the Cholesky factor first if asked, else (or when `M`
    is singular) :func:`psd_sqrt`."""
    if cholesky_first:
        try:
            return np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            pass
    return psd_sqrt(M)


def psd_sqrt(M: np.ndarray) -> np.ndarray:
    """A square root S of PSD matrices ``(..., m, m)`` (``S S^T = M``), from their eigen-decomposition."""
    if M.size == 0:
        return np.zeros_like(M)
    lam, V = np.linalg.eigh(M)
    return V * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]


def broadcast_batch(aname: str, a: tuple, bname: str, b: tuple) -> tuple:
    try:
        return np.broadcast_shapes(a, b)
    except ValueError:
        raise ValueError(f"the batch axes of {aname} {a} and {bname} {b} do not broadcast") from None
