"""Noise generators: Gaussian, uniform in a box, uniform in an ellipsoid.

Every function takes an explicit :class:`numpy.random.Generator` first; the
same generator state gives the same numbers, byte for byte.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ._fusion_kernels import psd_factor as _factor
from ._validation import as_vector, check_covariance, check_fits_in_memory, check_generator, sample_shape
from ._validation import float_array as _float_array

__all__ = ["gaussian", "psd_factor", "uniform_box", "uniform_ellipsoid"]


def _check_psd(M: object, name: str) -> np.ndarray:
    """A symmetric positive semidefinite (m, m) matrix with m >= 1."""
    P = check_covariance(_float_array(M, name), name)
    if P.ndim != 2 or P.shape[0] == 0:
        raise ValueError(f"{name} must be a single (m, m) matrix with m >= 1; got shape {P.shape}")
    return P


def psd_factor(M: ArrayLike, cholesky_first: bool = False) -> np.ndarray:
    """A factor ``F`` with ``F F^T = M`` for a symmetric positive semidefinite ``M``.

    Parameters
    ----------
    M : (..., m, m) array_like
        Symmetric positive semidefinite matrices (checked).
    cholesky_first : bool
        Return the lower Cholesky factor when ``M`` is positive definite and fall
        back to the eigenvector factor only when it is singular. By default the
        eigenvector factor ``V diag(sqrt(w))`` is always used.

    Returns
    -------
    (..., m, m) ndarray
        ``F`` maps standard normal draws to draws of covariance ``M``
        (``x = F z``), also for singular ``M``.

    Raises
    ------
    ValueError
        ``M`` not square, not symmetric or not positive semidefinite.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import noise
    >>> M = np.array([[4.0, 2.0], [2.0, 1.0]])            # singular: rank one
    >>> F = noise.psd_factor(M)
    >>> bool(np.allclose(F @ F.T, M))
    True
    """
    return _factor(check_covariance(_float_array(M, "M"), "M"), cholesky_first)


def _draw_shape(size: object, m: int) -> tuple[int, ...]:
    """`size` checked (:func:`~mascore._validation.sample_shape`), and its ``(*size, m)`` draws fit in memory."""
    size = sample_shape(size)
    check_fits_in_memory(8.0 * math.prod(size) * m, "size", f"{math.prod(size)} draws of {m} numbers")
    return size


def gaussian(
    rng: np.random.Generator, cov: ArrayLike, size: int | tuple[int, ...] = (), mean: ArrayLike | None = None
) -> np.ndarray:
    """Samples of ``N(mean, cov)``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness (a seed is refused: pass ``np.random.default_rng(seed)``).
    cov : (m, m) array_like
        Symmetric positive semidefinite covariance.
    size : int or tuple of int
        Leading shape of the output.
    mean : (m,) array_like, optional
        Defaults to zero.

    Returns
    -------
    (size..., m) ndarray
        Independent draws.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import noise
    >>> x = noise.gaussian(np.random.default_rng(0), np.diag([1.0, 4.0]), size=20000)
    >>> np.round(np.var(x, axis=0), 1)
    array([1., 4.])
    """
    rng = check_generator(rng)
    cov = _check_psd(cov, "cov")
    m = cov.shape[0]
    mean = np.zeros(m) if mean is None else as_vector(_float_array(mean, "mean"), "mean")
    if mean.size != m:
        raise ValueError(f"Incompatible dimensions of mean and cov: mean has length {mean.size}, cov is {cov.shape}")
    size = _draw_shape(size, m)
    return mean + rng.standard_normal((*size, m)) @ _factor(cov).T


def uniform_box(
    rng: np.random.Generator, low: ArrayLike, high: ArrayLike, size: int | tuple[int, ...] = ()
) -> np.ndarray:
    """Samples uniform in the box ``low <= x <= high`` (componentwise).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness.
    low : (m,) array_like
        Lower corner.
    high : (m,) array_like
        Upper corner, ``high >= low`` componentwise.
    size : int or tuple of int
        Leading shape of the output.

    Returns
    -------
    (size..., m) ndarray
        Independent draws.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import noise
    >>> x = noise.uniform_box(np.random.default_rng(0), [-0.05, -0.05], [0.05, 0.05], size=1000)
    >>> x.shape, bool(np.abs(x).max() <= 0.05)
    ((1000, 2), True)
    """
    rng = check_generator(rng)
    low = as_vector(np.atleast_1d(_float_array(low, "low")), "low")
    high = as_vector(np.atleast_1d(_float_array(high, "high")), "high")
    if low.size != high.size:
        raise ValueError(f"low and high must have the same length; got {low.size} and {high.size}")
    if np.any(high < low):
        raise ValueError(f"high must be >= low in every component; got low={low}, high={high}")
    size = _draw_shape(size, low.size)
    return low + (high - low) * rng.random((*size, low.size))


def uniform_ellipsoid(
    rng: np.random.Generator, center: ArrayLike, shape: ArrayLike, size: int | tuple[int, ...] = ()
) -> np.ndarray:
    """Samples uniform in ``E(c, P) = {x : (x - c)^T P^{-1} (x - c) <= 1}``.

    The bounded noise the set-membership filter assumes (Bhattacharjee and Subbarao 2021).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness.
    center : (m,) array_like
        Centre ``c``.
    shape : (m, m) array_like
        Shape matrix P, symmetric positive semidefinite.
    size : int or tuple of int
        Leading shape of the output.

    Returns
    -------
    (size..., m) ndarray
        Independent draws, all inside the ellipsoid.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids, noise
    >>> P = np.diag([4.0, 1.0])
    >>> x = noise.uniform_ellipsoid(np.random.default_rng(0), [1.0, 0.0], P, size=500)
    >>> bool(ellipsoids.contains(x, [1.0, 0.0], P).all())
    True
    """
    rng = check_generator(rng)
    P = _check_psd(shape, "shape")
    m = P.shape[0]
    c = as_vector(_float_array(center, "center"), "center")
    if c.size != m:
        raise ValueError(f"Incompatible dimensions of center and shape: center has length {c.size}, shape is {P.shape}")
    size = _draw_shape(size, m)
    direction = rng.standard_normal((*size, m))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    radius = rng.random((*size, 1)) ** (1.0 / m)
    return c + (radius * direction) @ _factor(P).T
