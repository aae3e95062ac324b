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
checked once per distinct value (remembered by their bytes), and a mean and
covariance that passed the full check, or that one of these two functions
returned, are recognised when they come back as a later call's arguments (the
same objects, still holding the same bytes: an array modified in place is
checked again). What remains per call is a few comparisons and the NaN/inf test
of the result; ``benchmarks/bench_validation.py`` measures it against the
unchecked kernels :func:`_predict` and :func:`_update`, which compute the same
numbers.

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
import threading
from collections import deque

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
# * _RECENT_STATES holds the last few (x, P) pairs that passed the full check or were returned as results,
#   finite and P symmetric PSD, with their bytes: an argument pair that *is* one of them (identity) and still
#   holds the same bytes (not modified in place) needs no scan; a recognised pair moves to the front;
# * _LAST_MODELS holds, per step kind, the last checked model matrices with their bytes (same test);
#   other model matrices go through the value-keyed memos of _const_finite and _const_covariance.
_N_RECENT = 8
_RECENT_STATES: deque[tuple] = deque(maxlen=_N_RECENT)
_NO_STATE = (object(), object(), b"", b"")  # matches no argument
_MAX_REMEMBERED_BYTES = 1 << 22
_LAST_MODELS: dict[str, tuple] = {}
#: Results up to this many bytes are tested for NaN/inf by a Python sum over their bytes (no numpy call).
_SMALL_BYTES = 2048


def _recognised_state(x: object, P: object) -> bool:
    """True if (x, P) passed the checks or is a result of :func:`predict`/:func:`update`, unmodified since.

    A recognised pair moves to the front (least recently used pairs are forgotten first).
    """
    for i, item in enumerate(_RECENT_STATES):
        if item[0] is x and item[1] is P:
            if x.tobytes() != item[2] or P.tobytes() != item[3]:
                return False
            if i:
                del _RECENT_STATES[i]
                _RECENT_STATES.appendleft(item)
            return True
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


def _remember(x: np.ndarray, P: np.ndarray, xb: bytes, Pb: bytes) -> None:
    """Remember (x, P), finite and P symmetric PSD, with their bytes (see _RECENT_STATES)."""
    if len(xb) + len(Pb) <= _MAX_REMEMBERED_BYTES:
        _RECENT_STATES.appendleft((x, P, xb, Pb))


