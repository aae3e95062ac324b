"""The Kalman filter step as pure functions, and filter-consistency statistics.

All functions accept a single filter or a batch: leading axes of ``x`` (``(...,
m)``) and ``P`` (``(..., m, m)``) are broadcast, so N agents' filters or many
Monte Carlo runs advance in one call. Nothing is modified in place.

The measurement update uses the Joseph form
``P+ = (I - K H) P (I - K H)^T + K R K^T``, which keeps ``P+`` symmetric
positive semidefinite for any gain and is the form Song et al. (2023) write in
their eq. (20).

Input checks and their cost
---------------------------
Every public function checks its arguments (shapes, finite entries, symmetric
positive (semi)definite covariances) and raises a ``ValueError``/``TypeError``
that names the argument; a result that is not finite (an overflow) raises too.
:func:`predict` and :func:`update` are called in long loops, so they pay each
full check once: the constant matrices (``F``, ``Q``, ``B``, ``H``, ``R``) are
checked once per distinct value (remembered by their bytes), and the mean and
covariance that one of these two functions returned are recognised when they
come back as the next call's arguments (the same objects, still holding the
same bytes: an array modified in place is checked again). What remains per call
is a few comparisons and the NaN/inf test of the result;
``benchmarks/bench_validation.py`` measures it against the unchecked kernels
:func:`_predict` and :func:`_update`, which compute the same numbers.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ._validation import cached_covariance as _const_covariance
from ._validation import cached_finite as _const_finite
from ._validation import check_covariance, check_positive_int
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite

__all__ = ["predict", "update", "kalman_gain", "run_filter", "nees", "nees_interval", "symmetrize"]


# ----------------------------------------------------------------------------
# private helpers, also used by the other core modules (candidates for _validation)
# ----------------------------------------------------------------------------

_ND = np.ndarray
_F64 = np.dtype(float)


class _RecentArrays:
    """The last few arrays that passed a check (or were computed from checked input), with their bytes.

    An argument is recognised if it *is* one of them (identity) and still holds
    the same bytes (not modified in place since): a long run that feeds a result
    back in, or calls a step again with the same arguments, pays a copy and a
    comparison instead of the full check. Least recently used entries go first.
    """

    __slots__ = ("_items", "_n", "_max_bytes")

    def __init__(self, n: int = 16, max_bytes: int = 1 << 24) -> None:
        self._items: list[tuple[np.ndarray, bytes, tuple]] = []
        self._n = n
        self._max_bytes = max_bytes

    def remember(self, arr: np.ndarray) -> np.ndarray:
        if type(arr) is _ND and arr.nbytes <= self._max_bytes:
            self._items.insert(0, (arr, arr.tobytes(), arr.shape))
            del self._items[self._n:]
        return arr

    def __contains__(self, arr: object) -> bool:
        items = self._items
        for i, item in enumerate(items):
            if item[0] is arr:
                ok = arr.shape == item[2] and arr.tobytes() == item[1]
                if ok and i and i < len(items) and items[i] is item:  # most recently used first
                    del items[i]
                    items.insert(0, item)
                return ok
        return False


# A long run calls predict and update with the state the previous call returned and with the same
# model matrices. Both are recognised cheaply, so that the run pays each full check once:
# * _RECENT_STATES holds the last few (x, P) results, finite and P symmetric PSD, with their bytes: an
#   argument that *is* one of them (identity) and still holds the same bytes (not modified in place)
#   needs no scan;
# * _LAST_MODELS holds, per step kind, the last checked model matrices with their bytes (same test);
#   other model matrices go through the value-keyed memos of _const_finite and _const_covariance.
_RECENT_STATES: list[tuple] = []
_NO_STATE = (object(), object(), b"", b"")  # matches no argument
_N_RECENT = 8
_MAX_REMEMBERED_BYTES = 1 << 22
_LAST_MODELS: dict[str, tuple] = {}
#: Results up to this many bytes are tested for NaN/inf by a Python sum over their bytes (no numpy call).
_SMALL_BYTES = 2048


def _recognised_state(x: object, P: object) -> bool:
    """True if (x, P) is a result of :func:`predict`/:func:`update`, unmodified since."""
    for ox, oP, xb, Pb in _RECENT_STATES:
        if ox is x and oP is P:
            return x.tobytes() == xb and P.tobytes() == Pb
    return False


def _check_predict_model(F: ArrayLike, Q: ArrayLike, B: ArrayLike | None) -> tuple:
    """Check F (finite, square), Q (covariance) and B (finite), each once per distinct value."""
    F = _const_finite(F, "F")
    if F.ndim < 2 or F.shape[-1] != F.shape[-2] or F.shape[-1] == 0:
        raise ValueError(f"F must be a square (m, m) or (..., m, m) matrix with m >= 1; got shape {F.shape}")
    Q = _const_covariance(Q, "Q")
    if B is not None:
        B = _const_finite(B, "B")
        if B.ndim < 2:
            raise ValueError(f"B must be an (m, p) matrix; got shape {B.shape}")
    _LAST_MODELS["p"] = (F, Q, B, F.tobytes(), Q.tobytes(), None if B is None else B.tobytes())
    return F, Q, B


def _check_update_model(H: ArrayLike, R: ArrayLike) -> tuple:
    """Check H (finite) and R (positive definite covariance), each once per distinct value."""
    H = _const_finite(H, "H")
    if H.ndim < 2:
        raise ValueError(f"H must be a (q, m) or (..., q, m) matrix; got shape {H.shape}")
    R = _const_covariance(R, "R", definite=True)
    _LAST_MODELS["u"] = (H, R, H.tobytes(), R.tobytes())
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


def _checked_result(x: np.ndarray, P: np.ndarray, what: str, fresh: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Refuse a non-finite result, naming the cause; remember a finite one as a checked state.

    `fresh` holds ``(array, name)`` pairs of inputs that change at every step (a
    measurement, an input) and were not scanned: a NaN or inf in them reaches
    the result, so they are scanned only when the result is not finite.
    """
    xb, Pb = x.tobytes(), P.tobytes()
    # NaN/inf anywhere makes a sum NaN/inf; so does an overflow of the sum itself (then the exact test decides)
    if len(xb) + len(Pb) <= _SMALL_BYTES:
        ok = math.isfinite(sum(memoryview(xb + Pb).cast("d")))
    else:
        ok = math.isfinite(x.sum()) and math.isfinite(P.sum())
    if not ok and not (np.isfinite(x).all() and np.isfinite(P).all()):
        for arr, name in fresh:
            _finite(arr, name)
        raise ValueError(
            f"the {what} overflowed (NaN or inf in the result) although every input is finite: "
            "the values are too large to be represented in floating point; rescale the problem"
        )
    if len(xb) + len(Pb) <= _MAX_REMEMBERED_BYTES:
        _RECENT_STATES.insert(0, (x, P, xb, Pb))
        del _RECENT_STATES[_N_RECENT:]
    return x, P


