"""Agent models: discrete-time linear agents and their team-level stacking.

A team of N identical agents with state ``x_i`` of size ``m`` is stacked as
``X = [x_1; ...; x_N]`` (size ``m N``). Identical decoupled dynamics then read
``X[k+1] = (I_N kron A) X[k] + (I_N kron B) U[k]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_matrix, check_square

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
        A = check_square(self.A, "A")
        B = as_matrix(self.B, "B", (A.shape[0], None))
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
        """One step for a state ``(..., m)`` and input ``(..., p)`` (batched)."""
        return np.asarray(x) @ self.A.T + np.asarray(u) @ self.B.T

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
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer; got {n!r}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be a positive number of seconds; got {dt!r}")
    eye = np.eye(n)
    A = np.block([[eye, dt * eye], [np.zeros((n, n)), eye]])
    B = np.vstack([0.5 * dt**2 * eye, dt * eye])
    return LTIAgent(A, B)


def team_matrices(A: ArrayLike, B: ArrayLike, n_agents: int) -> tuple[np.ndarray, np.ndarray]:
    """Block-diagonal team matrices ``(I_N kron A, I_N kron B)``."""
    A = check_square(A, "A")
    B = as_matrix(B, "B", (A.shape[0], None))
    if isinstance(n_agents, bool) or not isinstance(n_agents, (int, np.integer)) or n_agents < 1:
        raise ValueError(f"n_agents must be a positive integer; got {n_agents!r}")
    eye = np.eye(n_agents)
    return np.kron(eye, A), np.kron(eye, B)


def team_state(agent_states_: ArrayLike) -> np.ndarray:
    """Stack per-agent states ``(..., N, m)`` into team vectors ``(..., N m)``."""
    x = np.asarray(agent_states_, dtype=float)
    if x.ndim < 2:
        raise ValueError(f"agent states must have shape (..., N, m); got {x.shape}")
    return x.reshape(*x.shape[:-2], x.shape[-2] * x.shape[-1])


def agent_states(team: ArrayLike, n_states: int) -> np.ndarray:
    """Split team vectors ``(..., N m)`` into per-agent states ``(..., N, m)``."""
    X = np.asarray(team, dtype=float)
    if X.shape[-1] % n_states:
        raise ValueError(
            f"team state length {X.shape[-1]} is not a multiple of n_states={n_states}"
        )
    return X.reshape(*X.shape[:-1], X.shape[-1] // n_states, n_states)
