"""Ellipsoids: a small toolkit for set-membership estimation.

Convention (as in Bhattacharjee and Subbarao 2021 and merlresearch/pycvxset)::

    E(c, P) = {x : (x - c)^T P^{-1} (x - c) <= 1}

with centre ``c`` (n,) and shape matrix ``P`` (n, n), symmetric positive
definite. ``trace(P)`` is the sum of the squared semi-axes (the "trace
criterion"); ``volume = vol(unit ball) * sqrt(det P)``.

Most functions work on plain arrays and broadcast over leading (batch)
dimensions, so that many ellipsoids (agents x Monte Carlo runs) are handled in
one call; :class:`Ellipsoid` is a small validated convenience wrapper.

Two operations are exact only as outer approximations, chosen from a
one-parameter family by the trace criterion:

* Minkowski sum ``E(c1, P1) + E(c2, P2)`` is contained in
  ``E(c1 + c2, P1 / (1 - b) + P2 / b)`` for every ``b`` in (0, 1);
  the trace is minimised in closed form by ``b = sqrt(t2) / (sqrt(t1) + sqrt(t2))``
  with ``t_i = trace(P_i)`` (:func:`minkowski_sum_min_trace`).
* Intersection of ``E(c, P)`` with the measurement set
  ``{x : (y - C x)^T W^{-1} (y - C x) <= 1}`` (``W = D R D^T``, a "strip" when
  ``C`` has one row) is contained in every member of the family
  ``{x : (1 - t) |x - c|^2_{P^{-1}} + t |y - C x|^2_{W^{-1}} <= 1}``, ``t`` in [0, 1]
  (Schweppe 1968; :func:`intersection_family`).

Input checks: every public function checks its arguments and names the one at
fault (finite entries; matching and broadcastable shapes; shape matrices
symmetric positive definite, or semidefinite where a flat ellipsoid makes sense;
family parameters strictly inside (0, 1); counts and tolerances). The
set-membership filter calls the unchecked kernels of ``mascore._ellipsoid_kernels`` (the same
minimum-trace intersection, innovation form and sum) after checking its own arguments once.
A result that overflows (NaN or inf from finite input, e.g. entries near 1e308)
raises a ``ValueError`` instead of being returned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from . import _ellipsoid_kernels as kernels
from ._validation import (
    Frozen,
    as_matrix,
    as_vector,
    check_covariance,
    check_generator,
    check_positive,
    check_positive_int,
    finite_result,
    frozen_copy,
)
from ._validation import float_array as _float_array
from .noise import psd_factor, uniform_ellipsoid

__all__ = [
    "Ellipsoid",
    "affine_image",
    "contains",
    "intersection_family",
    "intersection_gain_form",
    "intersection_is_empty",
    "intersection_min_trace",
    "mahalanobis_sq",
    "max_innovation_form",
    "minkowski_sum",
    "minkowski_sum_min_trace",
    "sample_boundary",
    "sample_interior",
    "trace",
    "volume",
]


@dataclass(frozen=True, eq=False)
class Ellipsoid(Frozen):
    """The ellipsoid ``E(c, P) = {x : (x - c)^T P^{-1} (x - c) <= 1}``.

    Parameters
    ----------
    center : (n,) array_like
        Centre ``c``.
    shape : (n, n) array_like
        Shape matrix ``P``, symmetric positive definite.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> E = ell.Ellipsoid([0.0, 0.0], np.diag([4.0, 1.0]))    # semi-axes 2 and 1
    >>> E.dim, E.trace, round(E.volume, 4)                    # area = pi * 2 * 1
    (2, 5.0, 6.2832)
    """

    center: np.ndarray
    shape: np.ndarray

    def __post_init__(self) -> None:
        P = check_covariance(_float_array(self.shape, "shape"), "shape", definite=True)
        if P.ndim != 2:
            raise ValueError(f"shape must be a single (n, n) matrix; got shape {P.shape}")
        c = as_vector(_float_array(self.center, "center"), "center", P.shape[0])
        self._set(shape=frozen_copy(0.5 * (P + P.T)), center=frozen_copy(c))

    @property
    def dim(self) -> int:
        """Dimension n of the space.

        Returns
        -------
        int
            Length of the centre.
        """
        return self.center.shape[0]

    @property
    def trace(self) -> float:
        """``trace(P)``: the sum of the squared semi-axis lengths.

        Returns
        -------
        float
            The trace, the size measure the set-membership filter minimises.
        """
        return float(np.trace(self.shape))

    @property
    def volume(self) -> float:
        """Lebesgue volume ``vol(unit ball) * sqrt(det P)``.

        Returns
        -------
        float
            The volume (area in the plane).
        """
        return float(volume(self.shape))

    def contains(self, points: ArrayLike, rtol: float = 1e-9) -> np.ndarray:
        """Boolean membership of points; see :func:`contains`.

        Parameters
        ----------
        points : (..., n) array_like
            Points to test.
        rtol : float
            Relative tolerance on the quadratic form (finite, >= 0).

        Returns
        -------
        (...,) bool ndarray
            True where the point lies in the ellipsoid.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import ellipsoids as ell
        >>> ell.Ellipsoid(np.zeros(2), np.diag([4.0, 1.0])).contains([[1.9, 0.0], [0.0, 1.1]])
        array([ True, False])
        """
        return contains(points, self.center, self.shape, rtol)

    def affine_image(self, M: ArrayLike, b: ArrayLike | None = None) -> Ellipsoid:
        """The image ``{M x + b : x in E}`` (M must have full row rank to stay non-degenerate).

        Parameters
        ----------
        M : (m, n) array_like
            Linear map.
        b : (m,) array_like, optional
            Offset.

        Returns
        -------
        Ellipsoid
            ``E(M c + b, M P M^T)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import ellipsoids as ell
        >>> E = ell.Ellipsoid(np.zeros(2), np.eye(2)).affine_image(2.0 * np.eye(2), b=[1.0, 0.0])
        >>> E.center, E.trace
        (array([1., 0.]), 8.0)
        """
        c, P = affine_image(self.center, self.shape, M, b)
        return Ellipsoid(c, P)

    def __add__(self, other: Ellipsoid) -> Ellipsoid:
        """Trace-optimal outer ellipsoid of the Minkowski sum."""
        if not isinstance(other, Ellipsoid):
            return NotImplemented
        c, P, _ = minkowski_sum_min_trace(self.center, self.shape, other.center, other.shape)
        return Ellipsoid(c, P)

    def sample_boundary(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """Points on the boundary (directions uniform on the unit sphere).

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of randomness.
        size : int
            Number of points.

        Returns
        -------
        (size, n) ndarray
            Points with ``(x - c)^T P^{-1} (x - c) = 1``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import ellipsoids as ell
        >>> E = ell.Ellipsoid(np.zeros(2), np.diag([4.0, 1.0]))
        >>> x = E.sample_boundary(np.random.default_rng(0), 5)
        >>> np.round(ell.mahalanobis_sq(x, E.center, E.shape), 12)
        array([1., 1., 1., 1., 1.])
        """
        return sample_boundary(rng, self.center, self.shape, size)

    def sample_interior(self, rng: np.random.Generator, size: int) -> np.ndarray:
        """Points uniform in the ellipsoid.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of randomness.
        size : int
            Number of points.

        Returns
        -------
        (size, n) ndarray
            Points inside the ellipsoid.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import ellipsoids as ell
        >>> E = ell.Ellipsoid(np.zeros(2), np.diag([4.0, 1.0]))
        >>> bool(E.contains(E.sample_interior(np.random.default_rng(0), 100)).all())
        True
        """
        return sample_interior(rng, self.center, self.shape, size)


def trace(shape: ArrayLike) -> np.ndarray:
    """``trace(P)`` of one or a stack of shape matrices.

    Parameters
    ----------
    shape : (..., n, n) array_like
        Shape matrices (finite, square).

    Returns
    -------
    (...,) ndarray
        Their traces.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> ell.trace(np.stack([np.eye(2), 2.0 * np.eye(2)]))
    array([2., 4.])
    """
    P = _float_array(shape, "shape")
    if P.ndim < 2 or P.shape[-1] != P.shape[-2]:
        raise ValueError(f"shape must be a square matrix or a stack (..., n, n); got shape {P.shape}")
    kernels.require_finite(P, "shape")
    return finite_result("trace", np.trace(P, axis1=-2, axis2=-1))


def volume(shape: ArrayLike) -> np.ndarray:
    """Volume ``pi^(n/2) / Gamma(n/2 + 1) * sqrt(det P)`` of E(c, P).

    Parameters
    ----------
    shape : (..., n, n) array_like
        Shape matrices, symmetric positive semidefinite (a singular P, a flat ellipsoid,
        has volume 0).

    Returns
    -------
    (...,) ndarray
        Volumes.

    Raises
    ------
    ValueError
        A shape that is not symmetric positive semidefinite.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> round(float(ell.volume(np.diag([4.0, 1.0]))), 4)               # pi * 2 * 1
    6.2832
    """
    P = _float_array(shape, "shape")
    if P.ndim < 2 or P.shape[-1] != P.shape[-2]:
        raise ValueError(f"shape must be (..., n, n); got {P.shape}")
    kernels.require_finite(P, "shape")
    scale = np.maximum(np.abs(P).max(axis=(-1, -2), initial=0.0), 1e-300)
    sym = np.abs(P - np.swapaxes(P, -1, -2)).max(axis=(-1, -2), initial=0.0) <= 1e-10 * scale
    eig = np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2)))
    if not (np.all(sym) and np.all(eig[..., 0] >= -1e-12 * scale)):
        raise ValueError("shape must be symmetric positive semidefinite to have a volume")
    n = P.shape[-1]
    unit = math.pi ** (n / 2) / math.gamma(n / 2 + 1)
    return finite_result("volume", unit * np.sqrt(np.prod(np.clip(eig, 0.0, None), axis=-1)))


def contains(points: ArrayLike, center: ArrayLike, shape: ArrayLike, rtol: float = 1e-9) -> np.ndarray:
    """Whether points lie in ``E(c, P)`` (within ``1 + rtol``).

    Parameters
    ----------
    points : (..., n) array_like
        Points to test.
    center : (..., n) array_like
        Centre, broadcast against `points`.
    shape : (..., n, n) array_like
        Shape, symmetric positive definite (a negative definite or singular `shape` is
        refused: it describes no ellipsoid of this convention).
    rtol : float
        Accept ``(x - c)^T P^{-1} (x - c) <= 1 + rtol`` (round-off and solver tolerance); finite, >= 0.

    Returns
    -------
    (...,) bool ndarray
        True where the point lies in the ellipsoid.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> ell.contains([[0.5, 0.5], [1.0, 1.0]], [0.0, 0.0], np.eye(2))
    array([ True, False])
    """
    rtol = check_positive(rtol, "rtol", allow_zero=True)
    return mahalanobis_sq(points, center, shape) <= 1.0 + rtol


def mahalanobis_sq(points: ArrayLike, center: ArrayLike, shape: ArrayLike) -> np.ndarray:
    """``(x - c)^T P^{-1} (x - c)`` broadcast over leading dimensions.

    Parameters
    ----------
    points : (..., n) array_like
        Points ``x``, finite.
    center : (..., n) array_like
        Centre ``c``, finite.
    shape : (..., n, n) array_like
        ``P``, symmetric positive definite.

    Returns
    -------
    (...,) ndarray
        The quadratic form; at most 1 inside the ellipsoid.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> float(ell.mahalanobis_sq([2.0, 0.0], [0.0, 0.0], np.diag([4.0, 1.0])))
    1.0
    """
    P = kernels.shape_matrix(shape, "shape")
    n = P.shape[-1]
    x = kernels.points(points, "points", n)
    c = kernels.points(center, "center", n)
    kernels.broadcast(points=x.shape[:-1], center=c.shape[:-1], shape=P.shape[:-2])
    d = x - c
    P, d = np.broadcast_arrays(P, d[..., None])
    sol = np.linalg.solve(P, d[..., :1])[..., 0]
    return finite_result("Mahalanobis form", np.einsum("...i,...i->...", d[..., 0], sol))


def affine_image(
    center: ArrayLike, shape: ArrayLike, M: ArrayLike, b: ArrayLike | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Image ``{M x + b : x in E(c, P)} = E(M c + b, M P M^T)``.

    Parameters
    ----------
    center : (..., n) array_like
        Centre ``c``.
    shape : (..., n, n) array_like
        Shape ``P``, symmetric positive semidefinite.
    M : (m, n) array_like
        Linear map.
    b : (m,) array_like, optional
        Offset.

    Returns
    -------
    center : (..., m) ndarray
        ``M c + b``.
    shape : (..., m, m) ndarray
        ``M P M^T``: symmetric; only positive semidefinite if M lacks full row rank.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> c, P = ell.affine_image([1.0, 0.0], np.eye(2), [[1.0, 1.0]])       # project onto x_1 + x_2
    >>> c, P
    (array([1.]), array([[2.]]))
    """
    P = kernels.shape_matrix(shape, "shape", definite=False)
    n = P.shape[-1]
    c = kernels.points(center, "center", n)
    kernels.broadcast(center=c.shape[:-1], shape=P.shape[:-2])
    M = as_matrix(_float_array(M, "M"), "M")
    if M.shape[1] != n:
        raise ValueError(f"M has {M.shape[1]} columns but the ellipsoid lives in R^{n}")
    new_c = c @ M.T
    if b is not None:
        b = _float_array(b, "b")
        if b.shape != (M.shape[0],):
            raise ValueError(f"b must have shape ({M.shape[0]},) (one entry per row of M); got {b.shape}")
        new_c = new_c + as_vector(b, "b", M.shape[0])
    new_P = M @ P @ M.T
    return (finite_result("affine image (center)", new_c),
            finite_result("affine image (shape)", 0.5 * (new_P + np.swapaxes(new_P, -1, -2))))


