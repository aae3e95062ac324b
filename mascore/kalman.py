"""The Kalman filter step as pure functions, and filter-consistency statistics.

All functions accept a single filter or a batch: leading axes of ``x`` (``(...,
m)``) and ``P`` (``(..., m, m)``) are broadcast, so N agents' filters or many
Monte Carlo runs advance in one call. Nothing is modified in place.

The measurement update uses the Joseph form
``P+ = (I - K H) P (I - K H)^T + K R K^T``, which keeps ``P+`` symmetric
positive semidefinite for any gain and is the form Song et al. (2023) write in
their eq. (20).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from ._validation import check_covariance

__all__ = ["predict", "update", "kalman_gain", "nees", "nees_interval", "symmetrize"]


def predict(
    x: ArrayLike,
    P: ArrayLike,
    F: ArrayLike,
    Q: ArrayLike,
    B: ArrayLike | None = None,
    u: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Time update ``x- = F x + B u``, ``P- = F P F^T + Q``.

    Parameters
    ----------
    x : (..., m) array_like
        Prior mean(s).
    P : (..., m, m) array_like
        Prior covariance(s), symmetric positive semidefinite.
    F : (m, m) or (..., m, m) array_like
        State-transition matrix.
    Q : (m, m) or (..., m, m) array_like
        Process-noise covariance, symmetric positive semidefinite.
    B : (m, p) array_like, optional
        Input matrix; required with `u`.
    u : (..., p) array_like, optional
        Known input.

    Returns
    -------
    x_pred : (..., m) ndarray
    P_pred : (..., m, m) ndarray
    """
    x, P, F = _as_float(x, P, F)
    m = x.shape[-1]
    _check_pair(x, P)
    if F.shape[-2:] != (m, m):
        raise ValueError(f"Incompatible dimensions of F; expected (..., {m}, {m}) but found {F.shape}")
    Q = check_covariance(Q, "Q", size=m)
    x_pred = np.einsum("...ij,...j->...i", F, x)
    if u is not None or B is not None:
        if u is None or B is None:
            raise ValueError("B and u must be given together")
        B = np.asarray(B, dtype=float)
        u = np.asarray(u, dtype=float)
        if B.shape[-2] != m or B.shape[-1] != u.shape[-1]:
            raise ValueError(f"Incompatible dimensions of B {B.shape} and u {u.shape} for m={m}")
        x_pred = x_pred + np.einsum("...ij,...j->...i", B, u)
    P_pred = F @ P @ np.swapaxes(F, -1, -2) + Q
    return x_pred, symmetrize(P_pred)


def kalman_gain(P: ArrayLike, H: ArrayLike, R: ArrayLike) -> np.ndarray:
    """Optimal gain ``K = P H^T (H P H^T + R)^{-1}``, shape ``(..., m, q)``."""
    P, H, R = _as_float(P, H, R)
    S = H @ P @ np.swapaxes(H, -1, -2) + R
    # K^T = S^{-1} H P because S and P are symmetric
    return np.swapaxes(np.linalg.solve(S, H @ P), -1, -2)


def update(
    x: ArrayLike, P: ArrayLike, z: ArrayLike, H: ArrayLike, R: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Measurement update in Joseph form.

    Parameters
    ----------
    x : (..., m) array_like
        Predicted mean(s).
    P : (..., m, m) array_like
        Predicted covariance(s).
    z : (..., q) array_like
        Measurement(s).
    H : (q, m) or (..., q, m) array_like
        Measurement matrix.
    R : (q, q) or (..., q, q) array_like
        Measurement-noise covariance, symmetric positive definite.

    Returns
    -------
    x_post : (..., m) ndarray
    P_post : (..., m, m) ndarray
        Symmetric positive semidefinite by construction (Joseph form).
    """
    x, P, z, H = _as_float(x, P, z, H)
    m = x.shape[-1]
    _check_pair(x, P)
    q = z.shape[-1]
    if H.shape[-2:] != (q, m):
        raise ValueError(f"Incompatible dimensions of H; expected (..., {q}, {m}) but found {H.shape}")
    R = check_covariance(R, "R", size=q, definite=True)
    K = kalman_gain(P, H, R)
    innovation = z - np.einsum("...ij,...j->...i", H, x)
    x_post = x + np.einsum("...ij,...j->...i", K, innovation)
    I_KH = np.eye(m) - K @ H
    P_post = I_KH @ P @ np.swapaxes(I_KH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return x_post, symmetrize(P_post)


def nees(error: ArrayLike, P: ArrayLike) -> np.ndarray:
    """Normalized estimation error squared ``e^T P^{-1} e``.

    Parameters
    ----------
    error : (..., m) array_like
        Estimation error(s) ``x_true - x_hat``.
    P : (..., m, m) array_like
        The filter's covariance(s), positive definite.

    Returns
    -------
    (...) ndarray
        Chi-square distributed with m degrees of freedom for a consistent
        Gaussian filter.
    """
    e, P = _as_float(error, P)
    _check_pair(e, P)
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def nees_interval(dof: int, n_runs: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided interval for the NEES averaged over `n_runs` independent runs.

    ``n_runs * mean(NEES)`` is chi-square with ``n_runs * dof`` degrees of
    freedom (Bar-Shalom, Li and Kirubarajan 2001, Sec. 5.4).

    Returns
    -------
    (low, high) : tuple of float
        Bounds on the *average* NEES.
    """
    if dof < 1 or n_runs < 1:
        raise ValueError(f"dof and n_runs must be positive; got dof={dof}, n_runs={n_runs}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must lie in (0, 1); got {confidence}")
    tail = (1 - confidence) / 2
    total = dof * n_runs
    return (
        float(stats.chi2.ppf(tail, total) / n_runs),
        float(stats.chi2.ppf(1 - tail, total) / n_runs),
    )


def symmetrize(P: np.ndarray) -> np.ndarray:
    """``(P + P^T) / 2`` over the last two axes."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def _as_float(*arrays: ArrayLike) -> list[np.ndarray]:
    return [np.asarray(a, dtype=float) for a in arrays]


def _check_pair(x: np.ndarray, P: np.ndarray) -> None:
    m = x.shape[-1] if x.ndim else 0
    if x.ndim < 1 or P.shape[-2:] != (m, m):
        raise ValueError(
            f"Incompatible dimensions of x {x.shape} and P {P.shape}; P must be (..., m, m) for x (..., m)"
        )
