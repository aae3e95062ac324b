"""Input checks shared by every module.

Each check raises early with a message that names the offending argument and
what was expected, so that bad input never travels on into NaNs.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "as_matrix",
    "as_vector",
    "float_array",
    "graph_adjacency",
    "finite_result",
    "frozen_copy",
    "Frozen",
    "state_view",
    "require_finite",
    "symmetric_part",
    "check_adjacency",
    "check_covariance",
    "check_generator",
    "check_laplacian",
    "check_positive",
    "check_positive_int",
    "agent_index",
    "step_arrays",
    "check_moderate",
    "check_seed",
    "check_steps",
    "check_budget",
    "check_probability",
    "check_square",
]

#: Relative tolerance used for symmetry and positive-(semi)definiteness checks.
SYMMETRY_RTOL = 1e-8

#: Most time steps one simulation call accepts (a larger request is refused, not run).
MAX_STEPS = 10_000_000

#: Most elementary steps (steps x runs x repeats x agents) one call accepts: a larger request would run
#: for days, so it is refused before any work starts.
STEP_BUDGET = 10**9


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
    if not arr.size:  # (..., 0, 0): no eigenvalue, read as 0; an empty batch (0, ..., n, n): nothing to check
        if definite and arr.shape[-1] == 0:
            raise ValueError(f"{name} must be positive definite; smallest eigenvalue is 0")
        return arr
    largest = float(abs(arr).max())  # NaN or inf anywhere makes it NaN or inf: the finiteness test too
    if not math.isfinite(largest):
        raise ValueError(f"{name} contains NaN or infinite entries")
    scale = max(1.0, largest)
    if float(abs(arr - arr.swapaxes(-1, -2)).max()) > SYMMETRY_RTOL * scale:
        raise ValueError(f"{name} must be symmetric")
    eig_min = float(np.linalg.eigvalsh(arr).min())
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


def sample_shape(size: object, name: str = "size") -> tuple[int, ...]:
    """`size` (an int or a tuple of ints, each >= 0) as a tuple; anything else is refused by name."""
    dims = (size,) if isinstance(size, (int, np.integer)) and not isinstance(size, bool) else size
    if isinstance(dims, np.ndarray) and dims.ndim == 1:
        dims = dims.tolist()
    if not isinstance(dims, (tuple, list)) or not all(
        isinstance(d, (int, np.integer)) and not isinstance(d, bool) for d in dims
    ):
        raise TypeError(f"{name} must be an int or a tuple of ints (the leading shape of the output); got {size!r}")
    if any(d < 0 for d in dims):
        raise ValueError(f"{name} must hold non-negative ints; got {size!r}")
    return tuple(int(d) for d in dims)


def check_positive_int(n: object, name: str, minimum: int = 1) -> int:
    """Return `n` as an int, requiring an integer (not a bool or a float) ``>= minimum``."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise TypeError(f"{name} must be an integer >= {minimum}; got {type(n).__name__} {n!r}")
    if n < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}; got {n}")
    return int(n)


def agent_index(i: object, n_agents: int, name: str = "i") -> int:
    """Return agent `i` as an int in ``0..n_agents-1`` (an integer, not a bool or a float), else raise naming `name`."""
    i = check_positive_int(i, name, minimum=0)
    if i >= n_agents:
        raise ValueError(f"{name} must be an agent 0..{n_agents - 1}; got {i}")
    return i


#: Entries beyond this magnitude square to inf (products of two such entries overflow floating point).
MODERATE = 1e150


def check_moderate(*named: tuple[str, np.ndarray], what: str = "the computation") -> None:
    """Refuse (naming it) an array whose entries overflow floating point once squared (beyond :data:`MODERATE`)."""
    for name, M in named:
        big = float(np.abs(M).max()) if M.size else 0.0
        if big > MODERATE:
            raise ValueError(f"{name} has entries of magnitude {big:.3g}: {what} overflows floating point; "
                             f"rescale the problem (units of time, state or input) so that {name} is moderate")


def step_arrays(**named: object) -> tuple[np.ndarray, ...]:
    """Each named value as a finite float array (a step's inputs), refused by name otherwise.

    Examples
    --------
    >>> from mascore._validation import step_arrays
    >>> x, P = step_arrays(x=[0.0, 1.0], P=[[1.0, 0.0], [0.0, 1.0]])
    >>> x.shape, P.shape
    ((2,), (2, 2))
    """
    return tuple(require_finite(float_array(value, name), name) for name, value in named.items())


