"""Ellipsoidal set-membership filter (SMF), Algorithm 1 of Bhattacharjee and Subbarao (2021).

System (eq. (1)), with unknown-but-bounded disturbances::

    x_{k+1} = A x_k + B u_k + G w_k,   w_k in E(0, Q_k)
    y_k     = C x_k + D v_k,           v_k in E(0, R_k)

and the ellipsoid convention ``E(c, P) = {x : (x - c)^T P^{-1} (x - c) <= 1}``.
``G`` here is always the *disturbance* matrix of eq. (1); the pinning gains of
the synchronization law live in :mod:`mascore.synchronization`.

Each step comes in two interchangeable implementations, selected with ``method=``:

``"sdp"``
    The semidefinite programs of the paper, solved with Clarabel through
    :func:`mascore._solver.solve`. Correction, eqs. (6)-(7): minimise
    ``trace(P_{k|k})`` over ``P_{k|k}, L_k, tau_1, tau_2 >= 0`` subject to
    ``[[-P, Pi], [Pi^T, -Theta]] <= 0`` with
    ``Pi = [0, (I - L C) E, -L D]``, ``Theta = diag(1 - tau_1 - tau_2, tau_1 I, tau_2 R^{-1})``.
    Prediction, eq. (8): the same with ``Pi = [0, A E, G]`` and
    ``Psi = diag(1 - tau_3 - tau_4, tau_3 I, tau_4 Q^{-1})``. The LMIs are the
    S-procedure certificates that ``x - x_hat`` stays in ``E(0, P)`` whenever
    ``|z| <= 1`` and ``v^T R^{-1} v <= 1`` (or ``w^T Q^{-1} w <= 1``). Each program
    is built with cvxpy ``Parameter`` s once per :class:`SetMembershipModel` and reused
    by that model, step after step.

``"closed_form"``
    The fast twins. By a Schur complement the LMI reads
    ``P >= (I - L C) P^- (I - L C)^T / tau_1 + L W L^T / tau_2`` (``W = D R D^T``),
    whose best L for fixed tau is a Kalman gain: the optimum lies in the
    one-parameter ellipsoid/strip intersection family and is found by a 1-D
    convex search (:func:`mascore.ellipsoids.intersection_min_trace`). The
    prediction optimum is the trace-optimal Minkowski sum, in closed form
    (:func:`mascore.ellipsoids.minkowski_sum_min_trace`). Both are vectorized
    over any leading batch dimensions (agents, Monte Carlo runs).

Errors name the step (correction/prediction, time k) and the agent.

Checked model, plain steps
--------------------------
:class:`SetMembershipModel` checks the constant system matrices of eq. (1) once, at
construction (shapes, finiteness, symmetry, definiteness), derives ``D R D^T`` and
``G Q G^T`` and stores read-only copies; its :meth:`~SetMembershipModel.correct`,
:meth:`~SetMembershipModel.predict` and :meth:`~SetMembershipModel.run` check only the data
of each call (centre, shape, measurement, input) and the result. The functions
:func:`correct`, :func:`predict` and :func:`run_filter` take the plain arrays and check every
argument in full on every call (they build a model each time): for many steps with the
same system, build the model once. No state is shared between models; a model is safe
to share between threads with either method: the compiled cvxpy programs of ``method="sdp"``
belong to the call or to the caller (the `programs` dict of :meth:`SetMembershipModel.correct`),
never to the model.

Units: the state ``x`` and output ``y`` in the user's units; every ellipsoid shape matrix (``P``,
and the disturbance bounds ``Q`` and ``R``, which are *shapes*, not covariances) in the unit of its
vector squared: the semi-axes of ``E(c, P)`` are the square roots of the eigenvalues of ``P``.
Time is the step index ``k`` (discrete time).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from . import _ellipsoid_kernels as kernels
from ._validation import Frozen, agent_index, as_matrix, check_square, frozen_copy, require_finite, symmetric_part
from ._validation import float_array as _float_array
from .estimation import MethodSpec, protocol_docs
from .fusion_cost import kalman_step_flops

__all__ = [
    "SOLVERS",
    "METHODS",
    "FilterHistory",
    "SetMembershipModel",
    "correct",
    "predict",
    "run_filter",
]

#: Available implementations of each step.
SOLVERS = ("sdp", "closed_form")

#: Tolerance of the consistency test y_k vs. the prior ellipsoid (relative, on the quadratic form).
CONSISTENCY_RTOL = 1e-6

Method = Literal["sdp", "closed_form"]


def correct(
    center: ArrayLike, shape: ArrayLike, y: ArrayLike, C: ArrayLike, D: ArrayLike, R: ArrayLike,
    method: Method = "closed_form", step: int | None = None, agent: ArrayLike | None = None,
    check_consistency: bool = True, solver_options: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Correction step: eqs. (2), (6)-(7): the smallest-trace ellipsoid holding the prior and the measurement set.

    Checks every argument in full on every call, the system matrices included (with
    ``method="sdp"`` the program is also built anew): for many steps with the same
    `C`, `D`, `R`, build a :class:`SetMembershipModel` once and call its
    :meth:`~SetMembershipModel.correct`.

    Parameters
    ----------
    center : (..., n) array_like
        Predicted centre ``x_hat_{k|k-1}``.
    shape : (..., n, n) array_like
        Predicted shape ``P_{k|k-1}``, positive definite.
    y : (..., p) array_like
        Measurement ``y_k``.
    C : (p, n) array_like
        Output matrix.
    D : (p, v) array_like
        Output-disturbance matrix (``D R D^T`` positive definite for ``method="closed_form"``).
    R : (v, v) array_like
        Shape matrix of the output-disturbance ellipsoid ``{v : v^T R^{-1} v <= 1}``, positive definite: a
        set bound, not a covariance, in (output unit)^2.
    method : {"closed_form", "sdp"}
        The closed form of the trace-optimal intersection (default) or the SDP of eq. (6)
        solved with cvxpy/Clarabel (needs the ``sdp`` extra); both give the same ellipsoid.
    step : int, optional
        Time index, used in error messages.
    agent : int or array_like, optional
        Agent label(s) used in error messages; may be an array broadcast against the batch
        dimensions (e.g. ``np.arange(N)``).
    check_consistency : bool
        Raise if ``y`` is inconsistent with the prior ellipsoid (empty intersection).
    solver_options : dict, optional
        ``method="sdp"`` only: settings passed to the conic solver (Clarabel) by name;
        default Clarabel's own.

    Returns
    -------
    center : (..., n) ndarray
        ``x_hat_{k|k} = x_hat_{k|k-1} + L_k (y_k - C x_hat_{k|k-1})``, eq. (2).
    shape : (..., n, n) ndarray
        ``P_{k|k}``.
    gain : (..., n, p) ndarray
        ``L_k``.

    Raises
    ------
    ValueError
        Non positive-definite prior shape, bad shapes, or an empty intersection.
    mascore.SolverError
        The SDP was not solved to optimality.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import set_membership as sm
    >>> C, D, R = [[1.0, 0.0]], [[1.0]], [[0.04]]          # y = x_1 + v, |v| <= 0.2
    >>> c, P, L = sm.correct(np.zeros(2), np.eye(2), [0.1], C, D, R)
    >>> bool(np.trace(P) < 2.0)                           # the measurement shrinks the set
    True
    >>> cs, Ps, _ = sm.correct(np.zeros(2), np.eye(2), [0.1], C, D, R, method="sdp")
    >>> bool(np.allclose(Ps, P, atol=1e-5))               # SDP and closed form agree
    True
    """
    method = _check_method(method)
    c, P = _check_ellipsoid(center, shape, "correction", step, agent)
    model = SetMembershipModel(C=C, D=D, R=R, n=c.shape[-1])
    return model._correct(c, P, y, method, step, agent, check_consistency, solver_options)


