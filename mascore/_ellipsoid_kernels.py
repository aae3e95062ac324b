"""The kernels of the ellipsoidal operations (no checks of their own: callers check).

Shared by :mod:`mascore.ellipsoids` (the public operations) and :mod:`mascore.set_membership`
(the filter's steps): the minimum-trace intersection with a measurement strip and sum of
ellipsoids, the innovation's quadratic form, and the light argument checks of both.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ._validation import check_covariance
from ._validation import float_array as _float_array


def gain_form(c, P, C, y, W, t, shrink):
    """:func:`intersection_gain_form` on arrays already checked (no argument checks)."""
    t = np.asarray(t, dtype=float)[..., None, None]
    Ct = np.swapaxes(C, -1, -2)  # C may carry batch axes (one C per agent)
    PCt = P @ Ct
    S = (C @ PCt) / (1 - t) + W / t
    L = np.swapaxes(np.linalg.solve(S, np.swapaxes(PCt, -1, -2)), -1, -2) / (1 - t)
    IKC = np.eye(P.shape[-1]) - L @ C
    Pt = IKC @ P @ np.swapaxes(IKC, -1, -2) / (1 - t) + L @ W @ np.swapaxes(L, -1, -2) / t  # Joseph form
    nu = y - (c @ C.T if C.ndim == 2 else np.einsum("...ij,...j->...i", C, c))
    new_c = c + np.einsum("...ij,...j->...i", L, nu)
    if shrink:
        delta = 1.0 - np.einsum("...i,...i->...", nu, np.linalg.solve(S, nu[..., None])[..., 0])
        Pt = delta[..., None, None] * Pt
    return new_c, 0.5 * (Pt + np.swapaxes(Pt, -1, -2)), L


def intersection_min_trace(c, P, C, y, W, shrink=False, tol=1e-13, max_iter=100):
    """:func:`intersection_min_trace` on arrays already converted (no argument checks)."""
    if C.shape[0] == 1 and not shrink:
        return min_trace_one_measurement(c, P, C, y, W)
    h, m = trace_profile(P, C, W)
    if shrink:
        nu = np.asarray(y, dtype=float) - c @ C.T
        t = golden(lambda tt: trace_delta(tt, P, C, W, nu, h, m), P.shape[:-2], tol=1e-10)
    else:
        t = newton_trace(h, m, tol, max_iter)
    new_c, new_P, L = gain_form(c, P, C, y, W, t, shrink)
    return new_c, new_P, L, t


def max_innovation_form(c, P, C, y, W, n_iter=60):
    """:func:`max_innovation_form` on arrays already converted (no argument checks)."""
    nu = y - c @ C.T
    S0 = C @ P @ C.T
    if C.shape[0] == 1:
        return nu[..., 0] ** 2 / (np.sqrt(W[..., 0, 0]) + np.sqrt(np.maximum(S0[..., 0, 0], 0.0))) ** 2
    Fi = np.linalg.inv(np.linalg.cholesky(W))
    sig, V = np.linalg.eigh(Fi @ S0 @ np.swapaxes(Fi, -1, -2))
    sig = np.clip(sig, 0.0, None)
    z2 = np.einsum("...ji,...j->...i", V, np.einsum("...ij,...j->...i", Fi, nu)) ** 2
    # g(t) = sum z2 * t (1 - t) / ((1 - t) + sig t); g'(t) changes sign once (g concave)
    lo = np.zeros(sig.shape[:-1])
    hi = np.full(sig.shape[:-1], 1.0 - T_MIN)  # t = 1 exactly is 0/0 when a direction is unmeasured (sig = 0)
    for _ in range(n_iter):
        mid = 0.5 * (lo + hi)
        tt = mid[..., None]
        den = (1 - tt) + sig * tt
        dg = np.sum(z2 * ((1 - 2 * tt) * den - tt * (1 - tt) * (sig - 1)) / den**2, axis=-1)
        lo = np.where(dg > 0, mid, lo)
        hi = np.where(dg > 0, hi, mid)
    tt = (0.5 * (lo + hi))[..., None]
    return np.sum(z2 * tt * (1 - tt) / ((1 - tt) + sig * tt), axis=-1)


def sqrt_trace(P: np.ndarray) -> np.ndarray:
    """``sqrt(trace P)`` of a stack of PSD matrices (round-off below zero clipped)."""
    return np.sqrt(np.maximum(P.trace(axis1=-2, axis2=-1), 0.0))


def sum_min_trace(P1, P2, s1, s2):
    """Shape and beta of :func:`minkowski_sum_min_trace` given ``s_i = sqrt(trace P_i)`` (no argument checks).

    ``P1 / (1 - b) + P2 / b`` with ``b = s2 / (s1 + s2)`` equals ``(s1 + s2) (P1 / s1 + P2 / s2)``;
    a zero term drops out. `P1`, `P2` (and `s1`, `s2`) broadcast against each other.
    """
    total = s1 + s2
    if not (total > 0).all():
        raise ValueError("Minkowski sum of two points: both shape matrices (shape1 and shape2) are zero")
    w1 = np.divide(total, s1, out=np.zeros(np.shape(total)), where=s1 > 0)
    w2 = np.divide(total, s2, out=np.zeros(np.shape(total)), where=s2 > 0)
    P = w1[..., None, None] * P1 + w2[..., None, None] * P2
    return 0.5 * (P + P.swapaxes(-1, -2)), s2 / total


def trace_profile(P: np.ndarray, C: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """h, m with trace P_t = sum_i h_i / (1 + t (m_i - 1)) (see intersection_min_trace)."""
    try:
        E = np.linalg.cholesky(P)
    except np.linalg.LinAlgError as exc:
        raise ValueError("prior shape matrix is not positive definite") from exc
    try:
        Wi = np.linalg.inv(np.linalg.cholesky(W))
    except np.linalg.LinAlgError as exc:
        raise ValueError("measurement shape W = D R D^T must be positive definite") from exc
    F = Wi @ C @ E  # (..., p, n)
    m, U = np.linalg.eigh(np.swapaxes(F, -1, -2) @ F)
    EU = E @ U
    h = np.einsum("...ij,...ij->...j", EU, EU)
    return h, np.clip(m, 0.0, None)


def min_trace_one_measurement(c, P, C, y, W):
    """intersection_min_trace for a single measurement (p = 1), in closed form.

    With ``s = C P C^T``, ``g = P C^T``, ``b = |g|^2 / s``, ``a = trace P - b`` and
    ``mu = s / W``: ``trace P_t = a / (1 - t) + b / (1 + t (mu - 1))``, whose
    minimiser is ``t* = (rho - 1) / (mu - 1 + rho)``, ``rho = sqrt(b (mu - 1) / a)``
    (``t* = 0`` when ``rho <= 1``: the measurement cannot shrink the trace).
    """
    C0 = C[0]
    g = P @ C0  # (..., n)
    s = g @ C0  # (...,)
    w = W[..., 0, 0]
    if not (s >= 0).all():
        raise ValueError("prior shape matrix is not positive semidefinite (C P C^T < 0)")
    if not (w > 0).all():
        raise ValueError("measurement shape W = D R D^T must be positive definite")
    informative = s > 0  # C = 0 measures nothing: the gain is zero and the prior is kept (t -> 0)
    b = np.einsum("...i,...i->...", g, g) / np.where(informative, s, 1.0)
    a = np.maximum(P.trace(axis1=-2, axis2=-1) - b, 0.0)
    mu1 = s / w - 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.sqrt(np.maximum(b * mu1, 0.0) / a)
        t = np.where(np.isfinite(rho), (rho - 1.0) / (mu1 + rho), 1.0)
    t = np.minimum(np.maximum(np.where(mu1 > 0.0, t, 0.0), T_MIN), 1.0 - T_MIN)
    omt = 1.0 - t
    w_t = w / t
    L = g / (omt * (s / omt + w_t))[..., None]  # P C^T S^-1 / (1 - t), S = s / (1 - t) + w / t
    Lc = L[..., :, None]
    # Joseph form (I - L C) P (I - L C)^T / (1 - t) + L W L^T / t: the matrix of the SDP, stable as t -> 1
    IKC = np.eye(P.shape[-1]) - Lc * C0
    Pt = IKC @ P @ IKC.swapaxes(-1, -2) / omt[..., None, None] + w_t[..., None, None] * Lc * L[..., None, :]
    nu = y[..., 0] - c @ C0
    return c + L * nu[..., None], 0.5 * (Pt + Pt.swapaxes(-1, -2)), Lc, t


#: Smallest family parameter used (t = 0 or 1 are limits of the family).
T_MIN = 1e-12


def newton_trace(h: np.ndarray, m: np.ndarray, tol: float, max_iter: int) -> np.ndarray:
    """Minimiser over t in (0, 1) of f(t) = sum h / (1 + t (m - 1)), batched."""
    a = m - 1.0
    lo = np.zeros(h.shape[:-1])
    hi = np.ones(h.shape[:-1])
    t = np.full(h.shape[:-1], 0.5)
    for _ in range(max_iter):
        den = 1.0 + t[..., None] * a
        d1 = -np.sum(h * a / den**2, axis=-1)
        d2 = 2.0 * np.sum(h * a**2 / den**3, axis=-1)
        lo = np.where(d1 < 0, t, lo)
        hi = np.where(d1 < 0, hi, t)
        step = np.divide(d1, d2, out=np.zeros_like(d1), where=d2 > 0)
        new = t - step
        bad = ~((new > lo) & (new < hi))
        new = np.where(bad, 0.5 * (lo + hi), new)
        done = np.abs(new - t) <= tol
        t = new
        if np.all(done):
            break
    return np.clip(t, 1e-15, 1 - 1e-15)


def trace_delta(t, P, C, W, nu, h, m):
    tt = t[..., None]
    f = np.sum(h / (1.0 + tt * (m - 1.0)), axis=-1)
    S = (C @ P @ C.T) / (1 - tt[..., None]) + W / tt[..., None]
    delta = 1.0 - np.einsum("...i,...i->...", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    return delta * f


def golden(fun, batch_shape, tol: float = 1e-10) -> np.ndarray:
    """Batched golden-section minimisation of a unimodal function on (0, 1)."""
    g = (math.sqrt(5) - 1) / 2
    a = np.full(batch_shape, 1e-12)
    b = np.full(batch_shape, 1 - 1e-12)
    x1 = b - g * (b - a)
    x2 = a + g * (b - a)
    f1, f2 = fun(x1), fun(x2)
    while np.max(b - a) > tol:
        left = f1 < f2
        b = np.where(left, x2, b)
        a = np.where(left, a, x1)
        x2n = np.where(left, x1, a + g * (b - a))
        x1n = np.where(left, b - g * (b - a), x2)
        f_new = fun(np.where(left, x1n, x2n))
        f2, f1 = np.where(left, f1, f_new), np.where(left, f_new, f2)
        x1, x2 = x1n, x2n
    return 0.5 * (a + b)


def require_finite(arr: np.ndarray, name: str) -> None:
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or infinite entries")


def points(x: ArrayLike, name: str, n: int | None = None) -> np.ndarray:
    """A finite array (..., n) of points (centres, measurements)."""
    arr = _float_array(x, name)
    if arr.ndim < 1:
        raise ValueError(f"{name} must be an array (..., n); got a scalar")
    if n is not None and arr.shape[-1] != n:
        raise ValueError(f"{name} must have last dimension {n}; got shape {arr.shape}")
    require_finite(arr, name)
    return arr


def shape_matrix(P: ArrayLike, name: str, definite: bool = True, size: int | None = None) -> np.ndarray:
    """A stack (..., n, n) of symmetric positive definite (or semidefinite) shape matrices."""
    arr = check_covariance(_float_array(P, name), name, size, definite=definite)
    if arr.shape[-1] == 0:
        raise ValueError(f"{name} must be at least 1 x 1; got shape {arr.shape}")
    return arr


def broadcast(**batches: tuple[int, ...]) -> tuple[int, ...]:
    """Common batch shape of the named arguments, or a ``ValueError`` naming them."""
    try:
        return np.broadcast_shapes(*batches.values())
    except ValueError:
        listed = ", ".join(f"{k} {v}" for k, v in batches.items())
        raise ValueError(f"the batch (leading) dimensions do not broadcast: {listed}") from None
