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
    "cached_covariance",
    "cached_finite",
    "float_array",
    "finite_result",
    "frozen_copy",
    "require_finite",
    "symmetric_part",
    "check_adjacency",
    "check_covariance",
    "check_generator",
    "check_laplacian",
    "check_positive",
    "check_positive_int",
    "check_seed",
    "check_probability",
    "check_square",
]

#: Relative tolerance used for symmetry and positive-(semi)definiteness checks.
SYMMETRY_RTOL = 1e-8

#: Most time steps one simulation call accepts (a larger request is refused, not run).
MAX_STEPS = 10_000_000


def as_vector(x: ArrayLike, name: str, size: int | None = None) -> np.ndarray:
    """Return `x` as a 1-D float array, checking its length.

    Raises
    ------
    ValueError
        If `x` is not one-dimensional, has the wrong length or is not finite.
    """
    arr = float_array(x, name)
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
    arr = float_array(M, name)
    expected = "" if shape is None else " of shape (" + ", ".join("any" if w is None else str(w) for w in shape) + ")"
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D array{expected}; got shape {arr.shape}")
    if shape is not None:
        for got, want in zip(arr.shape, shape):
            if want is not None and got != want:
                raise ValueError(f"Incompatible dimensions of {name}; expected{expected[9:]} but found {arr.shape}")
    _check_finite(arr, name)
    return arr


def check_square(M: ArrayLike, name: str, size: int | None = None) -> np.ndarray:
    """Return `M` as a square float matrix, at least 1 x 1 (optionally of a given size)."""
    arr = as_matrix(M, name)
    if arr.shape[0] != arr.shape[1]:
        raise ValueError(f"{name} must be square; got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{name} must be at least 1 x 1; got shape {arr.shape}")
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
    arr = float_array(P, name)
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
        raise ValueError(f"{name} must be a square matrix (..., n, n); got shape {arr.shape}")
    if size is not None and arr.shape[-1] != size:
        raise ValueError(
            f"Incompatible dimensions of {name}; expected ({size}, {size}) "
            f"but found {arr.shape[-2:]}"
        )
    _check_finite(arr, name)
    scale = max(1.0, float(np.max(np.abs(arr)))) if arr.size else 1.0
    if arr.size and float(np.max(np.abs(arr - np.swapaxes(arr, -1, -2)))) > SYMMETRY_RTOL * scale:
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
    non-negative integer seeds are accepted and turned into ``np.random.default_rng(seed)``.

    Raises
    ------
    TypeError
        `rng` is neither a Generator nor an integer.
    ValueError
        `rng` is a negative integer.
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        if rng < 0:
            raise ValueError(f"{name} must be a numpy.random.Generator or a non-negative integer seed; got {rng}")
        return np.random.default_rng(int(rng))
    raise TypeError(
        f"{name} must be a numpy.random.Generator or an integer seed; got {type(rng).__name__}"
    )


def check_seed(seed: object, name: str = "seed") -> int:
    """Return `seed` as an int, requiring a non-negative integer (what ``numpy.random.SeedSequence`` takes)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{name} must be a non-negative integer seed; got {type(seed).__name__} {seed!r}")
    if seed < 0:
        raise ValueError(f"{name} must be a non-negative integer seed; got {seed}")
    return int(seed)


def check_positive_int(n: object, name: str, minimum: int = 1) -> int:
    """Return `n` as an int, requiring an integer (not a bool or a float) ``>= minimum``."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"{name} must be an integer >= {minimum}; got {type(n).__name__} {n!r}")
    if n < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {n}")
    return int(n)


def check_positive(x: object, name: str, unit: str = "", allow_zero: bool = False) -> float:
    """Return `x` as a finite float > 0 (or >= 0 with `allow_zero`); `unit` goes into the message."""
    if isinstance(x, np.ndarray) and x.ndim == 0:
        x = x.item()
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number; got {type(x).__name__} {x!r}")
    value = float(x)
    bound = ">= 0" if allow_zero else "> 0"
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{name} must be a finite number {bound}{' ' + unit if unit else ''}; got {x!r}")
    return value


def check_probability(p: object, name: str) -> float:
    """Return `p` as a float in [0, 1]."""
    value = check_positive(p, name, allow_zero=True)
    if value > 1:
        raise ValueError(f"{name} must be a probability in [0, 1]; got {p!r}")
    return value


