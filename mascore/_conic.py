"""Conic programs handed to Clarabel directly, without a modelling layer.

Building a program with cvxpy costs far more than solving it when the program has
hundreds of small matrix blocks (the LMI (56)-(62) of :mod:`mascore.observers` for a ring of
300 agents: about 70 times Clarabel's own time). This module holds the few pieces that let a
caller assemble the standard form itself with numpy and scipy.sparse:

    minimize    c^T x
    subject to  A x + s = b,   s in K = K_1 x ... x K_p

with ``K_j`` second-order cones or PSD cones in Clarabel's scaled upper-triangle form, and solve
it with the same settings and the same status checks as :func:`mascore._solver.solve`.

The conventions follow the ones cvxpy uses when it calls Clarabel, so that a program assembled
here is the very data cvxpy would have passed (same variable and row order): a symmetric
``k x k`` variable is stored as its upper triangle in row-major order (:func:`sym_basis`), a PSD
cone as ``svec(M)``, the upper triangle in column-major order with the off-diagonal entries
scaled by ``sqrt(2)`` (:func:`svec`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from . import _solver
from ._optional import require
from .exceptions import SolverError

clarabel = require("clarabel", "the LMI programs assembled without cvxpy (mascore.observers)")

__all__ = ["ConicProgram", "SolverStats", "solve", "svec", "svec_size", "sym_basis"]

#: Clarabel's status -> the status name cvxpy reports for it (the names :mod:`mascore._solver` uses).
_STATUS = {
    "Solved": "optimal",
    "AlmostSolved": "optimal_inaccurate",
    "PrimalInfeasible": "infeasible",
    "DualInfeasible": "unbounded",
    "AlmostPrimalInfeasible": "infeasible_inaccurate",
    "AlmostDualInfeasible": "unbounded_inaccurate",
    "MaxIterations": "user_limit",
    "MaxTime": "user_limit",
}

#: Option keys that cvxpy accepts besides Clarabel's settings (not settings of Clarabel).
_CVXPY_ONLY = ("use_quad_obj", "accept_unknown")


def svec_size(k: int) -> int:
    """Length ``k (k + 1) / 2`` of the triangle of a ``k x k`` symmetric matrix.

    Parameters
    ----------
    k : int
        Side of the matrix.

    Returns
    -------
    int
        Number of entries in its upper triangle.

    Examples
    --------
    >>> from mascore._conic import svec_size
    >>> svec_size(4)
    10
    """
    return k * (k + 1) // 2


def _svec_index(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns and scale of the entries of ``svec`` for side `k` (Clarabel's order), computed afresh."""
    rows, cols = np.triu_indices(k)
    order = np.lexsort((rows, cols))  # by column, then row: Clarabel's upper triangle
    rows, cols = rows[order], cols[order]
    scale = np.where(rows == cols, 1.0, math.sqrt(2.0))
    return rows, cols, scale


def svec(M: np.ndarray) -> np.ndarray:
    """Scaled upper triangle of symmetric matrices, the vector form of Clarabel's PSD triangle cone.

    Parameters
    ----------
    M : (..., k, k) ndarray
        Symmetric matrices (only the upper triangle is read).

    Returns
    -------
    (..., k (k + 1) / 2) ndarray
        ``M[0, 0], sqrt(2) M[0, 1], M[1, 1], sqrt(2) M[0, 2], ...``: the upper triangle by columns,
        the off-diagonal entries times ``sqrt(2)`` (so that ``svec(X) . svec(Y) = trace(X Y)``).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore._conic import svec
    >>> svec(np.array([[1.0, 2.0], [2.0, 3.0]])).round(4)
    array([1.    , 2.8284, 3.    ])
    """
    rows, cols, scale = _svec_index(M.shape[-1])
    return M[..., rows, cols] * scale


def sym_basis(k: int) -> np.ndarray:
    """Basis of the symmetric ``k x k`` matrices in which a symmetric variable is stored.

    Parameters
    ----------
    k : int
        Side of the matrix.

    Returns
    -------
    (k (k + 1) / 2, k, k) ndarray
        ``E_ab = e_a e_b^T + e_b e_a^T`` (``e_a e_a^T`` on the diagonal) for ``a <= b`` in row-major
        order, so that ``X = sum_j x_j E_j`` has ``X[a, b] = x_j``: the layout of a symmetric
        ``cvxpy.Variable``.

    Examples
    --------
    >>> from mascore._conic import sym_basis
    >>> sym_basis(2)[1]
    array([[0., 1.],
           [1., 0.]])
    """
    a, b = np.triu_indices(k)
    E = np.zeros((a.size, k, k))
    idx = np.arange(a.size)
    E[idx, a, b] = 1.0
    E[idx, b, a] = 1.0
    return E


@dataclass
class SolverStats:
    """What Clarabel reports besides the solution (the fields of ``cvxpy.Problem.solver_stats`` used here).

    Parameters
    ----------
    solve_time : float or None
        Seconds spent inside Clarabel's ``solve``.
    num_iters : int or None
        Interior-point iterations.

    Examples
    --------
    >>> from mascore._conic import SolverStats
    >>> SolverStats().solve_time is None
    True
    """

    solve_time: float | None = None
    num_iters: int | None = None


