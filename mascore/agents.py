"""Agent models: discrete-time linear agents and their team-level stacking.

A team of N identical agents with state ``x_i`` of size ``m`` is stacked as
``X = [x_1; ...; x_N]`` (size ``m N``). Identical decoupled dynamics then read
``X[k+1] = (I_N kron A) X[k] + (I_N kron B) U[k]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_matrix, check_positive, check_positive_int, check_square
from ._validation import require_finite as _finite
from ._validation import float_array as _float_array

__all__ = [
    "LTIAgent",
    "double_integrator",
    "team_matrices",
    "team_state",
    "agent_states",
]


@dataclass(frozen=True)
class LTIAgent:
    """A discrete-time linear agent ``x[k+1] = A x[k] + B u[k]``.

    Parameters
    ----------
    A : (m, m) ndarray
        State-transition matrix.
    B : (m, p) ndarray
        Input matrix.
    """

    A: np.ndarray
    B: np.ndarray

    def __post_init__(self) -> None:
        A = check_square(_float_array(self.A, "A"), "A")
        if A.shape[0] == 0:
            raise ValueError("A must be at least 1 x 1 (an agent with no state)")
        B = as_matrix(_float_array(self.B, "B"), "B", (A.shape[0], None))
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)

    @property
    def n_states(self) -> int:
        """State dimension m."""
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        """Input dimension p."""
        return self.B.shape[1]

    def step(self, x: ArrayLike, u: ArrayLike) -> np.ndarray:
        """One step for a state ``(..., m)`` and input ``(..., p)`` (batched, finite)."""
        x = _finite(_float_array(x, "x"), "x")
        u = _finite(_float_array(u, "u"), "u")
        if x.ndim < 1 or x.shape[-1] != self.n_states:
            raise ValueError(f"Incompatible dimensions of x; expected (..., {self.n_states}) but found {x.shape}")
        if u.ndim < 1 or u.shape[-1] != self.n_inputs:
            raise ValueError(f"Incompatible dimensions of u; expected (..., {self.n_inputs}) but found {u.shape}")
        try:
            return x @ self.A.T + u @ self.B.T
        except ValueError:
            raise ValueError(f"the batch axes of x {x.shape} and u {u.shape} do not broadcast") from None

    def team(self, n_agents: int) -> "LTIAgent":
        """The stacked team ``(I_N kron A, I_N kron B)`` as one LTI system."""
        return LTIAgent(*team_matrices(self.A, self.B, n_agents))


def double_integrator(n: int, dt: float) -> LTIAgent:
    """The n-dimensional double integrator sampled with step `dt`.

    State ``x = [p; v]`` (position in m, velocity in m/s), input acceleration
    ``u`` (m/s^2), zero-order hold on the input (Song et al. 2023, eq. (1))::

        A = [[I_n, dt I_n], [0, I_n]],   B = [[dt^2/2 I_n], [dt I_n]]

    Parameters
    ----------
    n : int
        Spatial dimension (2 for the plane).
    dt : float
        Sampling time (s), positive.
    """
    n = check_positive_int(n, "n")
    check_positive(dt, "dt", "seconds (the sampling time)")
    eye = np.eye(n)
    A = np.block([[eye, dt * eye], [np.zeros((n, n)), eye]])
    B = np.vstack([0.5 * dt**2 * eye, dt * eye])
    return LTIAgent(A, B)


def team_matrices(A: ArrayLike, B: ArrayLike, n_agents: int) -> tuple[np.ndarray, np.ndarray]:
    """Block-diagonal team matrices ``(I_N kron A, I_N kron B)``."""
    A = check_square(_float_array(A, "A"), "A")
    B = as_matrix(_float_array(B, "B"), "B", (A.shape[0], None))
    n_agents = check_positive_int(n_agents, "n_agents")
    eye = np.eye(n_agents)
    return np.kron(eye, A), np.kron(eye, B)


def team_state(agent_states_: ArrayLike) -> np.ndarray:
    """Stack per-agent states ``(..., N, m)`` into team vectors ``(..., N m)``."""
    x = _finite(_float_array(agent_states_, "agent_states_"), "agent_states_")
    if x.ndim < 2:
        raise ValueError(f"agent_states_ (the per-agent states) must have shape (..., N, m); got {x.shape}")
    return x.reshape(*x.shape[:-2], x.shape[-2] * x.shape[-1])


def agent_states(team: ArrayLike, n_states: int) -> np.ndarray:
    """Split team vectors ``(..., N m)`` into per-agent states ``(..., N, m)``."""
    n_states = check_positive_int(n_states, "n_states")
    X = _finite(_float_array(team, "team"), "team")
    if X.ndim < 1:
        raise ValueError("team must have shape (..., N m); got a scalar")
    if X.shape[-1] % n_states:
        raise ValueError(
            f"team state length {X.shape[-1]} is not a multiple of n_states={n_states}"
        )
    return X.reshape(*X.shape[:-1], X.shape[-1] // n_states, n_states)
