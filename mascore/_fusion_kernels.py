"""The kernels the fusion filters share (no checks of their own: callers check).

Used by :mod:`mascore.sensor_network` and :mod:`mascore.fusion`: weighted mixes over the
agent axis, information-form updates, consensus rounds, covariance-intersection weights.
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
    def f(w):
        info = np.einsum("k,kij->ij", w, infos)
        if criterion == "det":
            sign, logdet = np.linalg.slogdet(info)
            return -logdet if sign > 0 else np.inf
        return float(np.trace(np.linalg.inv(info)))

    def grad(w):
        inv = np.linalg.inv(np.einsum("k,kij->ij", w, infos))
        if criterion == "det":  # d(-log det) / dw_k = -tr(Om^{-1} Om_k)
            return -np.einsum("ij,kji->k", inv, infos)
        return -np.einsum("ij,kjl,li->k", inv, infos, inv)  # d tr(Om^{-1}) / dw_k = -tr(Om^-1 Om_k Om^-1)

    return f, grad


def ci_weights(infos: np.ndarray, criterion: str) -> np.ndarray:
    """The simplex weights minimizing trace or det of the fused covariance (a convex problem)."""
    from scipy import optimize

    k = infos.shape[0]
    if k == 1:
        return np.ones(1)
    f, grad = ci_objective(infos, criterion)
    w0 = np.full(k, 1.0 / k)
    if k == 2:
        res = optimize.minimize_scalar(lambda a: f(np.array([a, 1.0 - a])), bounds=(0.0, 1.0), method="bounded",
                                       options={"xatol": 1e-12})
        # the bounded search never returns an end point: take one if it is better
        w = min((np.array([t, 1.0 - t]) for t in (float(res.x), 0.0, 1.0)), key=f)
    else:
        res = optimize.minimize(f, w0, jac=grad, method="SLSQP", bounds=[(0.0, 1.0)] * k,
                                constraints=({"type": "eq", "fun": lambda w: w.sum() - 1.0,
                                              "jac": lambda w: np.ones_like(w)},),
                                options={"ftol": 1e-14, "maxiter": 500})
        w = np.clip(res.x, 0.0, None)
        w = w / w.sum()
    # a tie (a flat criterion, e.g. equal covariances) keeps the equal weights: the result does not depend on
    # where the search stopped
    return w if f(w) < f(w0) * (1 - 1e-12) else w0


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
    return Om, (Om @ x[..., None])[..., 0]


def from_information(Om, q):
    """``(Om^{-1} q, Om^{-1})``."""
    P = symmetric_part(np.linalg.inv(Om))
    return (P @ q[..., None])[..., 0], P


def psd_sqrt(M: np.ndarray) -> np.ndarray:
    """A square root S of a PSD matrix (``S S^T = M``), from its eigen-decomposition."""
    if M.size == 0:
        return np.zeros_like(M)
    lam, V = np.linalg.eigh(M)
    return V * np.sqrt(np.clip(lam, 0.0, None))


def broadcast_batch(aname: str, a: tuple, bname: str, b: tuple) -> tuple:
    try:
        return np.broadcast_shapes(a, b)
    except ValueError:
        raise ValueError(f"the batch axes of {aname} {a} and {bname} {b} do not broadcast") from None
