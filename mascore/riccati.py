"""Algebraic Riccati equations, solved and checked: the kernel of every LQR gain and LQR-dual observer.

:func:`care` and :func:`dare` check their arguments, solve the equation, and return the
optimal gain, the stabilizing solution and the closed-loop eigenvalues only after checking
the relative Riccati residual and the closed-loop stability (a
:class:`~mascore.exceptions.RiccatiError` otherwise). ``solve_care`` and ``solve_dare`` are
the same solvers without the argument checks, for the modules of this package that have
checked them already (the network designs solve one equation per Laplacian mode).
:func:`is_stabilizable` is the test a stabilizing solution needs; it looks
only at the modes that need stabilizing (``Re s >= 0``, or ``|z| >= 1`` in discrete time),
one rank test each, instead of one per eigenvalue.

:mod:`mascore.lqr` (controllers) and :mod:`mascore.observers` (their duals) both build on
this module and on neither of each other.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from ._validation import as_matrix, check_covariance, check_positive, check_square
from ._validation import float_array as _float_array
from .exceptions import RiccatiError

__all__ = ["RICCATI_RTOL", "care", "dare", "is_controllable", "is_stabilizable"]

#: Largest relative Riccati residual accepted from the solver.
RICCATI_RTOL = 1e-8


def is_controllable(A: ArrayLike, B: ArrayLike, tol: float = 1e-9) -> bool:
    """PBH test: ``rank [A - s I, B] = n`` at every eigenvalue ``s`` of `A`.

    Parameters
    ----------
    A : (n, n) array_like
        State matrix.
    B : (n, m) array_like
        Input matrix.
    tol : float
        Relative singular-value threshold for the rank; finite, > 0.

    Returns
    -------
    bool
        True if ``(A, B)`` is controllable.

    Examples
    --------
    >>> from mascore import riccati
    >>> riccati.is_controllable([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]])
    True
    >>> riccati.is_controllable([[1.0, 0.0], [0.0, 2.0]], [[1.0], [0.0]])
    False
    """
    A, B, tol = _pair(A, B, tol)
    return _pbh(A, B, np.linalg.eigvals(A), tol)


def is_stabilizable(A: ArrayLike, B: ArrayLike, discrete: bool = False, tol: float = 1e-9) -> bool:
    """PBH test on the modes that must be moved: ``Re s >= 0`` (or ``|z| >= 1`` if `discrete`).

    Parameters
    ----------
    A : (n, n) array_like
        State matrix.
    B : (n, m) array_like
        Input matrix.
    discrete : bool
        Discrete-time pair (unstable means ``|z| >= 1``) instead of continuous time.
    tol : float
        Relative singular-value threshold for the rank; finite, > 0.

    Returns
    -------
    bool
        True if every mode that is not asymptotically stable is controllable.

    Examples
    --------
    >>> from mascore import riccati
    >>> A = [[1.0, 0.0], [0.0, -2.0]]          # the second mode is stable on its own
    >>> riccati.is_stabilizable(A, [[1.0], [0.0]])
    True
    >>> riccati.is_stabilizable(A, [[0.0], [1.0]])
    False
    """
    A, B, tol = _pair(A, B, tol)
    if not isinstance(discrete, (bool, np.bool_)):
        raise TypeError(f"discrete must be True or False; got {discrete!r}")
    s = np.linalg.eigvals(A)
    unstable = s[np.abs(s) >= 1.0 - 1e-12] if discrete else s[s.real >= -1e-12]
    return _pbh(A, B, unstable, tol)


def care(A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous-time ARE ``A^T S + S A - S B R^{-1} B^T S + Q = 0``: gain, stabilizing solution, poles.

    Parameters
    ----------
    A : (n, n) array_like
        State matrix.
    B : (n, m) array_like
        Input matrix.
    Q : (n, n) array_like
        State weight, symmetric positive semidefinite.
    R : (m, m) array_like
        Input weight, symmetric positive definite.

    Returns
    -------
    K : (m, n) ndarray
        ``K = R^{-1} B^T S`` (``u = -K x``).
    S : (n, n) ndarray
        Stabilizing solution (symmetric).
    E : (n,) ndarray
        Eigenvalues of ``A - B K`` (all with negative real part).

    Raises
    ------
    ValueError
        Bad shapes or weights.
    RiccatiError
        No stabilizing solution, or a relative residual above :data:`RICCATI_RTOL`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import riccati
    >>> K, S, E = riccati.care([[0.0]], [[1.0]], [[1.0]], [[1.0]])   # x' = u: S = 1, K = 1
    >>> float(S[0, 0]), float(K[0, 0]), float(E[0].real)
    (1.0, 1.0, -1.0)
    """
    A, B, Q, R = _problem(A, B, Q, R)
    return solve_care(A, B, Q, R)


