"""The Kalman filter step as pure functions, and filter-consistency statistics.

All functions accept a single filter or a batch: leading axes of ``x`` (``(...,
m)``) and ``P`` (``(..., m, m)``) are broadcast, so N agents' filters or many
Monte Carlo runs advance in one call. Nothing is modified in place, and nothing
is remembered between calls: the functions are safe to call from many threads.

The measurement update uses the Joseph form
``P+ = (I - K H) P (I - K H)^T + K R K^T``, which keeps ``P+`` symmetric
positive semidefinite for any gain and is the form Song et al. (2023) write in
their eq. (20).

Input checks and their cost
---------------------------
The model is checked once, when it is built: :class:`LinearGaussianModel`
checks ``F``, ``Q``, ``H``, ``R`` and ``B`` (shapes, finite entries, symmetric
positive (semi)definite covariances) and keeps read-only copies, so no later
change of the caller's arrays can slip past the check. :func:`predict` and
:func:`update` given such a model check only what changes from call to call:
the shapes of the state, measurement and input, and that the result is finite
(a NaN or inf is traced back to the input that holds it, else reported as an
overflow). An initial covariance is checked in full once, by
:meth:`LinearGaussianModel.check_state`.

The same functions given plain arrays (``predict(x, P, F, Q)``,
``update(x, P, z, H, R)``) check every argument in full on every call (an
eigenvalue decomposition of each covariance), then take the same path; in a
loop, build the model once instead. ``benchmarks/bench_validation.py`` measures
both against the arithmetic alone.

How the step is computed
------------------------
One filter runs on plain matrix products (``ndarray.dot``) and one LAPACK call
for the gain; a batch runs on products of stacks (no einsum) and one stacked
inverse of the innovation covariances. A batch whose covariances are all equal
(Monte Carlo runs of one filter: the covariance does not depend on the data) with
shared model matrices computes the covariance and the gain once and applies the
gain to every mean. The Joseph form's left product
``(I - K H) P`` is formed as ``P - K (H P)`` from the ``H P`` already at hand
(the same rounding-error bound, ``n^2 q`` instead of ``n^3`` flops); its right
factor ``(I - K H)^T`` is formed explicitly, and the result is symmetrized.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._validation import (
    Frozen,
    agent_index,
    check_covariance,
    check_positive_int,
    finite_result,
    frozen_copy,
    symmetric_part,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .agents import is_system, system_matrices
from .estimation import Message, MethodSpec, protocol_docs
from .fusion_cost import kalman_step_flops

__all__ = ["LinearGaussianModel", "predict", "update", "kalman_gain", "run_filter", "nees", "nees_interval",
           "symmetrize"]

_ND = np.ndarray
_F64 = np.dtype(float)


# ----------------------------------------------------------------------------
# the model, checked once
# ----------------------------------------------------------------------------


@protocol_docs
class LinearGaussianModel(Frozen):
    """A linear Gaussian state-space model, checked once, when it is built.

    ``x[k+1] = F x[k] + B u[k] + w[k]``, ``w[k] ~ N(0, Q)``;
    ``z[k] = H x[k] + v[k]``, ``v[k] ~ N(0, R)``.

    The constructor checks every matrix (shapes, finite entries, symmetry and
    definiteness of the covariances) and keeps read-only copies: writing into
    ``model.F`` raises ``ValueError``, and changing the array that was passed in
    does not change the model. :func:`predict` and :func:`update` given a model
    check only the state, measurement and input of each call.

    Parameters
    ----------
    F : (m, m) or (..., m, m) array_like, or LTIAgent or StateSpace
        State-transition matrix, finite, ``m >= 1``; or a discrete-time system (an
        :class:`~mascore.agents.LTIAgent` or a discrete python-control ``StateSpace``): its
        ``A``, and its ``B`` unless `B` is given.
    Q : (m, m) or (..., m, m) array_like
        Process-noise covariance, symmetric positive semidefinite.
    H : (q, m) or (..., q, m) array_like
        Measurement matrix, finite, ``q >= 1``.
    R : (q, q) or (..., q, q) array_like
        Measurement-noise covariance, symmetric positive definite.
    B : (m, p) or (..., m, p) array_like, optional
        Input matrix, finite; needed for a known input ``u`` in :func:`predict`.

    Attributes
    ----------
    F, Q, H, R, B : ndarray (read-only) or None
        The checked matrices (B is None without an input).

    Raises
    ------
    ValueError, TypeError
        A bad matrix, named in the message.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import kalman
    >>> model = kalman.LinearGaussianModel(F=[[1.0, 0.1], [0.0, 1.0]], Q=0.01 * np.eye(2),
    ...                                    H=[[1.0, 0.0]], R=[[0.5]])
    >>> x, P = model.check_state(np.zeros(2), np.eye(2))      # the initial state: checked in full, once
    >>> for z in ([0.3], [0.5]):
    ...     x, P = kalman.update(*kalman.predict(x, P, model), z, model)
    >>> np.round(x, 3)
    array([0.328, 0.066])
    >>> model.F[0, 0] = 2.0
    Traceback (most recent call last):
    ...
    ValueError: assignment destination is read-only
    """

    __slots__ = ("F", "Q", "H", "R", "B", "_eye")

    F: np.ndarray
    Q: np.ndarray
    H: np.ndarray
    R: np.ndarray
    B: np.ndarray | None

    def __init__(self, F: ArrayLike, Q: ArrayLike, H: ArrayLike, R: ArrayLike, B: ArrayLike | None = None) -> None:
        if is_system(F):
            F, B_sys, _ = system_matrices(F, "discrete", name="F", needed_by="LinearGaussianModel, x[k+1] = F x[k] + "
                                          "B u[k] + w[k],")
            B = B_sys if B is None else B
        F, Q, B = _checked_dynamics(F, Q, B)
        H, R = _checked_measurement(H, R, F.shape[-1], f"F of shape {F.shape}")
        self._set(F=frozen_copy(F), Q=frozen_copy(Q), H=frozen_copy(H), R=frozen_copy(R),
                  B=None if B is None else frozen_copy(B), _eye=frozen_copy(np.eye(F.shape[-1])))  # I of Joseph

    def _args(self) -> tuple:
        return (self.F, self.Q, self.H, self.R, self.B)

    def __repr__(self) -> str:
        input_ = "" if self.B is None else f", p = {self.B.shape[-1]} inputs"
        return (f"LinearGaussianModel(m = {self.n_states} states, q = {self.n_measurements} measurements"
                f"{input_})")

    @property
    def n_states(self) -> int:
        """m, the length of the state."""
        return self.F.shape[-1]

    @property
    def n_measurements(self) -> int:
        """q, the length of a measurement."""
        return self.H.shape[-2]

    def check_state(self, x: ArrayLike, P: ArrayLike, names: tuple[str, str] = ("x", "P")) -> tuple[np.ndarray, np.ndarray]:
        """A state for this model, checked in full: what to do once with a filter's initial state.

        Parameters
        ----------
        x : (..., m) array_like
            Mean(s), finite.
        P : (..., m, m) array_like
            Covariance(s), symmetric positive semidefinite.
        names : (str, str)
            The names the error messages use for `x` and `P`.

        Returns
        -------
        x : (..., m) ndarray
        P : (..., m, m) ndarray
            The float arrays (not copies).

        Raises
        ------
        ValueError, TypeError
            A bad mean or covariance, named in the message.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import kalman
        >>> model = kalman.LinearGaussianModel(np.eye(2), 0.1 * np.eye(2), [[1.0, 0.0]], [[1.0]])
        >>> x, P = model.check_state([0.0, 1.0], np.eye(2))
        >>> model.check_state([0.0, 1.0], [[1.0, 2.0], [2.0, 1.0]])
        Traceback (most recent call last):
        ...
        ValueError: P must be positive semidefinite; smallest eigenvalue is -1
        """
        x, P = _checked_state(x, P, *names)
        if x.shape[-1] != self.n_states:
            raise ValueError(f"Incompatible dimensions of {names[0]}; expected (..., {self.n_states}) for the "
                             f"model's F of shape {self.F.shape} but found {x.shape}")
        return x, P

    def predict(self, x: ArrayLike, P: ArrayLike, u: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The prediction of the estimator protocol: ``predict(x, P, model, u)`` (:func:`predict`), this model's.

        Parameters
        ----------
        x : (..., m) array_like
            Estimates.
        P : (..., m, m) array_like
            Their covariances, symmetric positive semidefinite: this fast path checks their shapes and
            finiteness only (check a state from outside once with :meth:`check_state`).
        u : (..., p) array_like, optional
            Known input (the model's ``B`` then needed).

        Returns
        -------
        x_pred : (..., m) ndarray
            Predicted estimates.
        P_pred : (..., m, m) ndarray
            Predicted covariances.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import kalman
        >>> model = kalman.LinearGaussianModel(np.eye(1), 0.1 * np.eye(1), np.eye(1), np.eye(1))
        >>> model.update(*model.predict(np.zeros(1), np.eye(1)), [2.0])[0]     # P- = 1.1, gain 1.1 / 2.1
        array([1.04761905])
        """
        return predict(x, P, self, u)

    def update(self, x: ArrayLike, P: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The update of the estimator protocol: ``update(x, P, z, model)`` (:func:`update`), this model's.

        Parameters
        ----------
        x : (..., m) array_like
            Predicted estimates.
        P : (..., m, m) array_like
            Their covariances, symmetric positive semidefinite: this fast path checks their shapes and
            finiteness only (check a state from outside once with :meth:`check_state`).
        z : (..., q) array_like
            Measurements.

        Returns
        -------
        x_post : (..., m) ndarray
            Updated estimates.
        P_post : (..., m, m) ndarray
            Updated covariances (Joseph form).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import kalman
        >>> model = kalman.LinearGaussianModel(np.eye(1), 0.1 * np.eye(1), np.eye(1), np.eye(1))
        >>> model.update(np.zeros(1), np.eye(1), [1.0])[1]                    # P = 1 - 1/2
        array([[0.5]])
        """
        return update(x, P, z, self)

    def with_measurement(self, H: ArrayLike, R: ArrayLike) -> LinearGaussianModel:
        """The same dynamics with another measurement model (a sensor whose ``H`` or ``R`` changes per step).

        Only `H` and `R` are checked: ``F``, ``Q`` and ``B`` were checked when this model was built
        and are shared, read-only, with the new one, which equals
        ``LinearGaussianModel(F, Q, H, R, B)`` (in a fraction of its time).

        Parameters
        ----------
        H : (q, m) or (..., q, m) array_like
            Measurement matrix, finite, ``q >= 1``.
        R : (q, q) or (..., q, q) array_like
            Measurement-noise covariance, symmetric positive definite.

        Returns
        -------
        LinearGaussianModel
            The model with that measurement.

        Raises
        ------
        ValueError, TypeError
            A bad `H` or `R`, named in the message.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import kalman
        >>> model = kalman.LinearGaussianModel(np.eye(2), 0.1 * np.eye(2), [[1.0, 0.0]], [[1.0]])
        >>> far = model.with_measurement([[1.0, 0.0]], [[4.0]])           # the same sensor, four times the variance
        >>> far == kalman.LinearGaussianModel(np.eye(2), 0.1 * np.eye(2), [[1.0, 0.0]], [[4.0]])
        True
        """
        H, R = _checked_measurement(H, R, self.n_states, f"F of shape {self.F.shape}")
        new = object.__new__(type(self))
        new._set(**{name: getattr(self, name) for name in self.__slots__})
        new._set(H=frozen_copy(H), R=frozen_copy(R))
        return new


    # ------------------------------------------------------------------ one agent's filter (the estimator protocol)

    def agent_inputs(self, x: ArrayLike, P: ArrayLike, z: ArrayLike, u: ArrayLike | None, i: int) -> tuple[dict, tuple]:
        """Agent i's data of one step when every agent runs this Kalman filter on its own state.

        Parameters
        ----------
        x : (N, m) array_like
            The agents' estimates before the step, finite.
        P : (m, m) or (N, m, m) array_like
            Their covariance(s), symmetric positive semidefinite (one shared by all agents, or one each).
        z : (N, q) array_like
            Each agent's own measurement of the step.
        u : (N, p) array_like or None
            The inputs applied (None without ``B``).
        i : int
            The agent.

        Returns
        -------
        own : dict
            Its prior ``x``, ``P``, its measurement ``z`` and input ``u`` (copies).
        messages : tuple
            Empty: the filter uses the agent's own measurement only.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import kalman
        >>> model = kalman.LinearGaussianModel(np.eye(1), 0.1 * np.eye(1), np.eye(1), np.eye(1))
        >>> own, messages = model.agent_inputs(np.zeros((2, 1)), np.eye(1), [[1.0], [3.0]], None, 1)
        >>> own["z"], messages
        (array([3.]), ())
        """
        x, P = self.check_state(x, P)
        z = _finite(_float_array(z, "z"), "z")
        N, q = len(x) if x.ndim else 0, self.n_measurements
        if x.ndim != 2 or P.ndim not in (2, 3) or (P.ndim == 3 and P.shape[0] != N) or z.shape != (N, q):
            raise ValueError(f"Incompatible dimensions of x {x.shape}, P {P.shape} and z {z.shape}; expected one row "
                             f"per agent: x (N, {self.n_states}), P ({self.n_states}, {self.n_states}) or (N, "
                             f"{self.n_states}, {self.n_states}), z (N, {q})")
        i = agent_index(i, N)
        return ({"x": x[i].copy(), "P": (P if P.ndim == 2 else P[i]).copy(), "z": z[i].copy(),
                 "u": None if u is None else np.array(np.asarray(u, dtype=float)[i])}, ())

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        # update with its own measurement, then predict: x_i (m,), P_i (m, m)
        x, P = update(own["x"], own["P"], own["z"], self)
        return predict(x, P, self, own["u"])

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        # nothing
        return ()


def _checked_dynamics(F: ArrayLike, Q: ArrayLike, B: ArrayLike | None, x_shape: tuple | None = None) -> tuple:
    """F (finite, square), Q (symmetric PSD) and B (finite, (..., m, p)), checked in full.

    With `x_shape`, F must fit a mean of that shape (the plain-array :func:`predict`).
    """
    F = _finite(_float_array(F, "F"), "F")
    if F.ndim < 2 or F.shape[-1] != F.shape[-2] or F.shape[-1] == 0:
        raise ValueError(f"F must be a square (m, m) or (..., m, m) matrix with m >= 1; got shape {F.shape}")
    m = F.shape[-1]
    if x_shape is not None and x_shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of F; expected (..., {x_shape[-1]}, {x_shape[-1]}) for x of shape "
                         f"{x_shape} but found {F.shape}")
    Q = check_covariance(Q, "Q", size=m)
    if B is not None:
        B = _finite(_float_array(B, "B"), "B")
        if B.ndim < 2 or B.shape[-2] != m or B.shape[-1] == 0:
            raise ValueError(f"Incompatible dimensions of B; expected (..., {m}, p) with p >= 1 for F of shape "
                             f"{F.shape} but found {B.shape}")
    return F, Q, B


def _checked_measurement(H: ArrayLike, R: ArrayLike, m: int, against: str, q: int | None = None) -> tuple:
    """H (finite, (..., q, m)) and R (symmetric positive definite, (..., q, q)), checked in full.

    `against` says what fixed m (and `q`, if given) for the message.
    """
    H = _finite(_float_array(H, "H"), "H")
    if H.ndim < 2 or H.shape[-1] != m or H.shape[-2] == 0 or (q is not None and H.shape[-2] != q):
        raise ValueError(f"Incompatible dimensions of H; expected (..., {'q' if q is None else q}, {m}) with "
                         f"q >= 1 for {against} but found {H.shape}")
    R = check_covariance(R, "R", definite=True)
    if R.shape[-1] != H.shape[-2]:
        raise ValueError(f"Incompatible dimensions of R {R.shape} for H {H.shape}; expected R (..., q, q) with q = "
                         f"{H.shape[-2]}, the rows of H (one noise covariance row per measurement)")
    return H, R


def _checked_state(x: ArrayLike, P: ArrayLike, xname: str = "x", Pname: str = "P") -> tuple[np.ndarray, np.ndarray]:
    """A mean (..., m) and covariance (..., m, m): finite, P symmetric positive semidefinite."""
    x = _float_array(x, xname)
    P = _float_array(P, Pname)
    if x.ndim < 1 or x.shape[-1] == 0:
        raise ValueError(f"{xname} must be a (..., m) array of state means with m >= 1; got shape {x.shape}")
    m = x.shape[-1]
    if P.ndim < 2 or P.shape[-2:] != (m, m):
        raise ValueError(
            f"Incompatible dimensions of {Pname}; expected (..., {m}, {m}) for {xname} of shape {x.shape} "
            f"but found {P.shape}"
        )
    _finite(x, xname)
    check_covariance(P, Pname, size=m)
    return x, P


# ----------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------


def predict(
    x: ArrayLike,
    P: ArrayLike,
    F: LinearGaussianModel | ArrayLike,
    Q: ArrayLike | None = None,
    B: ArrayLike | None = None,
    u: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Time update ``x- = F x + B u``, ``P- = F P F^T + Q``.

    Two forms: ``predict(x, P, model, u=None)`` with a :class:`LinearGaussianModel`
    (checked when it was built; each call checks the shapes of `x`, `P`, `u` and
    that the result is finite) and ``predict(x, P, F, Q, B=None, u=None)`` with
    plain arrays, which checks every argument in full on every call (in a loop,
    build the model once instead). Both give the same numbers.

    Parameters
    ----------
    x : (..., m) array_like
        Prior mean(s), finite.
    P : (..., m, m) array_like
        Prior covariance(s), symmetric positive semidefinite.
    F : LinearGaussianModel, or (m, m) or (..., m, m) array_like
        The model, or the state-transition matrix (finite).
    Q : (m, m) or (..., m, m) array_like
        Process-noise covariance, symmetric positive semidefinite. With a model:
        the input `u`, if given positionally (``predict(x, P, model, u)``).
    B : (m, p) array_like, optional
        Input matrix; with plain arrays, required with `u` (a model holds its own).
    u : (..., p) array_like, optional
        Known input (with a model: none means no input this step).

    Returns
    -------
    x_pred : (..., m) ndarray
    P_pred : (..., m, m) ndarray

    Raises
    ------
    ValueError, TypeError
        A bad argument (named in the message), or a result that overflowed.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import kalman
    >>> F = [[1.0, 0.1], [0.0, 1.0]]                           # position, velocity, dt = 0.1 s
    >>> x, P = kalman.predict([0.0, 1.0], np.eye(2), F, 0.01 * np.eye(2))
    >>> x, np.round(P, 3)
    (array([0.1, 1. ]), array([[1.02, 0.1 ],
           [0.1 , 1.01]]))
    >>> model = kalman.LinearGaussianModel(F, 0.01 * np.eye(2), H=[[1.0, 0.0]], R=[[0.5]])  # checked once
    >>> x2, P2 = kalman.predict([0.0, 1.0], np.eye(2), model)
    >>> bool(np.array_equal(x2, x) and np.array_equal(P2, P))
    True
    """
    if isinstance(F, LinearGaussianModel):  # checked when built: only what changes per call is checked below
        if B is not None or (Q is not None and u is not None):
            raise TypeError("with a LinearGaussianModel, call predict(x, P, model, u=None): F, Q and B are the "
                            "model's")
        F, Q, B, u = F.F, F.Q, F.B, (Q if u is None else u)
        if type(x) is not _ND or x.dtype is not _F64:
            x = _float_array(x, "x")
        if type(P) is not _ND or P.dtype is not _F64:
            P = _float_array(P, "P")
    else:  # plain arrays: every argument checked in full
        x, P = _checked_state(x, P)
        F, Q, B = _checked_dynamics(F, Q, B, x.shape)
        if (u is None) != (B is None):
            raise ValueError("B and u must be given together (B alone or u alone cannot form B u)")
        if u is not None:
            u = _finite(_float_array(u, "u"), "u")
    m = F.shape[-1]
    if x.ndim == 0 or x.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of x; expected (..., {m}) for F of shape {F.shape} "
                         f"but found {x.shape}")
    if P.shape[-2:] != (m, m):
        raise ValueError(f"Incompatible dimensions of P; expected (..., {m}, {m}) for F of shape {F.shape} "
                         f"but found {P.shape}")
    if u is not None:
        if B is None:
            raise ValueError("an input u needs an input matrix B; this model has none")
        u = _float_array(u, "u")
        if u.ndim == 0 or B.shape[-1] != u.shape[-1]:
            raise ValueError(f"Incompatible dimensions of u; expected (..., {B.shape[-1]}) for B of shape {B.shape} "
                             f"but found {u.shape}")
    if x.ndim == 1 and P.ndim == 2 and F.ndim == 2 and Q.ndim == 2 and (u is None or (u.ndim == 1 and B.ndim == 2)):
        x_pred, P_pred, ok = _predict_one(x, P, F, Q, B, u)
    else:
        try:
            np.broadcast_shapes(x.shape[:-1], P.shape[:-2])  # the estimates and their covariances: one batch
            x_pred, P_pred, ok = _predict_stack(x, P, F, Q, B, u)
        except ValueError as exc:  # leading (batch) axes that do not broadcast
            raise ValueError(
                f"the batch axes of x {x.shape}, P {P.shape}, F {F.shape}, Q {Q.shape}"
                f"{'' if u is None else f', u {u.shape}'} do not broadcast ({exc})"
            ) from None
    if not ok:  # NaN/inf passed in is named; else an overflow (or a false alarm of the quick test)
        finite_result("Kalman prediction", x_pred, P_pred, inputs=((x, "x"), (P, "P"), (u, "u")))
    return x_pred, P_pred