def check_steps(n_steps: object, name: str = "n_steps") -> int:
    """Return `n_steps` as an int from 1 to :data:`MAX_STEPS` (a longer run is refused, not started)."""
    n_steps = check_positive_int(n_steps, name)
    if n_steps > MAX_STEPS:
        raise ValueError(f"{name} = {n_steps} is more than MAX_STEPS = {MAX_STEPS}; run fewer steps, in chunks if "
                         f"needed: each chunk starting from the last state of the one before")
    return n_steps


def check_budget(name: str, *counts: float, budget: float = STEP_BUDGET, what: str = "steps") -> None:
    """Refuse up front (``ValueError`` naming `name`) a request of more than `budget` elementary `what`.

    `counts` are the factors of the request (e.g. steps, runs, repeats), already checked one by one;
    their product must not exceed `budget` (:data:`STEP_BUDGET`).
    """
    total = math.prod(float(c) for c in counts)
    if not math.isfinite(total) or total > budget:
        raise ValueError(f"{name} asks for too much work: {total:.3g} {what} in one call, more than the budget of "
                         f"{budget:.3g}; ask for fewer (or split the work into several calls)")


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

def check_adjacency_stack(adjacency: ArrayLike, name: str = "adjacency") -> np.ndarray:
    """One adjacency ``(N, N)`` or a stack ``(..., N, N)``: finite, non-negative, zero diagonal, N >= 1."""
    A = float_array(adjacency, name)
    if A.ndim < 2 or A.shape[-1] != A.shape[-2] or A.shape[-1] == 0:
        raise ValueError(f"{name} must have shape (..., N, N) with N >= 1; got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    n = A.shape[-1]
    diag = A[..., np.arange(n), np.arange(n)]
    if np.any(diag != 0):
        off = A * (1 - np.eye(n))
        if np.all(off <= 0) and np.allclose(A.sum(axis=-1), 0):
            raise ValueError(
                f"{name} looks like a Laplacian (rows sum to zero, negative off-diagonal entries); "
                "pass the adjacency matrix instead (A = diag(diag(L)) - L)"
            )
        raise ValueError(f"{name} must have a zero diagonal (self-sensing is implicit in N̄_i)")
    if np.any(A < 0):
        raise ValueError(f"{name} entries must be non-negative (edge weights); smallest is {A.min():.3g}")
    return A

def check_flag(value: object, name: str) -> bool:
    """`value` as a bool: True or False only (numpy bools too; no 0/1, no None)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False; got {type(value).__name__} {value!r}")
    return bool(value)

def check_mask_values(mask: ArrayLike, name: str = "mask") -> np.ndarray:
    """A sensing mask as a bool array: bool, or numbers that are all exactly 0 or 1 (NaN is refused)."""
    if isinstance(mask, (str, bytes)) or mask is None:
        raise TypeError(f"{name} must be a boolean array (a sensing mask); got {mask!r}")
    S = np.asarray(mask)
    if S.dtype == bool:
        return S
    if S.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be a boolean array (a sensing mask); got dtype {S.dtype}")
    if not np.all((S == 0) | (S == 1)):
        raise ValueError(
            f"{name} must be a boolean array (or hold only 0 and 1); got other values"
            f"{' (NaN)' if S.dtype.kind == 'f' and np.isnan(S).any() else ''}"
        )
    return S.astype(bool)


def kron_factor(M: np.ndarray, k: int) -> np.ndarray | None:
    """``M_r`` with ``M = M_r ⊗ I_k`` over the last two axes, or ``None``."""
    M = np.asarray(M, dtype=float)
    if k == 1:
        return M
    r, c = M.shape[-2:]
    if r % k or c % k:
        return None
    blocks = M.reshape(*M.shape[:-2], r // k, k, c // k, k)
    red = blocks[..., :, 0, :, 0]
    rebuilt = red[..., :, None, :, None] * np.eye(k)[:, None, :]
    scale = max(1.0, float(np.max(np.abs(M)))) if M.size else 1.0
    if np.allclose(blocks, rebuilt, rtol=0, atol=1e-12 * scale):
        return red
    return None


def _check_finite(arr: np.ndarray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite entries")


# ---------------------------------------------------------------- conversion and value-keyed checks

_ND = np.ndarray
_F64 = np.dtype(float)


def float_array(value: object, name: str) -> np.ndarray:
    """`value` as a float array.

    Lists, ints and bools are converted; a networkx graph (or a list of graphs)
    is read as its adjacency matrix (a stack), see :func:`graph_adjacency`; a
    string, None, a complex or ragged array is a ``TypeError`` that names `name`.
    """
    if type(value) is _ND and value.dtype is _F64:
        return value
    if is_graph(value) or (isinstance(value, (list, tuple)) and value and all(map(is_graph, value))):
        return graph_adjacency(value)
    if value is None or isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be an array of real numbers; got {type(value).__name__} {value!r}")
    try:
        arr = np.asarray(value)
        if arr.dtype.kind == "O":  # e.g. Python ints beyond int64, numbers mixed with arrays
            arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        system = all(hasattr(value, a) for a in ("A", "B", "C", "D", "dt"))  # python-control's StateSpace and kin
        hint = (f"; a system's matrices are its attributes ({name} = sys.A, sys.B, ...), and the designs that take "
                f"a system take it as their first argument" if system else "")
        raise TypeError(
            f"{name} must be an array of real numbers; got a {type(value).__name__} that numpy cannot "
            f"convert ({exc}){hint}"
        ) from None
    if arr.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be an array of real numbers; got an array of dtype {arr.dtype}")
    return arr.astype(float, copy=False)


# ---------------------------------------------------------------- networkx graphs where an adjacency is expected


def is_graph(value: object) -> bool:
    """Whether `value` is a networkx graph (duck-typed, so networkx is imported only by its user)."""
    return type(value).__module__.startswith("networkx") and hasattr(value, "is_directed") and hasattr(value, "adj")


def graph_adjacency(graph: object) -> np.ndarray:
    """The adjacency matrix of a networkx graph (or the ``(T, N, N)`` stack of a list of graphs), mascore's convention.

    Agent ``i`` is the i-th node of ``sorted(graph.nodes)`` (the nodes ``0..N-1`` of
    every networkx generator), or of ``graph.nodes`` if they do not sort. An edge
    ``j -> i`` with attribute ``weight`` (default 1) gives ``A[i, j] = weight`` (agent
    ``i`` receives from ``j``); an undirected edge gives both entries. Every mascore
    argument that expects an adjacency accepts a graph, through :func:`float_array`.

    Examples
    --------
    >>> import networkx as nx
    >>> from mascore._validation import graph_adjacency
    >>> graph_adjacency(nx.DiGraph([(0, 1)]))            # 0 -> 1: agent 1 hears agent 0
    array([[0., 0.],
           [1., 0.]])
    """
    if isinstance(graph, (list, tuple)):
        mats = [graph_adjacency(g) for g in graph]
        if len({m.shape for m in mats}) > 1:
            raise ValueError(f"the graphs of a sequence must have the same number of nodes; got {[m.shape[0] for m in mats]}")
        return np.stack(mats)
    import networkx as nx

    nodes = list(graph.nodes)
    try:
        nodes = sorted(nodes)
    except TypeError:
        pass
    M = nx.to_numpy_array(graph, nodelist=nodes, weight="weight", dtype=float)  # M[u, v]: edge u -> v
    return np.ascontiguousarray(M.T)


def require_finite(arr: np.ndarray, name: str) -> np.ndarray:
    """Raise a ``ValueError`` naming `name` if `arr` holds NaN or inf."""
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or infinite entries")
    return arr


def finite_result(
    what: str,
    *arrays: np.ndarray,
    inputs: tuple[tuple[np.ndarray | None, str], ...] = (),
    advice: str = "the values overflow floating point (rescale the problem) or the covariances are too close "
    "to singular",
) -> np.ndarray | tuple[np.ndarray, ...]:
    """Refuse NaN/inf in a result, naming the input that held it, else the computation (an overflow).

    Parameters
    ----------
    what : str
        The computation, as the message names it (``"Kalman update"``).
    *arrays : ndarray
        Its results.
    inputs : tuple of (ndarray or None, str)
        ``(array, name)`` pairs of inputs that were not scanned for NaN/inf
        (a step's state, a fresh measurement): scanned, in order, only when a
        result is not finite, and the first holding NaN/inf is named. None
        entries are skipped.
    advice : str
        What the overflow message says to do.

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
            for value, name in inputs:
                if value is not None:
                    require_finite(value, name)
            raise ValueError(f"the {what} produced NaN or inf from finite input: {advice}")
    return arrays if len(arrays) != 1 else arrays[0]


def symmetric_part(M: np.ndarray) -> np.ndarray:
    """``(M + M^T) / 2`` over the last two axes (a plain kernel: no checks)."""
    return 0.5 * (M + M.swapaxes(-1, -2))


def frozen_copy(arr: ArrayLike, dtype: type = float) -> np.ndarray:
    """A read-only copy of `arr` (float by default): what a checked model stores, so no later change slips past
    its check.

    The copy lives in an immutable ``bytes`` buffer: neither it nor any array along its ``.base``
    chain can be made writeable again (``setflags(write=True)`` raises on each).
    """
    arr = np.asarray(arr, dtype=dtype)
    return np.frombuffer(arr.tobytes(), dtype=arr.dtype).reshape(arr.shape)


def state_view(obj: object, name: str, fields: dict[str, str]) -> np.ndarray:
    """A read-only view of the state array `name` of a filter `obj` (``fields`` maps names to attributes).

    What a filter's ``view(name)`` returns: no copy, but the next step may overwrite it. Its memory is the
    filter's, so the flag guards against a slip, not against a caller who sets it writeable again.
    """
    if name not in fields:
        raise ValueError(f"name must be one of {tuple(fields)}; got {name!r}")
    view = getattr(obj, fields[name]).view()
    view.flags.writeable = False
    return view


def _same(a: object, b: object) -> bool:
    """``a == b`` for the constructor arguments of a :class:`Frozen` (arrays by shape and value)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.shape(a) == np.shape(b) and bool(np.array_equal(a, b))
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return bool(a == b)


class Frozen:
    """Base of every checked model and value object: set once in the constructor, never again.

    A subclass checks its arguments in ``__init__`` (or a dataclass's ``__post_init__``), stores
    them with :meth:`_set` (arrays through :func:`frozen_copy`) and says in :meth:`_args` which
    constructor arguments rebuild it (a frozen dataclass: its ``init`` fields, by default). Then:
    setting or deleting an attribute raises ``AttributeError`` naming it; pickle, ``copy.copy`` and
    ``copy.deepcopy`` rebuild through the constructor (so the copy is checked and frozen too); two
    objects are ``==`` when they are of one type built from equal arguments.
    """

    __slots__ = ()

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"a {type(self).__name__} is frozen: cannot set {name!r} (build a new one)")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"a {type(self).__name__} is frozen: cannot delete {name!r}")

    def _set(self, **values: object) -> None:
        """Store attributes (constructor only)."""
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def _freeze_arrays(self) -> None:
        """Store every array field of a dataclass (an array, or a field annotated ``np.ndarray``) as a read-only copy
        of its own dtype (constructor only); such a field that is not a numeric or boolean array is refused."""
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            if value is None and "None" in str(f.type):  # an optional array left out
                continue
            if isinstance(value, np.ndarray) or "ndarray" in str(f.type):
                try:
                    arr = np.asarray(value)
                except ValueError:  # a ragged nesting
                    arr = np.asarray(None)
                if arr.dtype.kind not in "biufc":
                    raise TypeError(f"{type(self).__name__}.{f.name} must be a numeric array; got "
                                    f"{type(value).__name__} {value!r:.60}")
                self._set(**{f.name: frozen_copy(arr, arr.dtype)})

    def _args(self) -> tuple:
        """The constructor's positional arguments that rebuild this object (pickle, copy, ``==``)."""
        return tuple(getattr(self, f.name) for f in dataclasses.fields(self) if f.init)  # type: ignore[arg-type]

    def __reduce__(self) -> tuple:
        return (type(self), self._args())

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return other is self or _same(self.__reduce__()[1], other.__reduce__()[1])

    def __hash__(self) -> int:  # consistent with ==: arrays enter by shape, hashable values by value
        return hash((type(self), *map(_hash_key, self.__reduce__()[1])))


def _hash_key(a: object) -> object:
    if isinstance(a, np.ndarray):
        return a.shape
    try:
        return hash(a)
    except TypeError:
        return None


def available_memory_bytes() -> int:
    """Memory the system can still give this process (``MemAvailable`` of ``/proc/meminfo``, else free pages).

    A limit on the process's address space (``ulimit -v``, ``resource.RLIMIT_AS``) lowers it.
    """
    limit = _address_space_limit()
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return min(int(line.split()[1]) * 1024, limit)
    except (OSError, ValueError, IndexError):
        pass
    try:
        import os

        return min(int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_AVPHYS_PAGES")), limit)
    except (AttributeError, OSError, ValueError):  # pragma: no cover - no way to ask: assume 8 GiB
        return 8 * 2**30


def _address_space_limit() -> int:
    """Bytes of address space this process may still map under its soft limit (``2**62`` when there is none)."""
    try:
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    except (ImportError, OSError, ValueError):  # pragma: no cover - not a POSIX system
        return 2**62
    if soft == resource.RLIM_INFINITY or soft < 0:
        return 2**62
    used = 0
    try:
        with open("/proc/self/status") as fh:
            used = next((int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:")), 0)
    except (OSError, ValueError, IndexError):
        pass
    return max(int(soft) - used, 0)


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