def check_adjacency(
    A: ArrayLike, name: str = "adjacency", size: int | None = None, undirected: bool = False, why: str = ""
) -> np.ndarray:
    """Check a weighted adjacency matrix: square, finite, non-negative, no self-loops.

    ``A[i, j] > 0`` means agent i receives from agent j. A Laplacian passed by
    mistake (negative off-diagonal entries, positive diagonal) is named as such.
    With `undirected`, `A` must be symmetric; `why` (the reason the caller needs it) goes into the message.
    """
    arr = check_square(A, name, size)
    if np.any(np.diag(arr) != 0):
        if np.all(arr - np.diag(np.diag(arr)) <= 0) and np.allclose(arr.sum(axis=1), 0):
            raise ValueError(f"{name} looks like a Laplacian (rows sum to zero, negative off-diagonal entries); "
                             f"pass the adjacency matrix instead (A = diag(diag(L)) - L)")
        raise ValueError(f"{name} must have a zero diagonal (no self-loops); got diagonal {np.diag(arr)}")
    if np.any(arr < 0):
        raise ValueError(f"{name} must have non-negative weights; smallest entry is {arr.min():.3g}")
    if undirected and not np.allclose(arr, arr.T, atol=SYMMETRY_RTOL * max(1.0, float(np.abs(arr).max()))):
        raise ValueError(f"{name} must be symmetric (an undirected graph){': ' + why if why else ' here'}")
    return arr


def check_laplacian(
    L: ArrayLike, name: str = "laplacian", size: int | None = None, undirected: bool = False, why: str = ""
) -> np.ndarray:
    """Check a graph Laplacian: square, finite, rows summing to zero, non-positive off-diagonal.

    An adjacency matrix passed by mistake is named as such, with the function to call.
    With `undirected`, `L` must be symmetric (a theorem for undirected graphs needs it); `why`
    (the reason the caller needs it) goes into the message.
    """
    arr = check_square(L, name, size)
    off = arr - np.diag(np.diag(arr))
    scale = max(1.0, float(np.abs(arr).max())) if arr.size else 1.0
    if np.any(off > SYMMETRY_RTOL * scale) or not np.allclose(arr.sum(axis=1), 0, atol=SYMMETRY_RTOL * scale):
        if np.all(arr >= 0) and np.all(np.diag(arr) == 0):
            raise ValueError(f"{name} looks like an adjacency matrix; pass mascore.graphs.laplacian(A) instead")
        raise ValueError(f"{name} must be a graph Laplacian: rows summing to zero and off-diagonal entries <= 0")
    if undirected and not np.allclose(arr, arr.T, atol=SYMMETRY_RTOL * scale):
        raise ValueError(f"{name} must be symmetric (an undirected graph){': ' + why if why else ' here'}; "
                         "got a directed Laplacian")
    return arr


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite entries")


# ---------------------------------------------------------------- conversion and value-keyed checks

_ND = np.ndarray
_F64 = np.dtype(float)


def float_array(value: object, name: str) -> np.ndarray:
    """`value` as a float array.

    Lists, ints and bools are converted; a string, None, a complex or ragged
    array is a ``TypeError`` that names `name`.
    """
    if type(value) is _ND and value.dtype is _F64:
        return value
    if value is None or isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be an array of real numbers; got {type(value).__name__} {value!r}")
    try:
        arr = np.asarray(value)
        if arr.dtype.kind == "O":  # e.g. Python ints beyond int64, numbers mixed with arrays
            arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{name} must be an array of real numbers; got a {type(value).__name__} that numpy cannot "
            f"convert ({exc})"
        ) from None
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be an array of real numbers; got an array of dtype {arr.dtype}")
    return arr.astype(float, copy=False)


def require_finite(arr: np.ndarray, name: str) -> np.ndarray:
    """Raise a ``ValueError`` naming `name` if `arr` holds NaN or inf."""
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or infinite entries")
    return arr


def finite_result(what: str, *arrays: np.ndarray) -> np.ndarray | tuple[np.ndarray, ...]:
    """Refuse NaN/inf in a result computed from checked, finite input (an overflow), naming the computation.

    Parameters
    ----------
    what : str
        The computation, as the message names it (``"Kalman update"``).
    *arrays : ndarray
        Its results.

    Returns
    -------
    ndarray or tuple of ndarray
        The one array, or the tuple of arrays, unchanged.

    Raises
    ------
    ValueError
        If any entry is NaN or infinite.
    """
    for arr in arrays:
        if not np.isfinite(arr).all():
            raise ValueError(
                f"the {what} produced NaN or inf from finite input: the values overflow floating point "
                "(rescale the problem) or the covariances are too close to singular"
            )
    return arrays if len(arrays) != 1 else arrays[0]