def update(
    x: ArrayLike, P: ArrayLike, z: ArrayLike, H: LinearGaussianModel | ArrayLike, R: ArrayLike | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Measurement update in Joseph form.

    Two forms: ``update(x, P, z, model)`` with a :class:`LinearGaussianModel`
    (checked when it was built; each call checks the shapes of `x`, `P`, `z` and
    that the result is finite) and ``update(x, P, z, H, R)`` with plain arrays,
    which checks every argument in full on every call (in a loop, build the model
    once instead). Both give the same numbers.

    Parameters
    ----------
    x : (..., m) array_like
        Predicted mean(s), finite.
    P : (..., m, m) array_like
        Predicted covariance(s), symmetric positive semidefinite.
    z : (..., q) array_like
        Measurement(s), finite.
    H : LinearGaussianModel, or (q, m) or (..., q, m) array_like
        The model, or the measurement matrix (finite).
    R : (q, q) or (..., q, q) array_like
        Measurement-noise covariance, symmetric positive definite (not with a model).

    Returns
    -------
    x_post : (..., m) ndarray
    P_post : (..., m, m) ndarray
        Symmetric positive semidefinite by construction (Joseph form).

    Raises
    ------
    ValueError, TypeError
        A bad argument (named in the message), or a result that overflowed.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import kalman
    >>> x, P = kalman.update([0.0, 1.0], np.eye(2), z=[2.0], H=[[1.0, 0.0]], R=[[1.0]])
    >>> x, np.round(P, 3)                                     # halfway to the measurement, half the variance
    (array([1., 1.]), array([[0.5, 0. ],
           [0. , 1. ]]))
    >>> model = kalman.LinearGaussianModel(np.eye(2), np.zeros((2, 2)), H=[[1.0, 0.0]], R=[[1.0]])
    >>> x2, P2 = kalman.update([0.0, 1.0], np.eye(2), [2.0], model)
    >>> bool(np.array_equal(x2, x) and np.array_equal(P2, P))
    True
    """
    if isinstance(H, LinearGaussianModel):  # checked when built: only what changes per call is checked below
        if R is not None:
            raise TypeError("with a LinearGaussianModel, call update(x, P, z, model): H and R are the model's")
        H, R, I = H.H, H.R, H._eye
        if type(x) is not _ND or x.dtype is not _F64:
            x = _float_array(x, "x")
        if type(P) is not _ND or P.dtype is not _F64:
            P = _float_array(P, "P")
        if type(z) is not _ND or z.dtype is not _F64:
            z = _float_array(z, "z")
    else:  # plain arrays: every argument checked in full
        x, P = _checked_state(x, P)
        z = _finite(_float_array(z, "z"), "z")
        if z.ndim < 1:
            raise ValueError(f"z must be a (..., q) array of measurements; got shape {z.shape}")
        q_z = z.shape[-1]  # blame H for a row count that z and R agree on, else z (checked against H below)
        R = _float_array(R, "R")
        q = q_z if R.ndim >= 2 and R.shape[-1] == q_z else None
        H, R = _checked_measurement(H, R, x.shape[-1], f"x of shape {x.shape} and z of shape {z.shape}", q)
        I = np.eye(x.shape[-1])
    q, m = H.shape[-2:]
    if x.ndim == 0 or x.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of x; expected (..., {m}) for H of shape {H.shape} "
                         f"but found {x.shape}")
    if P.shape[-2:] != (m, m):
        raise ValueError(f"Incompatible dimensions of P; expected (..., {m}, {m}) for H of shape {H.shape} "
                         f"but found {P.shape}")
    if z.ndim == 0 or z.shape[-1] != q:
        raise ValueError(f"Incompatible dimensions of z; expected (..., {q}) for H of shape {H.shape} "
                         f"but found {z.shape}")
    try:
        if x.ndim == 1 and P.ndim == 2 and H.ndim == 2 and R.ndim == 2 and z.ndim == 1:
            x_post, P_post, ok = _update_one(x, P, z, H, R, I)
        else:
            x_post, P_post, ok = _update_stack(x, P, z, H, R, I)
    except np.linalg.LinAlgError:
        raise ValueError("the innovation covariance H P H^T + R is singular: P must be symmetric positive "
                         "semidefinite") from None
    except ValueError as exc:  # leading (batch) axes that do not broadcast
        raise ValueError(
            f"the batch axes of x {x.shape}, P {P.shape}, z {z.shape}, H {H.shape}, R {R.shape} "
            f"do not broadcast ({exc})"
        ) from None
    if not ok:  # NaN/inf passed in is named; else an overflow (or a false alarm of the quick test)
        finite_result("Kalman update", x_post, P_post, inputs=((x, "x"), (P, "P"), (z, "z")))
    return x_post, P_post


def kalman_gain(P: ArrayLike, H: ArrayLike, R: ArrayLike) -> np.ndarray:
    """Optimal gain ``K = P H^T (H P H^T + R)^{-1}``, shape ``(..., m, q)``.

    Parameters
    ----------
    P : (..., m, m) array_like
        Predicted covariance, symmetric positive semidefinite.
    H : (q, m) or (..., q, m) array_like
        Measurement matrix.
    R : (q, q) or (..., q, q) array_like
        Measurement-noise covariance, symmetric positive semidefinite; the
        innovation covariance ``H P H^T + R`` must be invertible.

    Returns
    -------
    (..., m, q) ndarray
        The gain.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import kalman
    >>> kalman.kalman_gain(np.eye(2), [[1.0, 0.0]], [[1.0]])       # equal prior and noise: gain 1/2
    array([[0.5],
           [0. ]])
    """
    P = _float_array(P, "P")
    if P.ndim < 2 or P.shape[-1] == 0:
        raise ValueError(f"P must be a (..., m, m) covariance with m >= 1; got shape {P.shape}")
    m = P.shape[-1]
    check_covariance(P, "P", size=m)
    H = _finite(_float_array(H, "H"), "H")
    if H.ndim < 2 or H.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of H and P; H must be (..., q, m) for P (..., m, m) = {P.shape} "
                         f"but found {H.shape}")
    R = check_covariance(R, "R")
    if R.shape[-1] != H.shape[-2]:
        raise ValueError(f"Incompatible dimensions of H {H.shape} and R {R.shape}: H must be (..., q, m) "
                         f"and R (..., q, q) with the same q")
    try:
        K = _gain(P, H, R)
    except np.linalg.LinAlgError:
        K = None
    except ValueError as exc:  # leading (batch) axes that do not broadcast
        raise ValueError(f"the batch axes of P {P.shape}, H {H.shape}, R {R.shape} do not broadcast ({exc})") from None
    if K is None or not np.isfinite(K).all():
        raise ValueError(
            "the innovation covariance H P H^T + R is singular (or the gain overflowed): "
            "R must be positive definite where H P H^T is not"
        )
    return K



def nees(error: ArrayLike, P: ArrayLike) -> np.ndarray:
    """Normalized estimation error squared ``e^T P^{-1} e``.

    Parameters
    ----------
    error : (..., m) array_like
        Estimation error(s) ``x_true - x_hat``, finite.
    P : (..., m, m) array_like
        The filter's covariance(s), symmetric positive definite.

    Returns
    -------
    (...) ndarray
        Chi-square distributed with m degrees of freedom for a consistent
        Gaussian filter (dimensionless).

    Raises
    ------
    ValueError
        Bad shapes, NaN/inf, a `P` that is not symmetric positive definite, or a
        NEES beyond floating point (``e^T P^{-1} e > 1e308``: rescale the units).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import kalman
    >>> float(kalman.nees([1.0, 2.0], np.diag([1.0, 4.0])))    # 1/1 + 4/4
    2.0
    """
    e = _float_array(error, "error")
    if e.ndim < 1 or e.shape[-1] == 0:
        raise ValueError(f"error must be a (..., m) array with m >= 1; got shape {e.shape}")
    _finite(e, "error")
    m = e.shape[-1]
    P = _float_array(P, "P")
    if P.ndim < 2 or P.shape[-2:] != (m, m):
        raise ValueError(
            f"Incompatible dimensions of error {e.shape} and P {P.shape}; P must be (..., m, m) for error (..., m)"
        )
    check_covariance(P, "P", size=m, definite=True)
    try:
        np.broadcast_shapes(e.shape[:-1], P.shape[:-2])
    except ValueError:
        raise ValueError(f"the batch axes of error {e.shape} and P {P.shape} do not broadcast") from None
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])
    if not np.isfinite(out).all():
        raise ValueError(
            f"the NEES overflows floating point (beyond 1e308): error has entries up to {float(np.abs(e).max()):.3g} "
            f"for a covariance P whose diagonal is down to {float(np.diagonal(P, axis1=-2, axis2=-1).min()):.3g}; "
            "rescale the state units (the NEES is unit-free)"
        )
    return out


def nees_interval(dof: int, n_runs: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided interval for the NEES averaged over `n_runs` independent runs.

    ``n_runs * mean(NEES)`` is chi-square with ``n_runs * dof`` degrees of
    freedom (Bar-Shalom, Li and Kirubarajan 2001, Sec. 5.4).

    Parameters
    ----------
    dof : int
        State dimension m (>= 1).
    n_runs : int
        Number of runs averaged (>= 1).
    confidence : float
        Probability in the open interval (0, 1).

    Returns
    -------
    (low, high) : tuple of float
        Bounds on the *average* NEES.

    Examples
    --------
    >>> from mascore import kalman
    >>> low, high = kalman.nees_interval(dof=4, n_runs=100)
    >>> round(low, 2), round(high, 2)
    (3.46, 4.57)
    """
    from scipy import stats

    dof = check_positive_int(dof, "dof")
    n_runs = check_positive_int(n_runs, "n_runs")
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float, np.integer, np.floating)):
        raise TypeError(f"confidence must be a real number in (0, 1); got {type(confidence).__name__} {confidence!r}")
    if not 0 < confidence < 1:  # also refuses NaN
        raise ValueError(f"confidence must lie in (0, 1); got {confidence}")
    tail = (1 - confidence) / 2
    total = dof * n_runs
    return (
        float(stats.chi2.ppf(tail, total) / n_runs),
        float(stats.chi2.ppf(1 - tail, total) / n_runs),
    )


