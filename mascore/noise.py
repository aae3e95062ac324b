"""Noise generators: Gaussian, uniform in a box, uniform in an ellipsoid.

Every function takes an explicit :class:`numpy.random.Generator` first; the
same generator state gives the same numbers, byte for byte.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_vector, check_covariance, check_generator

__all__ = ["gaussian", "uniform_box", "uniform_ellipsoid"]


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
    # eigh-based factor works for singular (semidefinite) covariances too
    w, V = np.linalg.eigh(cov)
    factor = V * np.sqrt(np.clip(w, 0.0, None))
    return mean + rng.standard_normal((*size, m)) @ factor.T


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
    w, V = np.linalg.eigh(P)
    factor = V * np.sqrt(np.clip(w, 0.0, None))
    return c + (radius * direction) @ factor.T