def dare(A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete-time ARE ``S = A^T S A - A^T S B (R + B^T S B)^{-1} B^T S A + Q``: gain, solution, poles.

    Parameters
    ----------
    A : (n, n) array_like
        State matrix of ``x_{k+1} = A x_k + B u_k``.
    B : (n, m) array_like
        Input matrix.
    Q : (n, n) array_like
        State weight, symmetric positive semidefinite.
    R : (m, m) array_like
        Input weight, symmetric positive definite.

    Returns
    -------
    K : (m, n) ndarray
        ``K = (R + B^T S B)^{-1} B^T S A`` (``u_k = -K x_k``).
    S : (n, n) ndarray
        Stabilizing solution (symmetric).
    E : (n,) ndarray
        Eigenvalues of ``A - B K`` (all inside the unit circle).

    Raises
    ------
    ValueError
        Bad shapes or weights.
    RiccatiError
        No stabilizing solution, or a relative residual above :data:`RICCATI_RTOL`.

    Examples
    --------
    >>> from mascore import riccati
    >>> K, S, E = riccati.dare([[1.0]], [[1.0]], [[1.0]], [[1.0]])   # S = (1 + sqrt 5) / 2
    >>> round(float(S[0, 0]), 6), round(float(K[0, 0]), 6)
    (1.618034, 0.618034)
    """
    A, B, Q, R = _problem(A, B, Q, R)
    return solve_dare(A, B, Q, R)


def solve_care(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`care` on arguments already checked by the caller (the kernel the network designs loop over).

    Parameters
    ----------
    A, B, Q, R : ndarray
        As in :func:`care`, already validated (float arrays of matching shapes, symmetric weights).

    Returns
    -------
    K, S, E : ndarray
        As in :func:`care`.

    Raises
    ------
    RiccatiError
        No stabilizing solution, or a relative residual above :data:`RICCATI_RTOL`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import riccati
    >>> K, S, E = riccati.solve_care(np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)), np.ones((1, 1)))
    >>> float(S[0, 0])
    1.0
    """
    try:
        S = sla.solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise RiccatiError(f"the Riccati equation has no stabilizing solution: {exc}") from exc
    S = (S + S.T) / 2
    K = np.linalg.solve(R, B.T @ S)
    residual = A.T @ S + S @ A - S @ B @ K + Q
    scale = max(1.0, np.linalg.norm(Q), np.linalg.norm(A.T @ S), np.linalg.norm(S @ B @ K))
    if np.linalg.norm(residual) > RICCATI_RTOL * scale:
        raise RiccatiError(
            f"Riccati residual {np.linalg.norm(residual) / scale:.2g} (relative) exceeds {RICCATI_RTOL:g}"
        )
    E = np.linalg.eigvals(A - B @ K)
    if np.max(E.real) >= 0:
        raise RiccatiError("the Riccati solution is not stabilizing (closed-loop eigenvalue in the right half-plane)")
    return K, S, E


def solve_dare(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`dare` on arguments already checked by the caller.

    Parameters
    ----------
    A, B, Q, R : ndarray
        As in :func:`dare`, already validated.

    Returns
    -------
    K, S, E : ndarray
        As in :func:`dare`.

    Raises
    ------
    RiccatiError
        No stabilizing solution, or a relative residual above :data:`RICCATI_RTOL`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import riccati
    >>> K, S, E = riccati.solve_dare(np.ones((1, 1)), np.ones((1, 1)), np.ones((1, 1)), np.ones((1, 1)))
    >>> round(float(S[0, 0]), 6)
    1.618034
    """
    try:
        S = sla.solve_discrete_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise RiccatiError(f"the discrete Riccati equation has no stabilizing solution: {exc}") from exc
    S = (S + S.T) / 2
    BtS = B.T @ S
    K = np.linalg.solve(R + BtS @ B, BtS @ A)
    residual = A.T @ S @ A - S - A.T @ S @ B @ K + Q
    scale = max(1.0, np.linalg.norm(Q), np.linalg.norm(S), np.linalg.norm(A.T @ S @ A))
    if np.linalg.norm(residual) > RICCATI_RTOL * scale:
        raise RiccatiError(
            f"Riccati residual {np.linalg.norm(residual) / scale:.2g} (relative) exceeds {RICCATI_RTOL:g}"
        )
    E = np.linalg.eigvals(A - B @ K)
    if np.max(np.abs(E)) >= 1:
        raise RiccatiError(
            "the Riccati solution is not stabilizing (closed-loop eigenvalue on or outside the unit circle)"
        )
    return K, S, E


def _pair(A, B, tol) -> tuple[np.ndarray, np.ndarray, float]:
    A = check_square(_float_array(A, "A"), "A")
    B = as_matrix(_float_array(B, "B"), "B", (A.shape[0], None))
    return A, B, check_positive(tol, "tol")


def _pbh(A: np.ndarray, B: np.ndarray, eigenvalues: np.ndarray, tol: float) -> bool:
    n = A.shape[0]
    scale = max(1.0, np.linalg.norm(A, 2), np.linalg.norm(B, 2))
    for s in eigenvalues:
        sv = np.linalg.svd(np.hstack([A - s * np.eye(n), B]), compute_uv=False)
        if sv[n - 1] <= tol * scale:
            return False
    return True


def _problem(A, B, Q, R):
    A = check_square(_float_array(A, "A"), "A")
    n = A.shape[0]
    B = as_matrix(_float_array(B, "B"), "B", (n, None))
    if B.shape[1] == 0:
        raise ValueError(f"B must have at least one column; got shape {B.shape}")
    Q = check_covariance(np.atleast_2d(_float_array(Q, "Q")), "Q", n)
    R = check_covariance(np.atleast_2d(_float_array(R, "R")), "R", B.shape[1], definite=True)
    return A, B, Q, R
