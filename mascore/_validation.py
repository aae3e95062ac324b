"""Input checks shared by every module.

Each check raises early with a message that names the offending argument and
what was expected, so that bad input never travels on into NaNs.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "as_matrix",
    "as_vector",
    "check_covariance",
    "check_generator",
    "check_square",
]

#: Relative tolerance used for symmetry and positive-(semi)definiteness checks.
SYMMETRY_RTOL = 1e-8


def as_vector(x: ArrayLike, name: str, size: int | None = None) -> np.ndarray:
    """Return `x` as a 1-D float array, checking its length.

    Raises
    ------
    ValueError
        If `x` is not one-dimensional, has the wrong length or is not finite.
    """
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array; got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise ValueError(f"{name} must have length {size}; got {arr.shape[0]}")
    _check_finite(arr, name)
    return arr


def as_matrix(
    M: ArrayLike, name: str, shape: tuple[int | None, int | None] | None = None
) -> np.ndarray:
    """Return `M` as a 2-D float array, checking its shape.

    Parameters
    ----------
    M : array_like
        The candidate matrix.
    name : str
        Argument name used in error messages.
    shape : tuple of (int or None), optional
        Expected shape; ``None`` in a slot accepts any size there.
    """
    arr = np.asarray(M, dtype=float)
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array; got shape {arr.shape}")
    if shape is not None:
        for got, want in zip(arr.shape, shape):
            if want is not None and got != want:
                expected = tuple("any" if w is None else w for w in shape)
                raise ValueError(
                    f"Incompatible dimensions of {name}; expected {expected} "
                    f"but found {arr.shape}"
                )
    _check_finite(arr, name)
    return arr


def check_square(M: ArrayLike, name: str, size: int | None = None) -> np.ndarray:
    """Return `M` as a square float matrix (optionally of a given size)."""
    arr = as_matrix(M, name)
    if arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be square; got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise ValueError(
            f"Incompatible dimensions of {name}; expected ({size}, {size}) "
            f"but found {arr.shape}"
        )
    return arr


def check_covariance(
    P: ArrayLike, name: str, size: int | None = None, definite: bool = False
) -> np.ndarray:
    """Check that `P` is a symmetric positive semidefinite (or definite) matrix.

    Works on a single ``(n, n)`` matrix or a stack ``(..., n, n)``.

    Parameters
    ----------
    P : array_like, shape (..., n, n)
        Candidate covariance (or stack of covariances).
    name : str
        Argument name used in error messages.
    size : int, optional
        Required n.
    definite : bool
        Require positive definiteness instead of semidefiniteness.

    Returns
    -------
    numpy.ndarray
        `P` as a float array, unchanged.
    """
    arr = np.asarray(P, dtype=float)
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
        raise ValueError(f"{name} must be a square matrix (..., n, n); got shape {arr.shape}")
    if size is not None and arr.shape[-1] != size:
        raise ValueError(
            f"Incompatible dimensions of {name}; expected ({size}, {size}) "
            f"but found {arr.shape[-2:]}"
        )
    _check_finite(arr, name)
    scale = max(1.0, float(np.max(np.abs(arr)))) if arr.size else 1.0
    if not np.allclose(arr, np.swapaxes(arr, -1, -2), rtol=0, atol=SYMMETRY_RTOL * scale):
        raise ValueError(f"{name} must be symmetric")
    eig_min = float(np.min(np.linalg.eigvalsh(arr))) if arr.size else 0.0
    if definite and eig_min <= 0:
        raise ValueError(
            f"{name} must be positive definite; smallest eigenvalue is {eig_min:.3g}"
        )
    if eig_min < -SYMMETRY_RTOL * scale:
        raise ValueError(
            f"{name} must be positive semidefinite; smallest eigenvalue is {eig_min:.3g}"
        )
    return arr


def check_generator(rng: object, name: str = "rng") -> np.random.Generator:
    """Require an explicit :class:`numpy.random.Generator`.

    Randomness in mascore always comes from a generator the caller passes in;
    integer seeds are accepted and turned into ``np.random.default_rng(seed)``.
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return np.random.default_rng(int(rng))
    raise TypeError(
        f"{name} must be a numpy.random.Generator or an integer seed; got {type(rng).__name__}"
    )


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite entries")