# ----------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------


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
        Prior mean(s), finite.
    P : (..., m, m) array_like
        Prior covariance(s), symmetric positive semidefinite.
    F : (m, m) or (..., m, m) array_like
        State-transition matrix, finite.
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
    """
    # model and state recognised by identity and bytes (see _RECENT_STATES), else checked in full
    last = _LAST_MODELS.get("p")
    if (last is None or F is not last[0] or Q is not last[1] or B is not last[2]
            or F.tobytes() != last[3] or Q.tobytes() != last[4] or (B is not None and B.tobytes() != last[5])):
        F, Q, B = _check_predict_model(F, Q, B)
    r = _RECENT_STATES[0] if _RECENT_STATES else _NO_STATE  # the usual case: the last result comes back
    if (x is not r[0] or P is not r[1] or x.tobytes() != r[2] or P.tobytes() != r[3]) and not _recognised_state(x, P):
        x, P = _checked_state(x, P)
    m = x.shape[-1]
    if F.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of F; expected (..., {m}, {m}) for x of shape {x.shape} "
                         f"but found {F.shape}")
    if Q.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of Q; expected (..., {m}, {m}) for x of shape {x.shape} "
                         f"but found {Q.shape}")
    if u is not None or B is not None:
        if u is None or B is None:
            raise ValueError("B and u must be given together (B alone or u alone cannot form B u)")
        u = _float_array(u, "u")  # scanned only if the result is not finite (a NaN in u reaches x_pred)
        if B.shape[-2] != m or u.ndim < 1 or B.shape[-1] != u.shape[-1]:
            raise ValueError(
                f"Incompatible dimensions of B {B.shape} and u {u.shape}; expected B ({m}, p) and u (..., p)"
            )
    try:
        out = _predict(x, P, F, Q, B, u)
    except ValueError as exc:  # leading (batch) axes that do not broadcast
        raise ValueError(
            f"the batch axes of x {x.shape}, P {P.shape}, F {F.shape}, Q {Q.shape}"
            f"{'' if u is None else f', u {u.shape}'} do not broadcast ({exc})"
        ) from None
    return _checked_result(*out, "prediction", () if u is None else ((u, "u"),))


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
    H = _const_finite(H, "H")
    if H.ndim < 2 or H.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of H and P; H must be (..., q, m) for P (..., m, m) = {P.shape} "
                         f"but found {H.shape}")
    R = _const_covariance(R, "R")
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


def update(
    x: ArrayLike, P: ArrayLike, z: ArrayLike, H: ArrayLike, R: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Measurement update in Joseph form.

    Parameters
    ----------
    x : (..., m) array_like
        Predicted mean(s), finite.
    P : (..., m, m) array_like
        Predicted covariance(s), symmetric positive semidefinite.
    z : (..., q) array_like
        Measurement(s), finite.
    H : (q, m) or (..., q, m) array_like
        Measurement matrix, finite.
    R : (q, q) or (..., q, q) array_like
        Measurement-noise covariance, symmetric positive definite.

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
    """
    # model and state recognised by identity and bytes (see _RECENT_STATES), else checked in full
    last = _LAST_MODELS.get("u")
    if last is None or H is not last[0] or R is not last[1] or H.tobytes() != last[2] or R.tobytes() != last[3]:
        H, R = _check_update_model(H, R)
    r = _RECENT_STATES[0] if _RECENT_STATES else _NO_STATE  # the usual case: the last result comes back
    if (x is not r[0] or P is not r[1] or x.tobytes() != r[2] or P.tobytes() != r[3]) and not _recognised_state(x, P):
        x, P = _checked_state(x, P)
    m = x.shape[-1]
    if type(z) is not _ND or z.dtype is not _F64:
        z = _float_array(z, "z")  # scanned only if the result is not finite (a NaN in z reaches x_post)
    if z.ndim < 1 or H.shape[-1] != m or H.shape[-2] != z.shape[-1]:
        raise ValueError(
            f"Incompatible dimensions of H; expected (..., q, {m}) with q the length of z (shape {z.shape}) "
            f"but found {H.shape}"
        )
    if R.shape[-1] != z.shape[-1]:
        raise ValueError(
            f"Incompatible dimensions of R; expected (..., {z.shape[-1]}, {z.shape[-1]}) for z of shape {z.shape} "
            f"but found {R.shape}"
        )
    try:
        out = _update(x, P, z, H, R)
    except ValueError as exc:  # leading (batch) axes that do not broadcast
        raise ValueError(
            f"the batch axes of x {x.shape}, P {P.shape}, z {z.shape}, H {H.shape}, R {R.shape} "
            f"do not broadcast ({exc})"
        ) from None
    return _checked_result(*out, "measurement update", ((z, "z"),))


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
        Gaussian filter.

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
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


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
    return _symmetrize(_finite(P, "P"))