def minkowski_sum(
    center1: ArrayLike, shape1: ArrayLike, center2: ArrayLike, shape2: ArrayLike, beta: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Member of the outer family of ``E(c1, P1) + E(c2, P2)`` for parameter beta in (0, 1).

    ``E(c1 + c2, P1 / (1 - beta) + P2 / beta)`` contains the sum for every beta
    (Schweppe 1968); beta broadcasts over the batch dimensions.

    Parameters
    ----------
    center1 : (..., n) array_like
        Centre of the first ellipsoid.
    shape1 : (..., n, n) array_like
        Its shape, symmetric positive semidefinite.
    center2 : (..., n) array_like
        Centre of the second ellipsoid.
    shape2 : (..., n, n) array_like
        Its shape, symmetric positive semidefinite.
    beta : (...,) array_like
        Family parameter in (0, 1).

    Returns
    -------
    center : (..., n) ndarray
        ``c1 + c2``.
    shape : (..., n, n) ndarray
        ``P1 / (1 - beta) + P2 / beta``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> c, P = ell.minkowski_sum([1.0, 0.0], np.eye(2), [0.0, 1.0], np.eye(2), 0.5)
    >>> c, np.diag(P)
    (array([1., 1.]), array([4., 4.]))
    """
    P1 = kernels.shape_matrix(shape1, "shape1", definite=False)
    n = P1.shape[-1]
    P2 = kernels.shape_matrix(shape2, "shape2", definite=False, size=n)
    c1 = kernels.points(center1, "center1", n)
    c2 = kernels.points(center2, "center2", n)
    beta = _open_unit(beta, "beta")
    kernels.broadcast(center1=c1.shape[:-1], shape1=P1.shape[:-2], center2=c2.shape[:-1], shape2=P2.shape[:-2],
               beta=beta.shape)
    beta = beta[..., None, None]
    c = c1 + c2
    P = P1 / (1 - beta) + P2 / beta
    return finite_result("Minkowski sum (center)", c), finite_result("Minkowski sum (shape)", P)


def minkowski_sum_min_trace(
    center1: ArrayLike, shape1: ArrayLike, center2: ArrayLike, shape2: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trace-optimal member of the outer family of a Minkowski sum.

    ``trace(P1 / (1 - b) + P2 / b) = t1 / (1 - b) + t2 / b`` is minimised at
    ``b* = sqrt(t2) / (sqrt(t1) + sqrt(t2))`` with value ``(sqrt(t1) + sqrt(t2))^2``.
    This equals the optimum of the prediction SDP, eq. (8) of Bhattacharjee
    and Subbarao (2021), with ``P1 = A P A^T``, ``P2 = G Q G^T``.

    Parameters
    ----------
    center1 : (..., n) array_like
        Centre of the first ellipsoid.
    shape1 : (..., n, n) array_like
        Its shape, positive semidefinite (may be singular).
    center2 : (..., n) array_like
        Centre of the second ellipsoid.
    shape2 : (..., n, n) array_like
        Its shape, positive semidefinite (may be singular; not both zero).

    Returns
    -------
    center : (..., n) ndarray
        ``c1 + c2``.
    shape : (..., n, n) ndarray
        The optimal outer shape.
    beta : (...,) ndarray
        The optimal parameter (0 when ``trace(P2) = 0``, 1 when ``trace(P1) = 0``).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> c, P, beta = ell.minkowski_sum_min_trace(np.zeros(2), 4.0 * np.eye(2), np.zeros(2), np.eye(2))
    >>> float(np.trace(P)), float(beta)                    # (sqrt 8 + sqrt 2)^2 = 18, beta = 1/3
    (18.0, 0.333...)
    """
    P1 = kernels.shape_matrix(shape1, "shape1", definite=False)
    n = P1.shape[-1]
    P2 = kernels.shape_matrix(shape2, "shape2", definite=False, size=n)
    c1 = kernels.points(center1, "center1", n)
    c2 = kernels.points(center2, "center2", n)
    kernels.broadcast(center1=c1.shape[:-1], shape1=P1.shape[:-2], center2=c2.shape[:-1], shape2=P2.shape[:-2])
    P, beta = kernels.sum_min_trace(P1, P2, kernels.sqrt_trace(P1), kernels.sqrt_trace(P2))
    c = c1 + c2
    return (finite_result("Minkowski sum (center)", c), finite_result("Minkowski sum (shape)", P),
            beta)


def intersection_gain_form(
    center: ArrayLike, shape: ArrayLike, C: ArrayLike, y: ArrayLike, W: ArrayLike, t: ArrayLike,
    shrink: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Member t of the ellipsoid/measurement-set intersection family, in gain form.

    The set ``{x : (1 - t) |x - c|^2_{P^{-1}} + t |y - C x|^2_{W^{-1}} <= 1}`` is
    ``E(c + L (y - C c), delta * P_t)`` with the Kalman-like formulas::

        S = C P C^T / (1 - t) + W / t,   L = P C^T S^{-1} / (1 - t),
        P_t = (P - L C P) / (1 - t)  =  (I - L C) P (I - L C)^T / (1 - t) + L W L^T / t,
        delta = 1 - nu^T S^{-1} nu,   nu = y - C c.

    (the second, Joseph-like form is the one evaluated: it is the matrix of the
    SDP's LMI and stays accurate as t -> 1.)

    With ``shrink=False`` the factor delta is dropped (``delta = 1``): the
    result is then the gain-based outer bound used by the correction SDP, eqs. (6)-(7),
    which does not use y in the shape. With ``shrink=True`` it is Schweppe's tighter set.

    Parameters
    ----------
    center : (..., n) array_like
        Centre ``c`` of the prior ellipsoid.
    shape : (..., n, n) array_like
        Its shape matrix ``P``, symmetric positive definite.
    C : (p, n) array_like
        Measurement matrix.
    y : (..., p) array_like
        Measurement.
    W : (p, p) array_like
        Shape of the measurement-noise set, symmetric positive definite (``D R D^T``).
    t : (...,) array_like
        Strictly inside (0, 1): ``t = 0`` and ``t = 1`` are only limits of the family
        (``W / t`` and ``P / (1 - t)`` are undefined there) and are refused.
    shrink : bool
        Multiply the shape by delta (Schweppe's set) or not (the SDP's bound).

    Returns
    -------
    center : (..., n) ndarray
        ``c + L (y - C c)``.
    shape : (..., n, n) ndarray
        ``P_t`` (times delta with `shrink`).
    gain : (..., n, p) ndarray
        ``L``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> c, P, L = ell.intersection_gain_form(np.zeros(2), np.eye(2), [[1.0, 0.0]], [0.0], [[1.0]], 0.5)
    >>> L.ravel()
    array([0.5, 0. ])
    """
    c, P, C, y, W = _intersection_args(center, shape, C, y, W)
    t = _open_unit(t, "t")
    kernels.broadcast(center=c.shape[:-1], shape=P.shape[:-2], y=y.shape[:-1], W=W.shape[:-2], t=t.shape)
    new_c, Pt, L = kernels.gain_form(c, P, C, y, W, t, shrink)
    return (finite_result("intersection (center)", new_c), finite_result("intersection (shape)", Pt),
            finite_result("intersection (gain)", L))


def intersection_family(
    center: ArrayLike, shape: ArrayLike, C: ArrayLike, y: ArrayLike, W: ArrayLike, t: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Schweppe's outer ellipsoid of ``E(c, P) ∩ {x : |y - C x|_{W^{-1}} <= 1}`` for t in (0, 1).

    The shape includes the shrink factor delta and is not positive definite when
    delta <= 0 (then the intersection is empty, or a single point when delta = 0).

    Parameters
    ----------
    center : (..., n) array_like
        Centre ``c`` of the prior ellipsoid.
    shape : (..., n, n) array_like
        Its shape matrix ``P``, symmetric positive definite.
    C : (p, n) array_like
        Measurement matrix.
    y : (..., p) array_like
        Measurement.
    W : (p, p) array_like
        Shape of the measurement-noise set, symmetric positive definite (``D R D^T``).
    t : (...,) array_like
        Family parameter, strictly inside (0, 1).

    Returns
    -------
    center : (..., n) ndarray
        Centre of the outer ellipsoid.
    shape : (..., n, n) ndarray
        Its shape, ``delta * P_t``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> c, P = ell.intersection_family(np.zeros(2), np.eye(2), [[1.0, 0.0]], [0.5], [[0.25]], 0.5)
    >>> bool(ell.contains([0.4, 0.0], c, P))               # a point in both sets is in the outer ellipsoid
    True
    """
    c, P, _ = intersection_gain_form(center, shape, C, y, W, t, shrink=True)
    return c, P


def intersection_min_trace(
    center: ArrayLike, shape: ArrayLike, C: ArrayLike, y: ArrayLike, W: ArrayLike,
    shrink: bool = False, tol: float = 1e-13, max_iter: int = 100,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Trace-optimal member of the intersection family (batched 1-D search).

    With ``shrink=False`` this is the closed-form twin of the correction SDP of
    Bhattacharjee and Subbarao (2021), eqs. (6)-(7): the SDP optimum over the
    gain L and the multipliers is attained in the family of
    :func:`intersection_gain_form` with ``t = tau_2``, ``1 - t = tau_1``.

    The search exploits structure: with ``P = E E^T`` and
    ``E^T C^T W^{-1} C E = U diag(m) U^T``,
    ``trace P_t = sum_i h_i / (1 + t (m_i - 1))`` with ``h = diag(U^T E^T E U)``,
    a convex function of t; its minimiser is found by safeguarded Newton
    iterations on the derivative, vectorized over the batch.
    With ``shrink=True`` the factor delta(t) multiplies this function; the
    minimiser of the product is then found by a bounded golden-section search.

    Parameters
    ----------
    center : (..., n) array_like
        Centre ``c`` of the prior ellipsoid.
    shape : (..., n, n) array_like
        Its shape matrix ``P``, symmetric positive definite.
    C : (p, n) array_like
        Measurement matrix.
    y : (..., p) array_like
        Measurement.
    W : (p, p) array_like
        Shape of the measurement-noise set, symmetric positive definite (``D R D^T``).
    shrink : bool
        As in :func:`intersection_gain_form`.
    tol : float
        Tolerance of the search on t (finite, > 0).
    max_iter : int
        Largest number of Newton steps (>= 1).

    Returns
    -------
    center : (..., n) ndarray
        Centre of the optimal member.
    shape : (..., n, n) ndarray
        Its shape.
    gain : (..., n, p) ndarray
        Its gain ``L``.
    t : (...,) ndarray
        The optimal parameter.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> c, P, L, t = ell.intersection_min_trace(np.zeros(2), np.eye(2), [[1.0, 0.0]], [0.1], [[0.04]])
    >>> ts = np.linspace(0.01, 0.99, 99)                    # no member of the family has a smaller trace
    >>> others = ell.intersection_gain_form(np.zeros(2), np.eye(2), [[1.0, 0.0]], [0.1], [[0.04]], ts[:, None])[1]
    >>> bool(np.trace(P) <= np.trace(others, axis1=-2, axis2=-1).min() + 1e-12)
    True
    """
    c, P, C, y, W = _intersection_args(center, shape, C, y, W)
    tol = check_positive(tol, "tol")
    max_iter = check_positive_int(max_iter, "max_iter")
    new_c, new_P, L, t = kernels.intersection_min_trace(c, P, C, y, W, bool(shrink), tol, max_iter)
    return (finite_result("intersection (center)", new_c), finite_result("intersection (shape)", new_P),
            finite_result("intersection (gain)", L), t)


def max_innovation_form(
    center: ArrayLike, shape: ArrayLike, C: ArrayLike, y: ArrayLike, W: ArrayLike, n_iter: int = 60,
) -> np.ndarray:
    """``max_t nu^T (W / t + C P C^T / (1 - t))^{-1} nu``, with ``nu = y - C c``.

    This is the largest value of ``min_x q_t(x)`` over the intersection family;
    the intersection ``E(c, P) ∩ {x : |y - C x|_{W^{-1}} <= 1}`` is empty iff it
    exceeds 1. For one measurement (p = 1) the maximum is
    ``nu^2 / (sqrt(W) + sqrt(C P C^T))^2`` (the strip misses the projected
    ellipsoid); otherwise the concave function of t is maximised by bisection
    on its derivative after a simultaneous diagonalisation.

    Parameters
    ----------
    center : (..., n) array_like
        Centre ``c`` of the prior ellipsoid.
    shape : (..., n, n) array_like
        Its shape matrix ``P``, symmetric positive definite.
    C : (p, n) array_like
        Measurement matrix.
    y : (..., p) array_like
        Measurement.
    W : (p, p) array_like
        Shape of the measurement-noise set, symmetric positive definite (``D R D^T``).
    n_iter : int
        Bisection steps (>= 1) for p > 1.

    Returns
    -------
    (...,) ndarray
        The maximum; above 1 means an empty intersection.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> float(ell.max_innovation_form(np.zeros(2), np.eye(2), [[1.0, 0.0]], [3.0], [[0.25]]))   # 3^2 / (0.5 + 1)^2
    4.0
    """
    c, P, C, y, W = _intersection_args(center, shape, C, y, W)
    n_iter = check_positive_int(n_iter, "n_iter")
    return finite_result("innovation form", kernels.max_innovation_form(c, P, C, y, W, n_iter))


def intersection_is_empty(
    center: ArrayLike, shape: ArrayLike, C: ArrayLike, y: ArrayLike, W: ArrayLike, rtol: float = 1e-9
) -> np.ndarray:
    """True where ``E(c, P) ∩ {x : (y - C x)^T W^{-1} (y - C x) <= 1}`` is empty.

    Parameters
    ----------
    center : (..., n) array_like
        Centre ``c`` of the prior ellipsoid.
    shape : (..., n, n) array_like
        Its shape matrix ``P``, symmetric positive definite.
    C : (p, n) array_like
        Measurement matrix.
    y : (..., p) array_like
        Measurement.
    W : (p, p) array_like
        Shape of the measurement-noise set, symmetric positive definite (``D R D^T``).
    rtol : float
        Relative tolerance of the test (finite, >= 0).

    Returns
    -------
    (...,) bool ndarray
        True where the measurement is inconsistent with the prior set.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> ell.intersection_is_empty(np.zeros(2), np.eye(2), [[1.0, 0.0]], [[0.5], [3.0]], [[0.25]])
    array([False,  True])
    """
    rtol = check_positive(rtol, "rtol", allow_zero=True)
    return max_innovation_form(center, shape, C, y, W) > 1.0 + rtol


def sample_boundary(
    rng: np.random.Generator, center: ArrayLike, shape: ArrayLike, size: int | tuple[int, ...] = ()
) -> np.ndarray:
    """Points ``c + E u`` with u uniform on the unit sphere (``P = E E^T``).

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of randomness (or a non-negative integer seed).
    center : (n,) array_like
        Centre.
    shape : (n, n) array_like
        Shape, symmetric positive semidefinite.
    size : int or tuple of int
        Leading shape of the output (``()``: one point).

    Returns
    -------
    (size..., n) ndarray
        Points on the boundary.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> x = ell.sample_boundary(np.random.default_rng(0), np.zeros(2), np.diag([4.0, 1.0]), size=3)
    >>> np.round(ell.mahalanobis_sq(x, np.zeros(2), np.diag([4.0, 1.0])), 12)
    array([1., 1., 1.])
    """
    rng, c, P, size = _sampling_args(rng, center, shape, size)
    u = rng.standard_normal((*size, P.shape[0]))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    return c + u @ psd_factor(P).T


def sample_interior(
    rng: np.random.Generator, center: ArrayLike, shape: ArrayLike, size: int | tuple[int, ...] = ()
) -> np.ndarray:
    """Points uniform in E(c, P); the same as :func:`mascore.noise.uniform_ellipsoid`.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of randomness (or a non-negative integer seed).
    center : (n,) array_like
        Centre.
    shape : (n, n) array_like
        Shape, symmetric positive semidefinite.
    size : int or tuple of int
        Leading shape of the output (``()``: one point).

    Returns
    -------
    (size..., n) ndarray
        Points inside the ellipsoid.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids as ell
    >>> x = ell.sample_interior(np.random.default_rng(0), np.zeros(2), np.eye(2), size=1000)
    >>> bool(ell.contains(x, np.zeros(2), np.eye(2)).all())
    True
    """
    rng, c, P, size = _sampling_args(rng, center, shape, size)
    return uniform_ellipsoid(rng, c, P, size)


# --------------------------------------------------------------------------- argument checks


def _open_unit(t: ArrayLike, name: str) -> np.ndarray:
    """Family parameters: finite, strictly between 0 and 1."""
    if isinstance(t, bool):
        raise TypeError(f"{name} must be a number or an array of numbers in (0, 1); got bool")
    arr = _float_array(t, name)
    kernels.require_finite(arr, name)
    if np.any((arr <= 0) | (arr >= 1)):
        bad = arr[(arr <= 0) | (arr >= 1)].ravel()[0]
        raise ValueError(
            f"{name} must lie strictly between 0 and 1 (0 and 1 are limits of the family, where a "
            f"term is divided by zero); got {bad:g}"
        )
    return arr


def _intersection_args(center, shape, C, y, W):
    """Check the prior ellipsoid, the output matrix, the measurement and its shape ``W``."""
    P = kernels.shape_matrix(shape, "shape")
    n = P.shape[-1]
    c = kernels.points(center, "center", n)
    C = as_matrix(_float_array(C, "C"), "C", (None, n))
    p = C.shape[0]
    if p == 0:
        raise ValueError(f"C must have at least one row; got shape {C.shape}")
    y = _float_array(y, "y")
    if y.ndim < 1 or y.shape[-1] != p:
        raise ValueError(f"y must have last dimension {p} (the rows of C); got shape {y.shape}")
    kernels.require_finite(y, "y")
    W = kernels.shape_matrix(W, "W", size=p)
    kernels.broadcast(center=c.shape[:-1], shape=P.shape[:-2], y=y.shape[:-1], W=W.shape[:-2])
    return c, P, C, y, W


def _sampling_args(rng, center, shape, size):
    rng = check_generator(rng)
    P = kernels.shape_matrix(shape, "shape", definite=False)
    if P.ndim != 2:
        raise ValueError(f"shape must be a single (n, n) matrix; got shape {P.shape}")
    c = as_vector(_float_array(center, "center"), "center", P.shape[0])
    if isinstance(size, (tuple, list)):
        size = tuple(check_positive_int(k, "size") for k in size)
    else:
        size = (check_positive_int(size, "size"),)
    return rng, c, P, size