def _checked_state_remembered(x: ArrayLike, P: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_checked_state`, then remember the pair: passed again unmodified, it is not checked again."""
    x, P = _checked_state(x, P)
    _remember(x, P, x.tobytes(), P.tobytes())
    return x, P


def _checked_result(x: np.ndarray, P: np.ndarray, what: str, fresh: tuple, ok: bool | None = None) -> tuple:
    """Refuse a non-finite result, naming the cause; remember a finite one as a checked state.

    `fresh` holds ``(array, name)`` pairs of inputs that change at every step (a
    measurement, an input) and were not scanned: a NaN or inf in them reaches
    the result, so they are scanned only when the result is not finite. `ok`,
    if given, is a quick test already made (False may be a false alarm: an
    overflow of the test itself; then the exact test decides).
    """
    xb, Pb = x.tobytes(), P.tobytes()
    if ok is None:
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
    _remember(x, P, xb, Pb)
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
        x, P = _checked_state_remembered(x, P)
    m = x.shape[-1]
    if F.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of F; expected (..., {m}, {m}) for x of shape {x.shape} "
                         f"but found {F.shape}")
    if Q.shape[-1] != m:
        raise ValueError(f"Incompatible dimensions of Q; expected (..., {m}, {m}) for x of shape {x.shape} "
                         f"but found {Q.shape}")
    if u is None and B is None:
        if x.ndim == 1 and P.ndim == 2 and F.ndim == 2 and Q.ndim == 2:  # one filter: the quickest path
            x, P, ok = _predict_one(x, P, F, Q, None, None)
            if ok:  # remember the result (as _checked_result does)
                _remember(x, P, x.tobytes(), P.tobytes())
                return x, P
            return _checked_result(x, P, "prediction", (), ok)
    else:
        if u is None or B is None:
            raise ValueError("B and u must be given together (B alone or u alone cannot form B u)")
        u = _float_array(u, "u")  # scanned only if the result is not finite (a NaN in u reaches x_pred)
        if B.shape[-2] != m or u.ndim < 1 or B.shape[-1] != u.shape[-1]:
            raise ValueError(
                f"Incompatible dimensions of B {B.shape} and u {u.shape}; expected B ({m}, p) and u (..., p)"
            )
    try:
        one = x.ndim == 1 and P.ndim == 2 and F.ndim == 2 and Q.ndim == 2 and (u is None or (u.ndim == 1 and B.ndim == 2))
        out = (_predict_one if one else _predict_stack)(x, P, F, Q, B, u)
    except ValueError as exc:  # leading (batch) axes that do not broadcast
        raise ValueError(
            f"the batch axes of x {x.shape}, P {P.shape}, F {F.shape}, Q {Q.shape}"
            f"{'' if u is None else f', u {u.shape}'} do not broadcast ({exc})"
        ) from None
    return _checked_result(out[0], out[1], "prediction", () if u is None else ((u, "u"),), out[2])


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
        x, P = _checked_state_remembered(x, P)
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
    if x.ndim == 1 and P.ndim == 2 and H.ndim == 2 and R.ndim == 2 and z.ndim == 1:  # one filter: the quickest path
        x, P, ok = _update_one(x, P, z, H, R)
        if ok:  # remember the result (as _checked_result does)
            _remember(x, P, x.tobytes(), P.tobytes())
            return x, P
        return _checked_result(x, P, "measurement update", ((z, "z"),), ok)
    try:
        out = _update_stack(x, P, z, H, R)
    except ValueError as exc:  # leading (batch) axes that do not broadcast
        raise ValueError(
            f"the batch axes of x {x.shape}, P {P.shape}, z {z.shape}, H {H.shape}, R {R.shape} "
            f"do not broadcast ({exc})"
        ) from None
    return _checked_result(out[0], out[1], "measurement update", ((z, "z"),), out[2])


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


#: A NaN/inf input or an overflow surfaces as a non-finite result, which the caller refuses by name: no warning
#: on the way (as a decorator, np.errstate costs half of what the context manager does).
_quiet = np.errstate(invalid="ignore", over="ignore")


def _predict(x, P, F, Q, B=None, u=None):
    """:func:`predict` without checks."""
    if x.ndim == 1 and P.ndim == 2 and F.ndim == 2 and Q.ndim == 2 and (u is None or (u.ndim == 1 and B.ndim == 2)):
        return _predict_one(x, P, F, Q, B, u)[:2]
    return _predict_stack(x, P, F, Q, B, u)[:2]


def _shared_covariance(P: np.ndarray, *model: np.ndarray) -> np.ndarray | None:
    """The one covariance of a stack whose matrices are all equal, with shared 2-D model matrices; else None.

    The test reads the stack once (``B n^2``), against the ``B n^3`` of the stacked products it saves.
    """
    if P.ndim < 3 or any(M is not None and M.ndim != 2 for M in model):
        return None
    flat = P.reshape(-1, *P.shape[-2:])
    return flat[0] if flat.shape[0] > 1 and (flat == flat[0]).all() else None


@_quiet
def _predict_stack(x, P, F, Q, B, u):
    """:func:`_predict` with batch axes (products on stacks, no einsum), and whether the result is finite."""
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
    P_pred = _mm(_mm(F, P, 0), np.ascontiguousarray(Ft), 1)  # a contiguous right factor: faster stacked products
    P_out = _symmetrize_fresh(_add_into(P_pred, Q))
    return x_pred, P_out, _finite_test(x_pred, P_out)


#: Temporaries of the stacked kernels from this many bytes on are kept for the next call (per thread, per
#: shape): fresh memory of that size comes from the system, and its page faults cost as much as the products.
_SCRATCH_MIN_BYTES = 1 << 20
_SCRATCH_MAX_BYTES = 1 << 25
_SCRATCH_TOTAL_BYTES = 1 << 26
_SCRATCH = threading.local()


def _mm(a, b, slot):
    """``a @ b`` on stacks; a large product goes into a kept temporary (`slot` tells apart those alive at once).

    The result is scratch: it must not leave the kernel.
    """
    if a.ndim == 2:
        batch = b.shape[:-2]
    elif b.ndim == 2 or a.shape[:-2] == b.shape[:-2]:
        batch = a.shape[:-2]
    else:
        batch = np.broadcast_shapes(a.shape[:-2], b.shape[:-2])
    shape = (*batch, a.shape[-2], b.shape[-1])
    nbytes = 8 * math.prod(shape)
    if nbytes < _SCRATCH_MIN_BYTES or nbytes > _SCRATCH_MAX_BYTES or a.dtype != _F64 or b.dtype != _F64:
        return a @ b
    pool = getattr(_SCRATCH, "pool", None)
    if pool is None:
        pool = _SCRATCH.pool = {}
    key = (slot, shape)
    out = pool.get(key)
    if out is None:
        if len(pool) >= 8 or nbytes + sum(buf.nbytes for buf in pool.values()) > _SCRATCH_TOTAL_BYTES:
            pool.clear()
        out = pool[key] = np.empty(shape)
    return np.matmul(a, b, out=out)


def _add_into(A, B):
    """``A + B``, in A's storage when the shapes allow."""
    if B.ndim <= A.ndim and (A.shape[A.ndim - B.ndim:] == B.shape or np.broadcast_shapes(A.shape, B.shape) == A.shape):
        A += B
        return A
    return A + B


def _finite_test(x, P):
    """False if x or P holds NaN/inf (or if the test itself overflows: then the exact test decides)."""
    return math.isfinite(np.vdot(x, x) + np.vdot(P, P))


@_quiet
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


def _gain(P, H, R):
    """:func:`kalman_gain` without checks."""
    S = H @ P @ np.swapaxes(H, -1, -2) + R
    # K^T = S^{-1} H P because S and P are symmetric
    return np.swapaxes(np.linalg.solve(S, H @ P), -1, -2)


_LAPACK = None
_EYES: dict[int, np.ndarray] = {}


def _solve_one(S: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``S^{-1} B`` for one (q, q) system, through LAPACK without numpy's gufunc overhead.

    Small q: posv (Cholesky; gesv, what np.linalg.solve calls, if S is not numerically positive
    definite). From q = 16 on, the LU inverse and one matrix
    product are quicker than gesv's triangular solves with many right-hand sides (the gain's
    rounding differs at the eps * cond(S) level; the Joseph form is insensitive to it to first order).
    """
    global _LAPACK
    if _LAPACK is None:
        from scipy.linalg import lapack

        _LAPACK = lapack
    if S.shape[0] < 16:
        X, info = _LAPACK.dposv(S, B)[1:]  # Cholesky: S is positive definite (R is)
        if info:  # not numerically: LU with pivoting decides
            X, info = _LAPACK.dgesv(S, B)[2:]
    else:
        lu, piv, info = _LAPACK.dgetrf(S)
        if not info:
            Si, info = _LAPACK.dgetri(lu, piv)
            X = Si.dot(B)
    if info:
        raise np.linalg.LinAlgError("Singular matrix")
    return X


def _eye(m: int) -> np.ndarray:
    I = _EYES.get(m)
    if I is None:
        I = np.eye(m)
        I.flags.writeable = False
        if len(_EYES) < 64:
            _EYES[m] = I
    return I


def _update(x, P, z, H, R):
    """:func:`update` without checks."""
    if x.ndim == 1 and P.ndim == 2 and H.ndim == 2 and R.ndim == 2 and z.ndim == 1:
        return _update_one(x, P, z, H, R)[:2]
    return _update_stack(x, P, z, H, R)[:2]


@_quiet
def _update_stack(x, P, z, H, R):
    """:func:`_update` with batch axes (products on stacks, no einsum), and whether the result is finite.

    Few large temporaries, reused in place (as in :func:`_predict_stack`).
    """
    one = _shared_covariance(P, H, R)
    if one is not None:  # one covariance for the batch: one gain, applied to every mean
        HP = H.dot(one)
        K = _solve_one(HP.dot(H.T) + R, HP).T
        x_post = x + (z - x @ H.T) @ K.T
        batch = np.broadcast_shapes(x_post.shape[:-1], P.shape[:-2])
        if x_post.shape[:-1] != batch:
            x_post = np.broadcast_to(x_post, (*batch, x_post.shape[-1])).copy()
        _, P1, _ = _update_one(np.zeros(one.shape[0]), one, np.zeros(H.shape[0]), H, R)
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
    At = _mm(Ht, KT, 2)
    np.subtract(_eye(x.shape[-1]), At, out=At)
    AP = _mm(K, HP, 3)
    AP = np.subtract(P, AP, out=AP) if AP.shape == np.broadcast_shapes(AP.shape, P.shape) else P - AP
    P_post = _mm(AP, At, 4)
    P_post = _add_into(P_post, _mm(K @ R, KT, 3))
    P_out = _symmetrize_fresh(P_post)
    return x_post, P_out, _finite_test(x_post, P_out)


@_quiet
def _update_one(x, P, z, H, R):
    """One filter (x (m,), z (q,), P, H, R matrices): the Joseph update and whether it is finite."""
    HP = H.dot(P)
    S = HP.dot(H.T)
    S += R
    K = _solve_one(S, HP).T  # K^T = S^{-1} H P (S, P symmetric)
    x_post = x + K.dot(z - H.dot(x))
    # Joseph form (I - K H) P (I - K H)^T + K R K^T, its left product (I - K H) P formed as P - K (H P) from
    # the H P at hand (the same rounding error bound, eps |K| |H| |P|, with n^2 q instead of n^3 flops)
    AP = P - K.dot(HP)
    P_post = AP.dot((_eye(x.shape[0]) - K.dot(H)).T)
    P_post += K.dot(R).dot(K.T)
    P_out = P_post.T.copy()  # (P + P^T) / 2; a contiguous copy of P^T adds faster than the transposed view
    P_out += P_post
    P_out *= 0.5
    return x_post, P_out, math.isfinite(x_post.dot(x_post) + np.vdot(P_out, P_out))  # as in _predict_one


def _symmetrize_fresh(P):
    """``(P + P^T) / 2`` of a freshly computed array (a contiguous copy of P^T adds faster than the view)."""
    out = np.swapaxes(P, -1, -2).copy()
    out += P
    out *= 0.5
    return out


def _symmetrize(P):
    """:func:`symmetrize` without checks."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))