@dataclass
class ConicProgram:
    """``minimize c^T x  subject to  A x + s = b, s in cones``: Clarabel's standard form, assembled by the caller.

    Parameters
    ----------
    c : (n,) ndarray
        Linear objective.
    A : (r, n) scipy.sparse matrix
        Constraint matrix.
    b : (r,) ndarray
        Constraint offset.
    cones : list
        Clarabel cones (``clarabel.SecondOrderConeT``, ``clarabel.PSDTriangleConeT``, ...) whose
        dimensions add up to ``r``, in row order.

    Attributes
    ----------
    status : str or None
        After :meth:`solve`: the status in cvxpy's words (``"optimal"``, ``"optimal_inaccurate"``,
        ``"infeasible"``, ``"user_limit"``, ``"solver_error"``, ...).
    x : (n,) ndarray or None
        After :meth:`solve`: the primal solution (None without one).
    value : float or None
        After :meth:`solve`: ``c^T x`` (None without a solution).
    solver_stats : SolverStats
        Solve time and iterations of the last solve.

    Examples
    --------
    >>> import clarabel, numpy as np, scipy.sparse as sp
    >>> from mascore._conic import ConicProgram
    >>> prog = ConicProgram(np.array([1.0]), sp.csc_matrix([[-1.0]]), np.array([-2.0]),
    ...                     [clarabel.NonnegativeConeT(1)])          # min x  s.t.  x >= 2
    >>> round(prog.solve(), 6), prog.status
    (2.0, 'optimal')
    """

    c: np.ndarray
    A: sp.spmatrix
    b: np.ndarray
    cones: list
    status: str | None = field(default=None, init=False)
    x: np.ndarray | None = field(default=None, init=False, repr=False)
    value: float | None = field(default=None, init=False)
    solver_stats: SolverStats = field(default_factory=SolverStats, init=False)

    def solve(self, options: Mapping[str, Any] | None = None) -> float | None:
        """Run Clarabel; set :attr:`status`, :attr:`x`, :attr:`value` and :attr:`solver_stats`.

        Parameters
        ----------
        options : mapping, optional
            Clarabel settings by name (default :data:`mascore._solver.SOLVER_OPTIONS`). The cvxpy
            keys ``use_quad_obj`` (ignored) and ``accept_unknown`` (an 'InsufficientProgress' stop
            with a solution counts as ``optimal_inaccurate``) are accepted as cvxpy accepts them.

        Returns
        -------
        float or None
            ``c^T x`` if a solution is present, else None.

        Raises
        ------
        TypeError
            An option that is not a Clarabel setting, or a setting of the wrong type.
        """
        opts = _solver.solver_options(options)
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        for key, val in opts.items():
            if key in _CVXPY_ONLY:
                continue
            try:
                setattr(settings, key, val)
            except TypeError as exc:
                raise TypeError(f"Clarabel: Incorrect type for setting '{key}'.") from exc
            except AttributeError as exc:
                raise TypeError(f"Clarabel: unrecognized solver setting '{key}'.") from exc
        n = self.c.size
        A = sp.csc_matrix(self.A)
        P = sp.csc_matrix((n, n))
        result = clarabel.DefaultSolver(P, self.c, A, self.b, self.cones, settings).solve()
        raw = str(result.status)
        status = _STATUS.get(raw, "solver_error")
        has_solution = result.x is not None and result.z is not None
        if raw == "InsufficientProgress" and opts.get("accept_unknown") and has_solution:
            status = "optimal_inaccurate"
        self.status = status
        self.solver_stats = SolverStats(solve_time=result.solve_time, num_iters=result.iterations)
        if status in ("optimal", "optimal_inaccurate") and result.x is not None:
            self.x = np.asarray(result.x, dtype=float)
            self.value = float(self.c @ self.x)
        else:
            self.x, self.value = None, None
        return self.value


def solve(problem: Any, what: str, options: Mapping[str, Any] | None = None) -> float:
    """Solve a :class:`ConicProgram` (or a cvxpy problem) with Clarabel; raise unless optimal.

    The checks and messages are those of :func:`mascore._solver.solve`, to which a
    ``cvxpy.Problem`` is passed on unchanged.

    Parameters
    ----------
    problem : ConicProgram or cvxpy.Problem
        The program.
    what : str
        Names the program in the error.
    options : mapping, optional
        Clarabel settings (default :data:`mascore._solver.SOLVER_OPTIONS`).

    Returns
    -------
    float
        The optimal value.

    Raises
    ------
    SolverError
        If the solver fails, the status is not ``optimal`` or the optimal value is not finite.
    TypeError
        If `what` is not a string or `options` not a mapping of Clarabel settings.

    Examples
    --------
    >>> import clarabel, numpy as np, scipy.sparse as sp
    >>> from mascore._conic import ConicProgram, solve
    >>> prog = ConicProgram(np.array([1.0]), sp.csc_matrix([[1.0]]), np.array([-2.0]),
    ...                     [clarabel.NonnegativeConeT(1)])          # min x  s.t.  x <= -2
    >>> solve(prog, "toy")
    Traceback (most recent call last):
    ...
    mascore.exceptions.SolverError: toy: solver status is 'unbounded', expected 'optimal'
    """
    if not isinstance(problem, ConicProgram):
        return _solver.solve(problem, what, options)
    if not isinstance(what, str):
        raise TypeError(f"what must be a string naming the program; got {type(what).__name__}")
    value = problem.solve(options)
    if problem.status == "solver_error":
        raise SolverError(f"{what}: the solver {_solver.SOLVER} failed: Clarabel stopped without a solution")
    return _solver.optimal_value(what, problem.status, value)