def run_filter(
    x0: ArrayLike, P0: ArrayLike, z: ArrayLike, F: ArrayLike, Q: ArrayLike, H: ArrayLike, R: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """A whole Kalman filter run: predict then update for each measurement, checked once.

    The arguments are checked once, at the start; the steps run on the unchecked
    kernels, so a long run costs what the arithmetic costs. The result is the
    same, bit for bit, as a loop of :func:`predict` and :func:`update`.

    Parameters
    ----------
    x0 : (..., m) array_like
        Initial mean(s), finite (a leading batch shape runs several filters at once).
    P0 : (..., m, m) array_like
        Initial covariance(s), symmetric positive semidefinite.
    z : (K, ..., q) array_like
        Measurements of steps 1..K, finite.
    F, Q : (m, m) array_like
        Transition matrix and process noise covariance (positive semidefinite).
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
    x, P = _checked_state(x0, P0, "x0", "P0")
    F, Q, _ = _check_predict_model(F, Q, None)
    H, R = _check_update_model(H, R)
    z = _finite(_float_array(z, "z"), "z")
    m = x.shape[-1]
    if F.shape[-2:] != (m, m) or Q.shape[-2:] != (m, m):
        raise ValueError(f"F and Q must be ({m}, {m}) for x0 of shape {x.shape}; got {F.shape} and {Q.shape}")
    if H.shape[-1] != m or R.shape[-2:] != (H.shape[-2], H.shape[-2]):
        raise ValueError(f"H must be (q, {m}) and R (q, q); got {H.shape} and {R.shape}")
    if z.ndim < 1 or z.shape[-1] != H.shape[-2] or z.shape[1:-1] != x.shape[:-1]:
        raise ValueError(f"Incompatible dimensions of z; expected (K, *{x.shape[:-1]}, {H.shape[-2]}) "
                         f"but found {z.shape}")
    xs = np.empty((z.shape[0], *x.shape))
    Ps = np.empty((z.shape[0], *P.shape))
    for k in range(z.shape[0]):
        x, P = _predict(x, P, F, Q)
        x, P = _update(x, P, z[k], H, R)
        xs[k], Ps[k] = x, P
    if not (np.isfinite(xs).all() and np.isfinite(Ps).all()):
        raise ValueError("the filter run overflowed (NaN or inf) although every input is finite; rescale the problem")
    return xs, Ps


# ----------------------------------------------------------------------------
# unchecked kernels (inner loops; callers have validated the arguments)
# ----------------------------------------------------------------------------


def _predict(x, P, F, Q, B=None, u=None):
    """:func:`predict` without checks."""
    if x.ndim == 1 and P.ndim == 2 and F.ndim == 2:  # one filter: plain matrix products, less call overhead
        # a NaN/inf input surfaces as a non-finite result, which the caller refuses by name
        with np.errstate(invalid="ignore", over="ignore"):
            x_pred = F @ x if u is None else F @ x + B @ u
            P_pred = F @ P @ F.T + Q
        return x_pred, 0.5 * (P_pred + P_pred.T)
    x_pred = np.einsum("...ij,...j->...i", F, x)
    if u is not None:
        x_pred = x_pred + np.einsum("...ij,...j->...i", B, u)
    P_pred = F @ P @ np.swapaxes(F, -1, -2) + Q
    return x_pred, _symmetrize(P_pred)


def _gain(P, H, R):
    """:func:`kalman_gain` without checks."""
    S = H @ P @ np.swapaxes(H, -1, -2) + R
    # K^T = S^{-1} H P because S and P are symmetric
    return np.swapaxes(np.linalg.solve(S, H @ P), -1, -2)


def _update(x, P, z, H, R):
    """:func:`update` without checks."""
    if x.ndim == 1 and P.ndim == 2 and H.ndim == 2 and R.ndim == 2:  # one filter
        HP = H @ P
        K = np.linalg.solve(HP @ H.T + R, HP).T  # K^T = S^{-1} H P (S, P symmetric)
        with np.errstate(invalid="ignore", over="ignore"):  # as in _predict
            x_post = x + K @ (z - H @ x)
        I_KH = np.eye(x.shape[0]) - K @ H
        P_post = I_KH @ P @ I_KH.T + K @ R @ K.T
        return x_post, 0.5 * (P_post + P_post.T)
    K = _gain(P, H, R)
    innovation = z - np.einsum("...ij,...j->...i", H, x)
    x_post = x + np.einsum("...ij,...j->...i", K, innovation)
    I_KH = np.eye(x.shape[-1]) - K @ H
    P_post = I_KH @ P @ np.swapaxes(I_KH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
    return x_post, _symmetrize(P_post)


def _symmetrize(P):
    """:func:`symmetrize` without checks."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))
