"""Solver settings for every SDP/LMI in mascore, kept in one place.

All convex programs are solved with Clarabel (an interior-point conic solver),
never with cvxpy's default choice, and the status is always checked.
"""

from __future__ import annotations

import math

import cvxpy as cp

__all__ = ["LMI_EPS", "SOLVER", "SOLVER_OPTIONS", "SolverError", "solve"]

#: cvxpy solver used for every SDP/LMI.
SOLVER = cp.CLARABEL

#: Options passed to the solver.
SOLVER_OPTIONS: dict = {}

#: Margin standing in for a strict LMI inequality (``X >> LMI_EPS * I``).
LMI_EPS = 1e-9


class SolverError(RuntimeError):
    """A convex program was infeasible, unbounded or not solved to optimality."""


def solve(problem: cp.Problem, what: str) -> float:
    """Solve `problem` with :data:`SOLVER`; raise unless the status is optimal.

    Parameters
    ----------
    problem : cvxpy.Problem
    what : str
        Names the program in the error (e.g. ``"correction SDP, agent 2, step 14"``).

    Returns
    -------
    float
        The optimal value.

    Raises
    ------
    SolverError
        If the solver fails, the status is not ``optimal`` or the optimal value is not finite.
    TypeError
        If `problem` is not a :class:`cvxpy.Problem` or `what` not a string.
    """
    if not isinstance(problem, cp.Problem):
        raise TypeError(f"problem must be a cvxpy.Problem; got {type(problem).__name__}")
    if not isinstance(what, str):
        raise TypeError(f"what must be a string naming the program; got {type(what).__name__}")
    try:
        value = problem.solve(solver=SOLVER, **SOLVER_OPTIONS)
    except cp.error.SolverError as exc:
        raise SolverError(f"{what}: the solver {SOLVER} failed: {exc}") from exc
    if problem.status != cp.OPTIMAL:
        raise SolverError(f"{what}: solver status is {problem.status!r}, expected 'optimal'")
    if value is None or not math.isfinite(float(value)):
        raise SolverError(f"{what}: the solver reported 'optimal' with a non-finite value {value!r}")
    return float(value)