def symmetrize(P: ArrayLike) -> np.ndarray:
    """``(P + P^T) / 2`` over the last two axes.

    Parameters
    ----------
    P : (..., n, n) array_like
        Finite square matrices.

    Returns
    -------
    (..., n, n) ndarray
        Their symmetric parts.

    Examples
    --------
    >>> from mascore import kalman
    >>> kalman.symmetrize([[1.0, 2.0], [0.0, 1.0]])
    array([[1., 1.],
           [1., 1.]])
    """
    P = _float_array(P, "P")
    if P.ndim < 2 or P.shape[-1] != P.shape[-2]:
        raise ValueError(f"P must be a (..., n, n) array of square matrices; got shape {P.shape}")
    return symmetric_part(_finite(P, "P"))




def run_filter(
    x0: ArrayLike,
    P0: ArrayLike,
    z: ArrayLike,
    F: LinearGaussianModel | ArrayLike,
    Q: ArrayLike | None = None,
    H: ArrayLike | None = None,
    R: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A whole Kalman filter run: predict then update for each measurement.

    The model and the initial state are checked in full once, at the start; each
    step is :func:`predict` and :func:`update` on the checked model, so the result
    is, bit for bit, that of such a loop.

    Parameters
    ----------
    x0 : (..., m) array_like
        Initial mean(s), finite (a leading batch shape runs several filters at once).
    P0 : (..., m, m) array_like
        Initial covariance(s), symmetric positive semidefinite.
    z : (K, ..., q) array_like
        Measurements of steps 1..K, finite.
    F : LinearGaussianModel, or (m, m) array_like
        The model (then `Q`, `H`, `R` are not given), or the transition matrix.
    Q : (m, m) array_like
        Process noise covariance (positive semidefinite).
    H, R : (q, m), (q, q) array_like
        Measurement matrix and noise covariance (positive definite).

    Returns
    -------
    x : (K, ..., m) ndarray
        Posterior means after each measurement.
    P : (K, ..., m, m) ndarray
        Posterior covariances.

    Raises
    ------
    ValueError
        Bad shapes, non-finite entries, an indefinite covariance, or a run that overflows.

    Examples
    --------
    >>> import numpy as np
    >>> x, P = run_filter([0.0], [[1.0]], np.ones((3, 1)), [[1.0]], [[0.0]], [[1.0]], [[1.0]])
    >>> np.round(x[:, 0], 4).tolist(), float(np.round(P[-1, 0, 0], 4))
    ([0.5, 0.6667, 0.75], 0.25)
    """
    if isinstance(F, LinearGaussianModel):
        if Q is not None or H is not None or R is not None:
            raise TypeError("with a LinearGaussianModel, call run_filter(x0, P0, z, model): Q, H and R are the "
                            "model's")
        model = F
    else:
        model = LinearGaussianModel(F, Q, H, R)
    x, P = model.check_state(x0, P0, ("x0", "P0"))
    z = _finite(_float_array(z, "z"), "z")
    q = model.n_measurements
    if z.ndim < 1 or z.shape[-1] != q or z.shape[1:-1] != x.shape[:-1]:
        raise ValueError(f"Incompatible dimensions of z {z.shape} and x0 {x.shape}; expected z (K, *batch, {q}) with "
                         f"the batch axes {x.shape[:-1]} of x0 (x0 (*batch, {model.n_states}))")
    xs = np.empty((z.shape[0], *x.shape))
    Ps = np.empty((z.shape[0], *P.shape))
    for k in range(z.shape[0]):
        x, P = predict(x, P, model)
        x, P = update(x, P, z[k], model)
        xs[k], Ps[k] = x, P
    return xs, Ps


# ----------------------------------------------------------------------------
# kernels (on checked arguments; each returns its result and whether it is finite)
# ----------------------------------------------------------------------------


def _shared_covariance(P: np.ndarray, *model: np.ndarray) -> np.ndarray | None:
    """The one covariance of a stack whose matrices are all equal, with shared 2-D model matrices; else None.

    The test reads the stack once (``B n^2``), against the ``B n^3`` of the stacked products it saves.
    """
    if P.ndim < 3 or any(M is not None and M.ndim != 2 for M in model):
        return None
    flat = P.reshape(-1, *P.shape[-2:])
    return flat[0] if flat.shape[0] > 1 and (flat == flat[0]).all() else None


def _add_into(A, B):
    """``A + B``, in A's storage (a fresh temporary) when the shapes allow."""
    if B.ndim <= A.ndim and (A.shape[A.ndim - B.ndim:] == B.shape or np.broadcast_shapes(A.shape, B.shape) == A.shape):
        A += B
        return A
    return A + B


def _finite_test(x, P):
    """False if x or P holds NaN/inf (or if the test itself overflows: then the exact test decides)."""
    return math.isfinite(np.vdot(x, x) + np.vdot(P, P))


# A NaN/inf input or an overflow surfaces as a non-finite result, which the caller refuses by name: no warning on
# the way. (As a decorator, np.errstate costs half of what the context manager does; numpy >= 2 keeps its state
# per thread and per call.)


@np.errstate(invalid="ignore", over="ignore")
def _predict_one(x, P, F, Q, B, u):
    """One filter (x (m,), P, F, Q (m, m), u (p,) or None): the prediction and whether it is finite."""
    x_pred = F.dot(x) if u is None else F.dot(x) + B.dot(u)
    P_pred = F.dot(P).dot(F.T)
    P_pred += Q
    P_out = P_pred.T.copy()  # (P + P^T) / 2; a contiguous copy of P^T adds faster than the transposed view
    P_out += P_pred
    P_out *= 0.5
    # NaN/inf anywhere makes this NaN/inf; so does an overflow of the squares (then the exact test decides)
    return x_pred, P_out, math.isfinite(x_pred.dot(x_pred) + np.vdot(P_out, P_out))  # _finite_test, inlined


@np.errstate(invalid="ignore", over="ignore")
def _predict_stack(x, P, F, Q, B, u):
    """:func:`_predict_one` with batch axes (products on stacks, no einsum)."""
    one = _shared_covariance(P, F, Q, B)
    if one is not None:  # every filter of the batch has this covariance: propagate it once
        x_pred = x @ F.T if u is None else x @ F.T + u @ B.T
        _, P1, _ = _predict_one(x.reshape(-1, x.shape[-1])[0], one, F, Q, None, None)
        P_out = np.broadcast_to(P1, P.shape).copy()  # the batch shape of P, as the stacked products give
        return x_pred, P_out, _finite_test(x_pred, P1)
    Ft = np.swapaxes(F, -1, -2)
    x_pred = x @ Ft if F.ndim == 2 else (F @ x[..., None])[..., 0]
    if u is not None:
        x_pred = x_pred + (u @ B.T if B.ndim == 2 else (B @ u[..., None])[..., 0])
    P_pred = (F @ P) @ np.ascontiguousarray(Ft)  # a contiguous right factor: faster stacked products
    P_out = _symmetrize_fresh(_add_into(P_pred, Q))
    return x_pred, P_out, _finite_test(x_pred, P_out)


def _gain(P, H, R):
    """:func:`kalman_gain` on checked arguments."""
    S = H @ P @ np.swapaxes(H, -1, -2) + R
    # K^T = S^{-1} H P because S and P are symmetric
    return np.swapaxes(np.linalg.solve(S, H @ P), -1, -2)


def _solve_one(S: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``S^{-1} B`` for one (q, q) system, through LAPACK without numpy's gufunc overhead.

    Small q: posv (Cholesky; gesv, what np.linalg.solve calls, if S is not numerically positive
    definite). From q = 16 on, the LU inverse and one matrix
    product are quicker than gesv's triangular solves with many right-hand sides (the gain's
    rounding differs at the eps * cond(S) level; the Joseph form is insensitive to it to first order).
    """
    from scipy.linalg import lapack  # imported on first use (import mascore.kalman stays light)

    if S.shape[0] < 16:
        X, info = lapack.dposv(S, B)[1:]  # Cholesky: S is positive definite (R is)
        if info:  # not numerically: LU with pivoting decides
            X, info = lapack.dgesv(S, B)[2:]
    else:
        lu, piv, info = lapack.dgetrf(S)
        if not info:
            Si, info = lapack.dgetri(lu, piv)
            X = Si.dot(B)
    if info:
        raise np.linalg.LinAlgError("Singular matrix")
    return X


@np.errstate(invalid="ignore", over="ignore")
def _update_one(x, P, z, H, R, I):
    """One filter (x (m,), z (q,), P, H, R matrices; I the (m, m) identity): the Joseph update and whether it is
    finite."""
    HP = H.dot(P)
    S = HP.dot(H.T)
    S += R
    K = _solve_one(S, HP).T  # K^T = S^{-1} H P (S, P symmetric)
    x_post = x + K.dot(z - H.dot(x))
    # Joseph form (I - K H) P (I - K H)^T + K R K^T, its left product (I - K H) P formed as P - K (H P) from
    # the H P at hand (the same rounding error bound, eps |K| |H| |P|, with n^2 q instead of n^3 flops)
    AP = P - K.dot(HP)
    P_post = AP.dot((I - K.dot(H)).T)
    P_post += K.dot(R).dot(K.T)
    P_out = P_post.T.copy()  # (P + P^T) / 2; a contiguous copy of P^T adds faster than the transposed view
    P_out += P_post
    P_out *= 0.5
    return x_post, P_out, math.isfinite(x_post.dot(x_post) + np.vdot(P_out, P_out))  # as in _predict_one


@np.errstate(invalid="ignore", over="ignore")
def _update_stack(x, P, z, H, R, I):
    """:func:`_update_one` with batch axes (products on stacks, no einsum)."""
    one = _shared_covariance(P, H, R)
    if one is not None:  # one covariance for the batch: one gain, applied to every mean
        HP = H.dot(one)
        K = _solve_one(HP.dot(H.T) + R, HP).T
        x_post = x + (z - x @ H.T) @ K.T
        batch = np.broadcast_shapes(x_post.shape[:-1], P.shape[:-2])
        if x_post.shape[:-1] != batch:
            x_post = np.broadcast_to(x_post, (*batch, x_post.shape[-1])).copy()
        _, P1, _ = _update_one(np.zeros(one.shape[0]), one, np.zeros(H.shape[0]), H, R, I)
        P_out = np.broadcast_to(P1, (*batch, *P1.shape)).copy()
        return x_post, P_out, _finite_test(x_post, P1)
    Ht = np.ascontiguousarray(np.swapaxes(H, -1, -2))
    HP = H @ P
    # K^T = S^{-1} H P (S, P symmetric); on stacks of small matrices the inverse and a product are quicker than
    # np.linalg.solve (whose triangular solves with many right-hand sides are slow)
    KT = np.linalg.inv(_add_into(HP @ Ht, R)) @ HP
    K = np.swapaxes(KT, -1, -2)
    innovation = z - (x @ Ht if H.ndim == 2 else (H @ x[..., None])[..., 0])
    x_post = x + (innovation[..., None, :] @ KT)[..., 0, :]
    # Joseph form (I - K H) P (I - K H)^T + K R K^T, as in _update_one: (I - K H) P = P - K (H P), and
    # (I - K H)^T = I - H^T K^T formed contiguous
    At = Ht @ KT
    np.subtract(I, At, out=At)
    AP = K @ HP
    AP = np.subtract(P, AP, out=AP) if AP.shape == np.broadcast_shapes(AP.shape, P.shape) else P - AP
    P_post = _add_into(AP @ At, (K @ R) @ KT)
    P_out = _symmetrize_fresh(P_post)
    return x_post, P_out, _finite_test(x_post, P_out)


def _symmetrize_fresh(P):
    """``(P + P^T) / 2`` of a freshly computed array (a contiguous copy of P^T adds faster than the view)."""
    out = np.swapaxes(P, -1, -2).copy()
    out += P
    out *= 0.5
    return out


# ----------------------------------------------------------------------------
# the method of the team task (mascore.compare's own-state rendezvous, mascore.agent_cost)
# ----------------------------------------------------------------------------

#: ``local``: every agent's Kalman filter of its own state from its own full-state measurement.
METHODS = (
    MethodSpec("local", ("team",), lambda team, x_hat0: LinearGaussianModel(team.A, team.Q_filter, team.C, team.R, team.B),
               lambda n, q, d, N: (float(n), kalman_step_flops(n)), {"team": ("O(n^3)", "O(n^2)")},
               lambda n, q, d, N: float(n**2 + n + d * n), position=1),
)