def symmetric_part(M: np.ndarray) -> np.ndarray:
    """``(M + M^T) / 2`` over the last two axes (a plain kernel: no checks)."""
    return 0.5 * (M + np.swapaxes(M, -1, -2))


def frozen_copy(arr: np.ndarray) -> np.ndarray:
    """A read-only float copy of `arr`: what a checked model stores, so no later change slips past its check."""
    out = np.array(arr, dtype=float, copy=True)
    out.setflags(write=False)
    return out


class _ValueMemo:
    """Values that already passed a check, keyed by their bytes (the tag says which shapes were checked).

    Keyed by value, an array modified in place after it was stored is simply not
    recognised any more. Bounded: cleared when it would hold more than
    `max_entries` keys or `max_total_bytes` bytes; a key longer than
    `max_key_bytes` is never stored (that value is checked every time).
    """

    __slots__ = ("store", "_max_entries", "_max_key", "_max_total", "_total")

    def __init__(self, max_entries: int = 512, max_key_bytes: int = 1 << 22, max_total_bytes: int = 1 << 26) -> None:
        self.store: dict[bytes, object] = {}
        self._max_entries = max_entries
        self._max_key = max_key_bytes
        self._max_total = max_total_bytes
        self._total = 0

    def put(self, key: bytes, tag: object) -> None:
        n = len(key)
        if n > self._max_key:
            return
        if len(self.store) >= self._max_entries or self._total + n > self._max_total:
            self.store.clear()
            self._total = 0
        self.store[key] = tag
        self._total += n


#: Constant matrices checked once per distinct value: F, H, B (finite) and Q, R (covariances).
_FINITE_CONSTANTS = _ValueMemo()
_COVARIANCE_CONSTANTS = _ValueMemo()


def cached_finite(M: ArrayLike, name: str) -> np.ndarray:
    """A constant matrix as a float array, its finiteness checked once per distinct value."""
    arr = float_array(M, name)
    key = arr.tobytes()
    if _FINITE_CONSTANTS.store.get(key) != arr.shape:
        require_finite(arr, name)
        _FINITE_CONSTANTS.put(key, arr.shape)
    return arr


def cached_covariance(M: ArrayLike, name: str, size: int | None = None, definite: bool = False) -> np.ndarray:
    """A constant covariance (Q, R): :func:`check_covariance` once per distinct value."""
    arr = float_array(M, name)
    key = arr.tobytes()
    got = _COVARIANCE_CONSTANTS.store.get(key)
    if got != (True, arr.shape) and (definite or got != (False, arr.shape)):
        check_covariance(arr, name, size=size, definite=definite)
        _COVARIANCE_CONSTANTS.put(key, (definite, arr.shape))
    elif size is not None and arr.shape[-1] != size:
        raise ValueError(f"Incompatible dimensions of {name}; expected ({size}, {size}) but found {arr.shape[-2:]}")
    return arr


def available_memory_bytes() -> int:
    """Memory the system can still give this process (``MemAvailable`` of ``/proc/meminfo``, else free pages)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os

        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_AVPHYS_PAGES"))
    except (AttributeError, OSError, ValueError):  # pragma: no cover - no way to ask: assume 8 GiB
        return 8 * 2**30


def check_fits_in_memory(n_bytes: float, name: str, what: str = "") -> None:
    """Refuse up front (``ValueError`` naming `name`) a request whose arrays need more than the available memory.

    `n_bytes` is the size of what the request must hold at once (e.g. runs x agents x steps x 8 bytes);
    `what` says what it is (``"the state histories"``). A request that cannot fit is refused instead of
    running for a long time before failing.
    """
    available = available_memory_bytes()
    if not np.isfinite(n_bytes) or n_bytes > available:
        held = f" for {what}" if what else ""
        raise ValueError(f"{name} asks for too much: about {float(n_bytes) / 2**30:.3g} GiB{held}, but only "
                         f"{available / 2**30:.3g} GiB of memory is available; ask for fewer")
