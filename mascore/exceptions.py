"""The exceptions mascore raises beyond Python's own, all in one place (no optional dependency).

Each one subclasses the built-in exception a caller would already catch, so
``except ValueError`` still works; catch the specific class to react to one cause.
They are exported from the package: ``from mascore import SolverError``.
"""

from __future__ import annotations

__all__ = [
    "ConsensusBreakdownError",
    "DivergenceError",
    "IsolatedAgentError",
    "RiccatiError",
    "SolverError",
]


class SolverError(RuntimeError):
    """A convex program (SDP/LMI) was infeasible, unbounded or not solved to optimality.

    The message names the program (e.g. ``"correction SDP eq. (6), agent 2, step 14"``) and
    the solver's status. ``optimal_inaccurate`` is refused too; pass looser or tighter solver
    options (the ``solver_options`` keyword of the function that solved it) to change that.

    Examples
    --------
    >>> from mascore import SolverError
    >>> issubclass(SolverError, RuntimeError)
    True
    """


class RiccatiError(ArithmeticError):
    """The algebraic Riccati equation has no stabilizing solution, or it was solved inaccurately.

    Examples
    --------
    >>> from mascore import RiccatiError
    >>> issubclass(RiccatiError, ArithmeticError)
    True
    """


class IsolatedAgentError(ValueError):
    """An agent has no neighbour, so it cannot sense anyone but itself.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import IsolatedAgentError, sensing
    >>> try:
    ...     sensing.sensing_mask(np.zeros((3, 3)))
    ... except IsolatedAgentError as exc:
    ...     print(type(exc).__name__)
    IsolatedAgentError
    """


class ConsensusBreakdownError(ValueError, FloatingPointError):
    """The covariances of a Kalman consensus run left double precision (e.g. zero communication noise).

    Raised with the step (or time) where ``P`` underflowed to zero, lost positivity or
    overflowed, and what to change; a ``ValueError`` (the arguments ask for more than floating
    point can hold) and a ``FloatingPointError``.

    Examples
    --------
    >>> from mascore import ConsensusBreakdownError
    >>> issubclass(ConsensusBreakdownError, ValueError)
    True
    """


class DivergenceError(FloatingPointError):
    """The sampled closed loop blew up (raised instead of returning overflowed states).

    With the fully-connected flocking law every agent feels N - 1 springs and dampers, so the
    loop gain grows with N; with the gains of Song et al. (2023), Table I, and dt = 0.1 s the
    sampled loop is unstable from about N = 18.

    Examples
    --------
    >>> from mascore import DivergenceError
    >>> issubclass(DivergenceError, FloatingPointError)
    True
    """