def predict(
    center: ArrayLike, shape: ArrayLike, A: ArrayLike, G: ArrayLike, Q: ArrayLike,
    B: ArrayLike | None = None, u: ArrayLike | None = None, method: Method = "closed_form",
    step: int | None = None, agent: ArrayLike | None = None, solver_options: dict | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Prediction step: eqs. (4), (8): the smallest-trace ellipsoid holding ``A E + G W (+ B u)``.

    Checks every argument in full on every call, the system matrices included (with
    ``method="sdp"`` the program is also built anew): for many steps with the same
    `A`, `G`, `Q`, `B`, build a :class:`SetMembershipModel` once and call its
    :meth:`~SetMembershipModel.predict`.

    Parameters
    ----------
    center : (..., n) array_like
        Corrected centre ``x_hat_{k|k}``.
    shape : (..., n, n) array_like
        Corrected shape ``P_{k|k}``, positive definite.
    A : (n, n) array_like
        State matrix.
    G : (n, w) array_like
        Disturbance matrix.
    Q : (w, w) array_like
        Shape matrix of the process-disturbance ellipsoid ``{w : w^T Q^{-1} w <= 1}``, positive definite: a
        set bound, not a covariance, in (disturbance unit)^2.
    B : (n, m) array_like, optional
        Input matrix (with `u`).
    u : (..., m) array_like, optional
        Known input (with `B`).
    method : {"closed_form", "sdp"}
        As in :func:`correct`.
    step : int, optional
        Time index, used in error messages.
    agent : int or array_like, optional
        Agent label(s), used in error messages.
    solver_options : dict, optional
        As in :func:`correct`.

    Returns
    -------
    center : (..., n) ndarray
        ``A x_hat_{k|k} + B u_k``, eq. (4).
    shape : (..., n, n) ndarray
        ``P_{k+1|k}``.

    Raises
    ------
    ValueError
        Bad shapes, a non positive-definite shape, or only one of `B` and `u`.
    mascore.SolverError
        The SDP was not solved to optimality.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import set_membership as sm
    >>> c, P = sm.predict(np.zeros(2), np.eye(2), A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), Q=0.01 * np.eye(2))
    >>> bool(np.trace(P) > 2.0)                           # the disturbance grows the set
    True
    """
    method = _check_method(method)
    c, P = _check_ellipsoid(center, shape, "prediction", step, agent)
    if (B is None) != (u is None):
        raise ValueError("give both B and u, or neither")
    model = SetMembershipModel(A=A, G=G, Q=Q, B=B, n=c.shape[-1])
    return model._predict(c, P, u, method, step, agent, solver_options)


@dataclass(frozen=True)
class FilterHistory:
    """Output of :func:`run_filter` over k = 0..T_f.

    A run's output: its arrays are the caller's, writeable and shared with no model or filter.

    Parameters
    ----------
    center_corr : (T_f + 1, ..., n) ndarray
        Centres of the correction ellipsoids ``E(x_hat_{k|k}, P_{k|k})``.
    shape_corr : (T_f + 1, ..., n, n) ndarray
        Their shape matrices.
    center_pred : (T_f + 1, ..., n) ndarray
        Centres of the prediction ellipsoids ``E(x_hat_{k+1|k}, P_{k+1|k})``.
    shape_pred : (T_f + 1, ..., n, n) ndarray
        Their shape matrices.
    gain : (T_f + 1, ..., n, p) ndarray
        The correction gains ``L_k``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import set_membership as sm
    >>> C, D, R = [[1.0, 0.0]], [[1.0]], [[0.04]]          # y = x_1 + v, |v| <= 0.2
    >>> h = sm.run_filter(np.zeros(2), np.eye(2), np.zeros((5, 1)), np.eye(2), np.eye(2), C, D, 0.01 * np.eye(2), R)
    >>> h.center_corr.shape, h.shape_corr.shape, h.gain.shape
    ((5, 2), (5, 2, 2), (5, 2, 1))
    """

    center_corr: np.ndarray
    shape_corr: np.ndarray
    center_pred: np.ndarray
    shape_pred: np.ndarray
    gain: np.ndarray


def run_filter(
    x0_hat: ArrayLike, P0: ArrayLike, y: ArrayLike, A: ArrayLike, G: ArrayLike, C: ArrayLike,
    D: ArrayLike, Q: ArrayLike, R: ArrayLike, B: ArrayLike | None = None, u: ArrayLike | None = None,
    method: Method = "closed_form", agent: ArrayLike | None = None, solver_options: dict | None = None,
) -> FilterHistory:
    """Algorithm 1 for open-loop data: correct with ``y[k]``, then predict, k = 0..T_f.

    Checks every argument in full on every call (the system matrices through a
    :class:`SetMembershipModel` built for the call); :meth:`SetMembershipModel.run` runs
    the same filter on a model checked once. The initial ellipsoid, the measurement array
    and the method are checked before the first step; each step then checks its
    measurement, input and result.

    Parameters
    ----------
    x0_hat : (..., n) array_like
        Centre of the initial ellipsoid (Assumption 1.1).
    P0 : (..., n, n) array_like
        Its shape matrix, positive definite.
    y : (T_f + 1, ..., p) array_like
        Measurements.
    A : (n, n) array_like
        State matrix.
    G : (n, w) array_like
        Disturbance matrix.
    C : (p, n) array_like
        Output matrix.
    D : (p, v) array_like
        Output-disturbance matrix.
    Q : (w, w) array_like
        Shape matrix of the process-disturbance ellipsoid ``{w : w^T Q^{-1} w <= 1}`` (time-invariant): a
        set bound, not a covariance, in (disturbance unit)^2.
    R : (v, v) array_like
        Shape matrix of the output-disturbance ellipsoid ``{v : v^T R^{-1} v <= 1}`` (time-invariant): a
        set bound, not a covariance, in (output unit)^2.
    B : (n, m) array_like, optional
        Input matrix (with `u`).
    u : (T_f + 1, ..., m) array_like, optional
        Known inputs (with `B`; give both or neither).
    method : {"closed_form", "sdp"}
        As in :func:`correct`.
    agent : int or array_like, optional
        Agent label(s), used in error messages.
    solver_options : dict, optional
        As in :func:`correct`.

    Returns
    -------
    FilterHistory
        The correction and prediction ellipsoids and gains of every step.

    Raises
    ------
    ValueError
        Bad shapes, a non positive-definite shape, inconsistent data (empty intersection).
    mascore.SolverError
        An SDP was not solved to optimality (``method="sdp"``).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import ellipsoids, noise
    >>> from mascore import set_membership as sm
    >>> rng = np.random.default_rng(1)
    >>> A, G, C, D = np.array([[1.0, 0.1], [-0.1, 1.0]]), np.eye(2), [[1.0, 0.0]], [[1.0]]
    >>> Q, R = 1e-4 * np.eye(2), [[0.01]]
    >>> x = [np.array([0.5, 0.0])]
    >>> for k in range(30):
    ...     x.append(A @ x[-1] + noise.uniform_ellipsoid(rng, np.zeros(2), Q))
    >>> x = np.array(x)
    >>> y = x[:, :1] + noise.uniform_ellipsoid(rng, np.zeros(1), R, size=31)
    >>> h = sm.run_filter(np.zeros(2), np.eye(2), y, A, G, C, D, Q, R)
    >>> bool(ellipsoids.contains(x, h.center_corr, h.shape_corr).all())   # the set always holds the state
    True
    """
    method = _check_method(method)
    c, P, y, u = _check_run_data(x0_hat, P0, y, B, u)
    model = SetMembershipModel(A=A, G=G, C=C, D=D, Q=Q, R=R, B=B, n=P.shape[-1])
    return model.run(c, P, y, u, method, agent, solver_options)


@dataclass(frozen=True, eq=False)
@protocol_docs
class SetMembershipModel(Frozen):
    """The system of eq. (1), checked once: the filter's constant matrices, stored read-only.

    Give the motion part (`A`, `G`, `Q`, optionally `B`) for :meth:`predict`, the
    measurement part (`C`, `D`, `R`) for :meth:`correct`, both for :meth:`run`. The
    constructor checks every matrix (shape, finiteness, symmetry, definiteness),
    derives ``D R D^T`` and ``G Q G^T`` and keeps read-only copies, so that a later change
    to the caller's arrays cannot reach the filter; the methods then check only the data
    of each call (centre, shape, measurement, input) and the result.

    Parameters
    ----------
    A : (n, n) array_like, optional
        State matrix.
    G : (n, w) array_like, optional
        Disturbance matrix (with `A` and `Q`).
    C : (p, n) array_like, optional
        Output matrix.
    D : (p, v) array_like, optional
        Output-disturbance matrix (with `C` and `R`).
    Q : (w, w) array_like, optional
        Shape matrix of the process-disturbance ellipsoid ``{w : w^T Q^{-1} w <= 1}``, positive definite: a
        set bound, not a covariance, in (disturbance unit)^2.
    R : (v, v) array_like, optional
        Shape matrix of the output-disturbance ellipsoid ``{v : v^T R^{-1} v <= 1}``, positive definite: a
        set bound, not a covariance, in (output unit)^2.
    B : (n, m) array_like, optional
        Input matrix (then :meth:`predict` needs `u`).
    n : int, optional
        State size (default: from `A`, else from the columns of `C`).

    Notes
    -----
    A model holds no mutable state and may be shared between threads, with either method. The
    compiled cvxpy programs of ``method="sdp"`` belong to the call (:meth:`run` compiles them once
    for all its steps) or to the caller, who keeps them in the `programs` dict of
    :meth:`correct` and :meth:`predict` across the steps of a loop (one dict per thread).

    Raises
    ------
    ValueError
        A matrix of the wrong shape, with NaN/inf entries, not symmetric positive definite
        (`Q`, `R`), or a part given incompletely; the message names the matrix.
    TypeError
        A matrix that is not an array of real numbers.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import set_membership as sm
    >>> model = sm.SetMembershipModel(A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), C=[[1.0, 0.0]], D=[[1.0]],
    ...                               Q=0.01 * np.eye(2), R=[[0.04]])
    >>> c, P, L = model.correct(np.zeros(2), np.eye(2), [0.1])
    >>> c, P = model.predict(c, P)
    >>> model.A.flags.writeable                                  # read-only: checked once, cannot change
    False
    """

    A: np.ndarray | None = None
    G: np.ndarray | None = None
    C: np.ndarray | None = None
    D: np.ndarray | None = None
    Q: np.ndarray | None = None
    R: np.ndarray | None = None
    B: np.ndarray | None = None
    n: int | None = None
    W: np.ndarray | None = field(init=False, repr=False, default=None)  #: D R D^T
    W_error: str | None = field(init=False, repr=False, default=None)  #: why W cannot serve the consistency test
    GQG: np.ndarray | None = field(init=False, repr=False, default=None)  #: G Q G^T
    sqrt_tr_GQG: np.ndarray | None = field(init=False, repr=False, default=None)  #: sqrt(trace(G Q G^T))

    def __post_init__(self) -> None:
        motion = (self.A, self.G, self.Q)
        measurement = (self.C, self.D, self.R)
        if any(m is not None for m in motion) and any(m is None for m in motion):
            raise ValueError("give A, G and Q together (the motion part of the model)")
        if any(m is not None for m in measurement) and any(m is None for m in measurement):
            raise ValueError("give C, D and R together (the measurement part of the model)")
        if self.B is not None and self.A is None:
            raise ValueError("B needs the motion part A, G, Q")
        if self.A is None and self.C is None:
            raise ValueError("give the motion part (A, G, Q) or the measurement part (C, D, R), or both")
        n = self.n
        if n is None:
            n = (check_square(self.A, "A") if self.A is not None else as_matrix(self.C, "C", (None, None))).shape[1]
        self._set(n=int(n))
        if self.A is not None:
            A = check_square(self.A, "A", n)
            G = as_matrix(self.G, "G (disturbance matrix)", (n, None))
            Q = _check_pd_small(self.Q, "Q", G.shape[1])
            with np.errstate(over="ignore", invalid="ignore"):
                GQG = G @ Q @ G.T
            if not np.isfinite(GQG).all() or np.abs(GQG).max() > _MAX_SHAPE_ENTRY:
                raise ValueError("G (disturbance matrix): G Q G^T overflows floating point; G and Q must be of "
                                 "moderate magnitude (rescale the units of the state or of the disturbance)")
            self._set(A=frozen_copy(A), G=frozen_copy(G), Q=frozen_copy(Q), GQG=frozen_copy(GQG))
            self._set(sqrt_tr_GQG=frozen_copy(kernels.sqrt_trace(GQG)))
            if self.B is not None:
                self._set(B=frozen_copy(as_matrix(self.B, "B", (n, None))))
        if self.C is not None:
            C = as_matrix(self.C, "C", (None, n))
            p = C.shape[0]
            D = as_matrix(self.D, "D", (p, None))
            R = _check_pd_small(self.R, "R", D.shape[1])
            with np.errstate(over="ignore", invalid="ignore"):
                W = D @ R @ D.T
            if not np.isfinite(W).all():
                raise ValueError("D: D R D^T overflows floating point; D and R must be of moderate magnitude "
                                 "(rescale the units of the measurement or of its noise)")
            for name, M in (("C", C), ("D R D^T (from D and R)", W)):
                if M.size and np.abs(M).max() > _MAX_SHAPE_ENTRY:
                    raise ValueError(f"{name} has entries of magnitude {np.abs(M).max():.3g}, beyond "
                                     f"{_MAX_SHAPE_ENTRY:g}: the correction would overflow floating point; rescale "
                                     f"the units of the measurement or of its noise")
            try:
                _check_pd_small(W, "D R D^T (needed to test the consistency of y)", p)
            except ValueError as exc:
                self._set(W_error=str(exc))
            self._set(C=frozen_copy(C), D=frozen_copy(D), R=frozen_copy(R), W=frozen_copy(W))

    def correct(
        self, center: ArrayLike, shape: ArrayLike, y: ArrayLike, method: Method = "closed_form",
        step: int | None = None, agent: ArrayLike | None = None, check_consistency: bool = True,
        solver_options: dict | None = None, programs: dict | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Correction step, eqs. (2), (6)-(7), with this model's `C`, `D`, `R` (see :func:`correct`).

        Checks `center`, `shape` (positive definite), `y` and the result; the matrices were
        checked at construction.

        Parameters
        ----------
        center : (..., n) array_like
            Predicted centre ``x_hat_{k|k-1}``.
        shape : (..., n, n) array_like
            Predicted shape ``P_{k|k-1}``, positive definite.
        y : (..., p) array_like
            Measurement ``y_k``.
        method, step, agent, check_consistency, solver_options
            As in :func:`correct`.
        programs : dict, optional
            ``method="sdp"`` only: where the compiled SDPs are kept between calls. Pass one dict, empty at
            first, to every step of a loop to compile once; it is the caller's (one per thread). By default
            the call compiles its own.

        Returns
        -------
        center : (..., n) ndarray
        shape : (..., n, n) ndarray
        gain : (..., n, p) ndarray
            As in :func:`correct`.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import set_membership as sm
        >>> model = sm.SetMembershipModel(A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), C=[[1.0, 0.0]], D=[[1.0]],
        ...                               Q=0.01 * np.eye(2), R=[[0.04]])
        >>> c, P, L = model.correct(np.zeros(2), np.eye(2), [0.1])
        >>> bool(np.trace(P) < 2.0)                           # the measurement shrinks the set
        True
        """
        method = _check_method(method)
        c, P = self._ellipsoid(center, shape, "correction", step, agent, self.C)
        return self._correct(c, P, y, method, step, agent, check_consistency, solver_options, programs)

    def update(self, center: ArrayLike, shape: ArrayLike, y: ArrayLike, **options: Any
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The update of the estimator protocol: :meth:`correct` (the paper's correction step).

        Parameters
        ----------
        center : (..., n) array_like
            Predicted centre.
        shape : (..., n, n) array_like
            Predicted shape, positive definite.
        y : (..., p) array_like
            Measurement.
        **options
            Those of :meth:`correct` (``method``, ``solver_options``, ...).

        Returns
        -------
        center : (..., n) ndarray
        shape : (..., n, n) ndarray
        gain : (..., n, p) ndarray
            As :meth:`correct`.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import set_membership as sm
        >>> model = sm.SetMembershipModel(A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), C=[[1.0, 0.0]], D=[[1.0]],
        ...                               Q=0.01 * np.eye(2), R=[[0.04]])
        >>> all(np.array_equal(a, b) for a, b in zip(model.update(np.zeros(2), np.eye(2), [0.1]),
        ...                                          model.correct(np.zeros(2), np.eye(2), [0.1])))
        True
        """
        return self.correct(center, shape, y, **options)

    def predict(
        self, center: ArrayLike, shape: ArrayLike, u: ArrayLike | None = None, method: Method = "closed_form",
        step: int | None = None, agent: ArrayLike | None = None, solver_options: dict | None = None,
        programs: dict | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Prediction step, eqs. (4), (8), with this model's `A`, `G`, `Q` (and `B`) (see :func:`predict`).

        Parameters
        ----------
        center : (..., n) array_like
            Corrected centre ``x_hat_{k|k}``.
        shape : (..., n, n) array_like
            Corrected shape ``P_{k|k}``, positive definite.
        u : (..., m) array_like, optional
            Known input, exactly when the model has `B`.
        method, step, agent, solver_options
            As in :func:`predict`.
        programs : dict, optional
            As in :meth:`correct`.

        Returns
        -------
        center : (..., n) ndarray
        shape : (..., n, n) ndarray
            As in :func:`predict`.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import set_membership as sm
        >>> model = sm.SetMembershipModel(A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), C=[[1.0, 0.0]], D=[[1.0]],
        ...                               Q=0.01 * np.eye(2), R=[[0.04]])
        >>> c, P = model.predict(np.zeros(2), np.eye(2))
        >>> bool(np.trace(P) > 2.0)                           # the disturbance grows the set
        True
        """
        method = _check_method(method)
        c, P = self._ellipsoid(center, shape, "prediction", step, agent, self.A)
        if (self.B is None) != (u is None):
            raise ValueError("give both B and u, or neither")
        return self._predict(c, P, u, method, step, agent, solver_options, programs)

    def agent_inputs(self, center: ArrayLike, shape: ArrayLike, y: ArrayLike, u: ArrayLike | None,
                     i: int) -> tuple[dict, tuple]:
        """Agent i's data of one step when every agent runs this set-membership filter on its own state.

        Parameters
        ----------
        center : (N, n) array_like
            The agents' set centres before the step.
        shape : (n, n) or (N, n, n) array_like
            Their shape matrices (one shared by all agents, or one each).
        y : (N, p) array_like
            Each agent's own measurement of the step.
        u : (N, k) array_like or None
            The inputs applied (None without ``B``).
        i : int
            The agent.

        Returns
        -------
        own : dict
            Its ``center``, ``shape``, measurement ``y`` and input ``u`` (copies).
        messages : tuple
            Empty: the filter uses the agent's own measurement only.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.set_membership import SetMembershipModel
        >>> model = SetMembershipModel(A=np.eye(1), G=np.eye(1), C=np.eye(1), D=np.eye(1), Q=np.eye(1), R=np.eye(1))
        >>> own, messages = model.agent_inputs(np.zeros((2, 1)), np.eye(1), [[0.5], [1.0]], None, 1)
        >>> own["y"], messages
        (array([1.]), ())
        """
        c, E, y = (require_finite(_float_array(a, name), name) for a, name in ((center, "center"), (shape, "shape"),
                                                                              (y, "y")))
        if c.ndim != 2 or E.shape[-2:] != (c.shape[1],) * 2 or E.ndim not in (2, 3) or (E.ndim == 3 and len(E) != len(c)):
            raise ValueError(f"center must be (N, n) and shape (n, n) or (N, n, n); got {c.shape} and {E.shape}")
        i = agent_index(i, len(c))
        return ({"center": c[i].copy(), "shape": (E if E.ndim == 2 else E[i]).copy(), "y": y[i].copy(),
                 "u": None if u is None else np.array(np.asarray(u, dtype=float)[i])}, ())

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        # the closed-form correction with its own measurement, then prediction: centre (n,), shape (n, n)
        c, E, _ = self.correct(own["center"], own["shape"], own["y"], check_consistency=False)
        return self.predict(c, E, own["u"])

    def messages(self, i: int = 0) -> tuple:
        # nothing
        return ()

    def run(
        self, x0_hat: ArrayLike, P0: ArrayLike, y: ArrayLike, u: ArrayLike | None = None,
        method: Method = "closed_form", agent: ArrayLike | None = None, solver_options: dict | None = None,
    ) -> FilterHistory:
        """Algorithm 1 for open-loop data with this model (see :func:`run_filter`).

        Parameters
        ----------
        x0_hat : (..., n) array_like
            Centre of the initial ellipsoid.
        P0 : (..., n, n) array_like
            Its shape matrix, positive definite (checked in full once).
        y : (T_f + 1, ..., p) array_like
            Measurements.
        u : (T_f + 1, ..., m) array_like, optional
            Known inputs, exactly when the model has `B`.
        method, agent, solver_options
            As in :func:`run_filter`.

        Returns
        -------
        FilterHistory

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import set_membership as sm
        >>> model = sm.SetMembershipModel(A=[[1.0, 0.1], [0.0, 1.0]], G=np.eye(2), C=[[1.0, 0.0]], D=[[1.0]],
        ...                               Q=0.01 * np.eye(2), R=[[0.04]])
        >>> h = model.run(np.zeros(2), np.eye(2), np.zeros((5, 1)))
        >>> h.center_corr.shape, h.shape_pred.shape
        ((5, 2), (5, 2, 2))
        """
        method = _check_method(method)
        if self.A is None or self.C is None:
            raise ValueError("run needs both parts of the model: A, G, Q and C, D, R")
        c, P, y, u = _check_run_data(x0_hat, P0, y, self.B, u)
        if P.shape[-1] != self.n:
            raise ValueError(f"P0 must be ({self.n}, {self.n}) like the model's A; got {P.shape}")
        out: dict[str, list] = {k: [] for k in ("cc", "pc", "cp", "pp", "L")}
        programs: dict = {}  # the run's compiled SDPs (method="sdp"), reused step after step
        for k in range(y.shape[0]):  # Algorithm 1: correct with y[k], then predict, k = 0..T_f
            c, P, L = self._correct(c, P, y[k], method, k, agent, True, solver_options, programs)
            out["cc"].append(c)
            out["pc"].append(P)
            out["L"].append(L)
            uk = None if u is None else u[k]
            c, P = self._predict(c, P, uk, method, k, agent, solver_options, programs)
            out["cp"].append(c)
            out["pp"].append(P)
        return FilterHistory(np.array(out["cc"]), np.array(out["pc"]), np.array(out["cp"]),
                             np.array(out["pp"]), np.array(out["L"]))

    # -- the steps on checked data (the public methods and functions check first)

    def _ellipsoid(self, center, shape, what, step, agent, part):
        if part is None:
            raise ValueError(f"this model has no {'C, D, R' if what == 'correction' else 'A, G, Q'}: "
                             f"it cannot run the {what} step")
        c, P = _check_ellipsoid(center, shape, what, step, agent)
        if c.shape[-1] != self.n:
            raise ValueError(f"{_where(what, step, agent, None, ())}: center has size {c.shape[-1]} but the "
                             f"model's state has size {self.n}")
        return c, P

    def _correct(self, c, P, y, method, step, agent, check_consistency, solver_options, programs=None):
        """Eqs. (2), (6)-(7) on a checked ellipsoid `c`, `P` (`y` checked here)."""
        if self.C is None:
            raise ValueError("this model has no C, D, R: it cannot run the correction step")
        C, D, R, W, W_error = self.C, self.D, self.R, self.W, self.W_error
        n = self.n
        p = C.shape[0]
        y = _float_array(y, "y")
        if y.shape[-1:] != (p,):
            raise ValueError(f"y must have last dimension {p} (rows of C); got shape {y.shape}")
        if not np.isfinite(y).all():
            raise ValueError(f"{_where('correction', step, agent, None, ())}: y has NaN/inf entries")
        if P.size and np.abs(P).max() > _MAX_SHAPE_ENTRY:  # squared in eqs. (6)-(7): beyond floating point
            raise ValueError(f"{_where('correction', step, agent, None, ())}: shape has entries of magnitude "
                             f"{np.abs(P).max():.3g}, beyond {_MAX_SHAPE_ENTRY:g}: the correction would overflow "
                             f"floating point; rescale the state's units")
        batch = c.shape[:-1]
        if P.shape[:-2] != batch or y.shape[:-1] != batch:
            batch = kernels.broadcast(center=batch, shape=P.shape[:-2], y=y.shape[:-1])
            c, P, y = (np.broadcast_to(c, (*batch, n)), np.broadcast_to(P, (*batch, n, n)),
                       np.broadcast_to(y, (*batch, p)))
        if check_consistency:
            if W_error is not None:
                raise ValueError(W_error)
            q = kernels.max_innovation_form(c, P, C, y, W)
            bad = q > 1.0 + CONSISTENCY_RTOL
            if bad.any():
                idx = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
                raise ValueError(
                    f"{_where('correction', step, agent, idx, batch)}: measurement y = {y[idx]} is "
                    f"inconsistent with the prior ellipsoid (empty intersection; the innovation form "
                    f"max_t nu^T S_t^-1 nu = {float(q[idx]):.6g} > 1): the truth left the set, so a bound is "
                    f"too small for the data: the process or measurement noise ellipsoids (their shape "
                    f"matrices) or the initial ellipsoid; enlarge the one that is optimistic"
                )
        if method == "closed_form":
            try:
                new_c, new_P, L, _ = kernels.intersection_min_trace(c, P, C, y, W)
            except ValueError as exc:
                raise ValueError(f"{_where('correction', step, agent, None, batch)}: {exc}") from exc
        else:
            new_c = np.empty_like(c)
            new_P = np.empty_like(P)
            L = np.empty((*batch, n, p))
            from ._set_membership_sdp import correction_sdp

            sdp = _program(programs, "correction", correction_sdp, n, p, D.shape[1])
            Rinv = np.linalg.inv(R)
            for idx in np.ndindex(*batch):
                E = _cholesky(P[idx], "correction", step, agent, idx, batch)
                where = _where("correction SDP eq. (6)", step, agent, idx, batch)
                new_P[idx], L[idx] = sdp(E, C, D, Rinv, where, solver_options)
                new_c[idx] = c[idx] + L[idx] @ (y[idx] - C @ c[idx])
        _check_result(new_P, "correction", step, agent, batch)
        return new_c, new_P, L

    def _predict(self, c, P, u, method, step, agent, solver_options, programs=None):
        """Eqs. (4), (8) on a checked ellipsoid `c`, `P` (`u` checked here)."""
        if self.A is None:
            raise ValueError("this model has no A, G, Q: it cannot run the prediction step")
        A, G, Q, GQG, sqrt_tr_GQG, B = self.A, self.G, self.Q, self.GQG, self.sqrt_tr_GQG, self.B
        n = self.n
        batch = c.shape[:-1]
        if P.shape[:-2] != batch:
            batch = kernels.broadcast(center=batch, shape=P.shape[:-2])
            c, P = np.broadcast_to(c, (*batch, n)), np.broadcast_to(P, (*batch, n, n))
        new_c = c @ A.T
        if B is not None:
            u = _float_array(u, "u")
            if u.shape[-1:] != B.shape[1:] or not np.isfinite(u).all():
                raise ValueError(f"u must be finite with last dimension {B.shape[1]} (columns of B); got shape {u.shape}")
            new_c = new_c + u @ B.T
        with np.errstate(over="ignore", invalid="ignore"):
            APA = A @ P @ A.T
        _check_overflow(new_c, APA, A, P, step, agent)
        if method == "closed_form":  # trace-optimal Minkowski sum of E(0, A P A^T) and E(0, G Q G^T)
            with np.errstate(over="ignore", invalid="ignore"):
                new_P, _ = kernels.sum_min_trace(APA, GQG, kernels.sqrt_trace(APA), sqrt_tr_GQG)
            _check_overflow(new_c, new_P, A, P, step, agent)
        else:
            new_P = np.empty_like(P)
            from ._set_membership_sdp import prediction_sdp

            sdp = _program(programs, "prediction", prediction_sdp, n, G.shape[1])
            Qinv = np.linalg.inv(Q)
            for idx in np.ndindex(*batch):
                E = _cholesky(P[idx], "prediction", step, agent, idx, batch)
                new_P[idx] = sdp(A @ E, G, Qinv, _where("prediction SDP eq. (8)", step, agent, idx, batch),
                                 solver_options)
        _check_result(new_P, "prediction", step, agent, batch)
        return new_c, new_P


def _check_run_data(x0_hat, P0, y, B, u):
    """The initial ellipsoid, the measurements and the inputs of :func:`run_filter`, checked."""
    P = kernels.shape_matrix(P0, "P0")
    c = kernels.points(x0_hat, "x0_hat", P.shape[-1])
    y = _float_array(y, "y")
    if y.ndim < 2 or y.shape[0] < 1:
        raise ValueError(f"y must be an array (T_f + 1, ..., p) with at least one measurement; got shape {y.shape}")
    kernels.broadcast(x0_hat=c.shape[:-1], P0=P.shape[:-2], y=y.shape[1:-1])
    for name, M in (("x0_hat", c), ("P0", P)):  # the first correction squares them
        if M.size and np.abs(M).max() > _MAX_SHAPE_ENTRY:
            raise ValueError(f"{name} has entries of magnitude {np.abs(M).max():.3g}, beyond {_MAX_SHAPE_ENTRY:g}: "
                             f"the correction would overflow floating point; rescale the state's units")
    if (B is None) != (u is None):
        raise ValueError("give both B and u, or neither")
    if u is not None:
        u = _float_array(u, "u")
        if u.ndim < 1 or u.shape[0] < y.shape[0]:
            raise ValueError(f"u must have one input per measurement, shape (T_f + 1, ..., m) with T_f + 1 = "
                             f"{y.shape[0]}; got shape {u.shape}")
    return c, P, y, u


# --------------------------------------------------------------------------- private


def _program(programs, key, build, *sizes):
    """The compiled SDP `key`: built anew without `programs`, else taken from (or built into) that dict."""
    if programs is None:
        return build(*sizes)
    if key not in programs:
        programs[key] = build(*sizes)
    return programs[key]


def _check_method(method: str) -> str:
    if not isinstance(method, str):
        raise TypeError(f"method must be one of {SOLVERS}; got {type(method).__name__} {method!r}")
    if method not in SOLVERS:
        raise ValueError(f"method must be one of {SOLVERS}; got {method!r}")
    return method


def _where(what: str, step, agent, idx, batch) -> str:
    parts = [what + " step" if not what.endswith(")") else what]
    if step is not None:
        parts.append(f"k = {step}")
    if agent is not None:
        if idx is None or not np.ndim(agent):
            parts.append(f"agent {agent if not np.ndim(agent) else 'batch'}")
        else:
            parts.append(f"agent {np.broadcast_to(np.asarray(agent), batch)[idx]}")
    if idx is not None and len(batch):
        parts.append(f"batch index {idx}")
    return ", ".join(parts)


def _check_ellipsoid(center, shape, what, step, agent):
    c = _float_array(center, "center")
    P = _float_array(shape, "shape")
    if c.ndim < 1 or P.ndim < 2 or P.shape[-2:] != (c.shape[-1], c.shape[-1]):
        raise ValueError(
            f"{_where(what, step, agent, None, ())}: center (..., n) and shape (..., n, n) do not "
            f"match; got {c.shape} and {P.shape}"
        )
    if not (np.isfinite(c).all() and np.isfinite(P).all()):
        raise ValueError(f"{_where(what, step, agent, None, ())}: center or shape has NaN/inf entries")
    _require_pd(P, what, step, agent, "the shape matrix")
    return c, P


def _require_pd(P, what, step, agent, label):
    """Raise naming the step and agent unless every matrix of the stack P is symmetric PD."""
    if (P == np.swapaxes(P, -1, -2)).all():  # exactly symmetric (the usual case): Cholesky decides
        try:
            np.linalg.cholesky(P)
            return
        except np.linalg.LinAlgError:
            pass  # fall through to locate the offending matrix
    scale = np.abs(P).max(axis=(-1, -2))
    asym = np.abs(P - np.swapaxes(P, -1, -2)).max(axis=(-1, -2)) > 1e-8 * np.maximum(1.0, scale)
    ok = not np.any(asym)
    if ok:
        try:
            np.linalg.cholesky(P)
        except np.linalg.LinAlgError:
            ok = False
    if ok:
        return
    eig = np.linalg.eigvalsh(symmetric_part(P))[..., 0]
    bad = (eig <= 0) | asym | ~np.isfinite(eig)
    batch = bad.shape
    idx = tuple(int(i) for i in np.argwhere(bad)[0]) if bad.ndim else ()
    raise ValueError(
        f"{_where(what, step, agent, idx, batch)}: {label} is not symmetric positive definite "
        f"(smallest eigenvalue {float(eig[idx]):.3g})"
    )


def _check_overflow(c, P, A, P_prior, step, agent):
    """Refuse a prediction that overflowed floating point, naming A and the prior shape (not a NaN shape)."""
    if np.isfinite(c).all() and np.isfinite(P).all():
        return
    where = "" if step is None else f" at step {step}"
    raise ValueError(
        f"the prediction{where} overflowed floating point (A P A^T is beyond 1e308): A has entries up to "
        f"{float(np.abs(A).max()):.3g} and the shape up to {float(np.abs(P_prior).max()):.3g}; rescale A or the "
        "state units"
    )


#: Largest entry of a prior shape matrix the correction takes: its square stays a float.
_MAX_SHAPE_ENTRY = 1e150


def _check_result(P, what, step, agent, batch):
    try:  # results are symmetric by construction: a Cholesky attempt is the whole test
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        _require_pd(P, what, step, agent, "the new shape matrix")


def _check_pd_small(M, name, size):
    M = check_square(M, name, size)
    try:
        np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        raise ValueError(f"{name} must be symmetric positive definite") from None
    if np.abs(M - M.T).max() > 1e-8 * max(1.0, np.abs(M).max()):
        raise ValueError(f"{name} must be symmetric")
    return M


def _cholesky(P, what, step, agent, idx, batch):
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError as exc:  # pragma: no cover - caught by _check_ellipsoid first
        raise ValueError(f"{_where(what, step, agent, idx, batch)}: shape matrix is not positive definite") from exc


# --------------------------------------------------------------------------------------------
# the methods of the team task (mascore.compare's own-state rendezvous, mascore.agent_cost)

#: Why the set-membership filter of one agent does not apply elsewhere (the tables show it).
_SM_NOT_APPLICABLE = MappingProxyType({
    "target": "a single agent's filter; alone, an agent that senses one coordinate cannot observe the target "
              "(sm-forwarding is the set-membership filter on its neighbourhood's measurements)",
    "localization": "a single agent's filter; without an anchor an agent's relative measurements do not fix it "
                    "(sm-forwarding: on its neighbourhood's measurements)",
})


def _team_set_filter(confidence: float | None):
    """``build(team, x_hat0)``: each agent's closed-form filter of its own state, its noise sets scaled by the scenario.

    ``team.bound_scale(dim, confidence)`` is the scale of the covariance ellipsoid given as the bound (the
    scenario knows its noise: a guaranteed bound for bounded noise, else a confidence level; None: the
    scenario's default level).
    """
    def build(team, x_hat0: np.ndarray) -> SetMembershipModel:
        (m, n) = team.C.shape  # what a measurement holds of the state
        return SetMembershipModel(A=team.A, G=np.eye(n), C=team.C, D=np.eye(m),
                                  Q=team.bound_scale(n, confidence) * team.Q_filter,
                                  R=team.bound_scale(m, confidence) * team.R, B=team.B)
    return build


def _set_membership_spec(name: str, confidence: float | None, position: float, role: str = "recipe") -> MethodSpec:
    return MethodSpec(name, ("team",), _team_set_filter(confidence),
                      lambda n, q, d, N: (float(n), kalman_step_flops(n) + 2 * n**3), {"team": ("O(n^3)", "O(n^2)")},
                      lambda n, q, d, N: float(n**2 + n + d * n), _SM_NOT_APPLICABLE if confidence is None else {},
                      position=position, role=role, family="set-membership", setting=confidence)


#: The set-membership filter at the scenario's confidence level, and at two others (its knob).
METHODS = (_set_membership_spec("set-membership", None, 8), _set_membership_spec("set-membership-c90", 0.9, 9, "knob"),
           _set_membership_spec("set-membership-c99999", 0.99999, 10, "knob"))
