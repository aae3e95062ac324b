"""Noise generators: Gaussian, uniform in a box, uniform in an ellipsoid.

Every function takes an explicit :class:`numpy.random.Generator` first; the
same generator state gives the same numbers, byte for byte.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_vector, check_covariance, check_generator

__all__ = ["gaussian", "psd_factor", "uniform_box", "uniform_ellipsoid"]


def psd_factor(M: ArrayLike, cholesky_first: bool = False) -> np.ndarray:
    """A factor ``F`` with ``F F^T = M`` for a symmetric positive semidefinite ``M``.

    Parameters
    ----------
    M : (..., m, m) array_like
        Symmetric positive semidefinite matrices (not checked: callers validate).
    cholesky_first : bool
        Return the lower Cholesky factor when ``M`` is positive definite and fall
        back to the eigenvector factor only when it is singular. By default the
        eigenvector factor ``V diag(sqrt(w))`` is always used.

    Returns
    -------
    (..., m, m) ndarray
        ``F`` maps standard normal draws to draws of covariance ``M``
        (``x = F z``), also for singular ``M``.
    """
    M = np.asarray(M, dtype=float)
    if cholesky_first:
        try:
            return np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            pass
    w, V = np.linalg.eigh(M)
    return V * np.sqrt(np.clip(w, 0.0, None))[..., None, :]


def gaussian(
    rng: np.random.Generator, cov: ArrayLike, size: int | tuple[int, ...] = (), mean: ArrayLike | None = None
) -> np.ndarray:
    """Samples of ``N(mean, cov)``.

    Parameters
    ----------
    rng : numpy.random.Generator
    cov : (m, m) array_like
        Symmetric positive semidefinite covariance.
    size : int or tuple of int
        Leading shape of the output.
    mean : (m,) array_like, optional
        Defaults to zero.

    Returns
    -------
    (*size, m) ndarray
    """
    rng = check_generator(rng)
    cov = check_covariance(cov, "cov")
    m = cov.shape[0]
    mean = np.zeros(m) if mean is None else as_vector(mean, "mean", m)
    size = (size,) if isinstance(size, (int, np.integer)) else tuple(size)
    return mean + rng.standard_normal((*size, m)) @ psd_factor(cov).T


def uniform_box(
    rng: np.random.Generator, low: ArrayLike, high: ArrayLike, size: int | tuple[int, ...] = ()
) -> np.ndarray:
    """Samples uniform in the box ``low <= x <= high`` (componentwise).

    Returns
    -------
    (*size, m) ndarray
    """
    rng = check_generator(rng)
    low = as_vector(np.atleast_1d(low), "low")
    high = as_vector(np.atleast_1d(high), "high", low.size)
    if np.any(high < low):
        raise ValueError("high must be >= low in every component")
    size = (size,) if isinstance(size, (int, np.integer)) else tuple(size)
    return low + (high - low) * rng.random((*size, low.size))


def uniform_ellipsoid(
    rng: np.random.Generator, center: ArrayLike, shape: ArrayLike, size: int | tuple[int, ...] = ()
) -> np.ndarray:
    """Samples uniform in ``E(c, P) = {x : (x - c)^T P^{-1} (x - c) <= 1}``.

    Parameters
    ----------
    center : (m,) array_like
    shape : (m, m) array_like
        Shape matrix P, symmetric positive semidefinite.

    Returns
    -------
    (*size, m) ndarray
    """
    rng = check_generator(rng)
    P = check_covariance(shape, "shape")
    m = P.shape[0]
    c = as_vector(center, "center", m)
    size = (size,) if isinstance(size, (int, np.integer)) else tuple(size)
    direction = rng.standard_normal((*size, m))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    radius = rng.random((*size, 1)) ** (1.0 / m)
    return c + (radius * direction) @ psd_factor(P).T
