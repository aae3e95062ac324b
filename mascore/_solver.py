"""Solver settings for every SDP/LMI in mascore, kept in one place.

All convex programs are solved with Clarabel (an interior-point conic solver),
never with cvxpy's default choice, and the status is always checked. The public
functions that solve a program take ``solver_options`` (a dict passed to
Clarabel through cvxpy, e.g. ``{"tol_gap_abs": 1e-7, "max_iter": 500}``) whose
default is :data:`SOLVER_OPTIONS`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import ModuleType
from typing import TYPE_CHECKING, Any

from ._optional import require
from .exceptions import SolverError

if TYPE_CHECKING:
    import cvxpy as cp

__all__ = ["LMI_EPS", "SOLVER", "SOLVER_OPTIONS", "SolverError", "optimal_value", "solve", "solver_options"]

#: cvxpy solver used for every SDP/LMI (the value of ``cvxpy.CLARABEL``; cvxpy is imported only to solve).
SOLVER = "CLARABEL"

# The statuses optimal_value tells apart, in cvxpy's words (the values of cvxpy.OPTIMAL, cvxpy.OPTIMAL_INACCURATE).
_OPTIMAL, _OPTIMAL_INACCURATE = "optimal", "optimal_inaccurate"

#: What cvxpy is needed for, in the message of a missing ``sdp`` extra.
CVXPY_PURPOSE = "the SDPs and LMIs (set-membership method='sdp', the distributed observer, the bottom-up LQR)"


#: Default options passed to the solver (Clarabel's own defaults).
SOLVER_OPTIONS: dict = {}

#: Margin standing in for a strict LMI inequality (``X >> LMI_EPS * I``).
LMI_EPS = 1e-9


def _cvxpy() -> ModuleType:
    """cvxpy, imported where a program is solved (importing this module, or the observers, does not pay for it)."""
    return require("cvxpy", CVXPY_PURPOSE)


def solver_options(options: Mapping[str, Any] | None) -> dict:
    """Check `options` (a mapping of Clarabel settings, or None for :data:`SOLVER_OPTIONS`) and copy it.

    Parameters
    ----------
    options : mapping or None
        Solver settings by name, passed to ``cvxpy.Problem.solve``.

    Returns
    -------
    dict
        The options to pass.

    Raises
    ------
    TypeError
        If `options` is not a mapping with string keys.

    Examples
    --------
    >>> from mascore._solver import solver_options
    >>> solver_options({"max_iter": 200})
    {'max_iter': 200}
    """
    if options is None:
        return dict(SOLVER_OPTIONS)
    if not isinstance(options, Mapping) or not all(isinstance(k, str) for k in options):
        raise TypeError(f"solver_options must be a dict of Clarabel settings by name; got {options!r}")
    return dict(options)


def solve(problem: cp.Problem, what: str, options: Mapping[str, Any] | None = None) -> float:
    """Solve `problem` with :data:`SOLVER`; raise unless the status is optimal.

    Parameters
    ----------
    problem : cvxpy.Problem
        The program.
    what : str
        Names the program in the error (e.g. ``"correction SDP, agent 2, step 14"``).
    options : mapping, optional
        Solver settings (default :data:`SOLVER_OPTIONS`).

    Returns
    -------
    float
        The optimal value.

    Raises
    ------
    SolverError
        If the solver fails, the status is not ``optimal`` or the optimal value is not finite.
    TypeError
        If `problem` is not a :class:`cvxpy.Problem`, `what` not a string or `options` not a mapping.
    """
    cp = _cvxpy()
    if not isinstance(problem, cp.Problem):
        raise TypeError(f"problem must be a cvxpy.Problem; got {type(problem).__name__}")
    if not isinstance(what, str):
        raise TypeError(f"what must be a string naming the program; got {type(what).__name__}")
    opts = solver_options(options)
    # problem.solve in its public steps, deciding from the status instead of cvxpy's warning (so that no
    # process-wide warning filter is touched): compile (cached by cvxpy for a parametrized program), solve, invert
    data, chain, inverse = problem.get_problem_data(SOLVER, solver_opts=opts)
    try:
        solution = chain.invert(chain.solve_via_data(problem, data, True, False, opts), inverse)
    except cp.error.SolverError as exc:
        raise SolverError(f"{what}: the solver {SOLVER} failed: {exc}") from exc
    if solution.status in cp.settings.ERROR:
        raise SolverError(f"{what}: the solver {SOLVER} failed (status {solution.status!r})")
    problem.unpack(solution)  # status, value and variables, as problem.solve leaves them (infeasible included)
    return optimal_value(what, problem.status, problem.value)


def optimal_value(what: str, status: str, value: float | None) -> float:
    """`value` if `status` is ``"optimal"`` and the value finite; a :class:`SolverError` naming `what` otherwise.

    Parameters
    ----------
    what : str
        Names the program in the error.
    status : str
        The solver status, in cvxpy's words (``"optimal"``, ``"optimal_inaccurate"``, ``"infeasible"``, ...).
    value : float or None
        The reported optimal value.

    Returns
    -------
    float
        The optimal value.

    Raises
    ------
    SolverError
        If the status is not ``optimal`` (with a hint for ``optimal_inaccurate``) or the value not finite.

    Examples
    --------
    >>> from mascore._solver import optimal_value
    >>> optimal_value("toy", "optimal", 2.0)
    2.0
    """
    if status != _OPTIMAL:
        hint = (" (pass looser tolerances or more iterations in solver_options, e.g. "
                "{'max_iter': 1000, 'tol_feas': 1e-7})") if status == _OPTIMAL_INACCURATE else ""
        raise SolverError(f"{what}: solver status is {status!r}, expected 'optimal'{hint}")
    if value is None or not math.isfinite(float(value)):
        raise SolverError(f"{what}: the solver reported 'optimal' with a non-finite value {value!r}")
    return float(value)
