"""Agent models: discrete-time linear agents and their team-level stacking.

A team of N identical agents with state ``x_i`` of size ``m`` is stacked as
``X = [x_1; ...; x_N]`` (size ``m N``). Identical decoupled dynamics then read
``X[k+1] = (I_N kron A) X[k] + (I_N kron B) U[k]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._validation import Frozen, as_matrix, check_positive, check_positive_int, check_square, frozen_copy
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite

__all__ = [
    "LTIAgent",
    "double_integrator",
    "zoh",
    "team_matrices",
    "team_state",
    "agent_states",
]


@dataclass(frozen=True, eq=False)
class LTIAgent(Frozen):
    """A discrete-time linear agent ``x[k+1] = A x[k] + B u[k]``.

    Parameters
    ----------
    A : (m, m) array_like
        State-transition matrix (over one sampling period).
    B : (m, p) array_like
        Input matrix.
    dt : float, optional
        Sampling time (s) the agent was discretized with. A model built from the
        agent (e.g. ``mascore.rendezvous.RendezvousModel.from_agent``) takes its
        time base from here, and refuses a ``dt`` that contradicts it.
    A_c, B_c : array_like, optional
        The continuous-time agent ``x' = A_c x + B_c u`` that ``(A, B)`` samples with a
        zero-order hold over `dt` (both or neither, and only with `dt`); then
        ``A == expm(A_c dt)`` and ``B == int_0^dt expm(A_c s) ds B_c`` are checked.
        :meth:`from_continuous` computes ``(A, B)`` from them.

    Raises
    ------
    ValueError
        A not square, B with a different number of rows, a non-positive `dt`, or
        ``(A, B)`` that is not the zero-order-hold sampling of ``(A_c, B_c)`` over `dt`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.agents import LTIAgent
    >>> agent = LTIAgent(A=[[1.0, 0.1], [0.0, 1.0]], B=[[0.0], [0.1]])
    >>> agent.n_states, agent.n_inputs
    (2, 1)
    """

    A: np.ndarray
    B: np.ndarray
    dt: float | None = None
    A_c: np.ndarray | None = None
    B_c: np.ndarray | None = None

    def __post_init__(self) -> None:
        A = check_square(_float_array(self.A, "A"), "A")
        if A.shape[0] == 0:
            raise ValueError("A must be at least 1 x 1 (an agent with no state)")
        B = as_matrix(_float_array(self.B, "B"), "B", (A.shape[0], None))
        self._set(A=frozen_copy(A), B=frozen_copy(B))
        if self.dt is not None:
            self._set(dt=check_positive(self.dt, "dt", "seconds (the sampling time)"))
        if (self.A_c is None) != (self.B_c is None):
            raise ValueError("give both A_c and B_c (the continuous-time agent), or neither")
        if self.A_c is not None:
            if self.dt is None:
                raise ValueError("A_c and B_c need dt, the sampling time (s) that (A, B) samples them with")
            A_c = check_square(_float_array(self.A_c, "A_c"), "A_c", A.shape[0])
            B_c = as_matrix(_float_array(self.B_c, "B_c"), "B_c", B.shape)
            Ad, Bd = zoh(A_c, B_c, self.dt)
            for name, given, sampled in (("A", A, Ad), ("B", B, Bd)):
                if not np.allclose(given, sampled, rtol=1e-8, atol=1e-10 * max(1.0, float(np.abs(sampled).max()))):
                    raise ValueError(
                        f"{name} is not the zero-order-hold sampling of (A_c, B_c) over dt = {self.dt:g} s "
                        f"(largest difference {float(np.abs(given - sampled).max()):.3g}): the time base contradicts "
                        f"the matrices; use LTIAgent.from_continuous(A_c, B_c, dt)"
                    )
            self._set(A_c=frozen_copy(A_c), B_c=frozen_copy(B_c))

    @classmethod
    def from_continuous(cls, A_c: ArrayLike, B_c: ArrayLike, dt: float) -> LTIAgent:
        """The agent ``x' = A_c x + B_c u`` sampled with a zero-order hold over `dt` (s).

        Parameters
        ----------
        A_c : (m, m) array_like
            Continuous-time state matrix (1/s).
        B_c : (m, p) array_like
            Continuous-time input matrix.
        dt : float
            Sampling time (s), positive.

        Returns
        -------
        LTIAgent
            ``A = expm(A_c dt)``, ``B = int_0^dt expm(A_c s) ds B_c``, carrying `dt`,
            `A_c` and `B_c`.

        Examples
        --------
        >>> from mascore.agents import LTIAgent
        >>> agent = LTIAgent.from_continuous([[0.0, 1.0], [0.0, -1.0]], [[0.0], [1.0]], 0.1)   # damped cart
        >>> agent.dt, agent.A.round(4).tolist()
        (0.1, [[1.0, 0.0952], [0.0, 0.9048]])
        """
        dt = check_positive(dt, "dt", "seconds (the sampling time)")
        A_c = check_square(_float_array(A_c, "A_c"), "A_c")
        B_c = as_matrix(_float_array(B_c, "B_c"), "B_c", (A_c.shape[0], None))
        A, B = zoh(A_c, B_c, dt)
        return cls(A, B, dt, A_c, B_c)

    @property
    def n_states(self) -> int:
        """State dimension m.

        Returns
        -------
        int
            Number of rows of ``A``.
        """
        return self.A.shape[0]

    @property
    def n_inputs(self) -> int:
        """Input dimension p.

        Returns
        -------
        int
            Number of columns of ``B``.
        """
        return self.B.shape[1]

    def step(self, x: ArrayLike, u: ArrayLike) -> np.ndarray:
        """One step ``A x + B u`` for a state ``(..., m)`` and an input ``(..., p)`` (batched).

        Parameters
        ----------
        x : (..., m) array_like
            Current state(s), finite.
        u : (..., p) array_like
            Input(s), finite; the batch axes broadcast against those of `x`.

        Returns
        -------
        (..., m) ndarray
            The next state(s).

        Raises
        ------
        ValueError
            Non-finite entries, wrong last dimensions or batch axes that do not broadcast.

        Examples
        --------
        >>> from mascore import agents
        >>> agent = agents.double_integrator(1, 0.5)           # position, velocity
        >>> agent.step([0.0, 1.0], [2.0])                      # p + v dt + a dt^2 / 2, v + a dt
        array([0.75, 2.  ])
        """
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

    def team(self, n_agents: int) -> LTIAgent:
        """The stacked team ``(I_N kron A, I_N kron B)`` as one LTI system.

        Parameters
        ----------
        n_agents : int
            Number of identical agents N.

        Returns
        -------
        LTIAgent
            The team, with ``N m`` states and ``N p`` inputs.

        Examples
        --------
        >>> from mascore import agents
        >>> agents.double_integrator(2, 0.1).team(3).A.shape
        (12, 12)
        """
        return LTIAgent(*team_matrices(self.A, self.B, n_agents), dt=self.dt)


def zoh(A_c: ArrayLike, B_c: ArrayLike, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold sampling ``(expm(A_c dt), int_0^dt expm(A_c s) ds B_c)`` of a continuous-time agent.

    Parameters
    ----------
    A_c : (m, m) array_like
        Continuous-time state matrix (1/s).
    B_c : (m, p) array_like
        Continuous-time input matrix.
    dt : float
        Sampling time (s), positive.

    Returns
    -------
    A : (m, m) ndarray
    B : (m, p) ndarray

    Examples
    --------
    >>> from mascore import agents
    >>> A, B = agents.zoh([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], 0.1)      # the double integrator
    >>> B.round(4).tolist()
    [[0.005], [0.1]]
    """
    from scipy.linalg import expm

    dt = check_positive(dt, "dt", "seconds (the sampling time)")
    A_c = check_square(_float_array(A_c, "A_c"), "A_c")
    B_c = as_matrix(_float_array(B_c, "B_c"), "B_c", (A_c.shape[0], None))
    m, p = B_c.shape
    block = np.zeros((m + p, m + p))
    block[:m, :m], block[:m, m:] = A_c * dt, B_c * dt
    E = expm(block)
    if not np.all(np.isfinite(E)):
        raise ValueError(f"expm(A_c dt) overflows floating point for dt = {dt:g} s: A_c is too large for this dt")
    return E[:m, :m], E[:m, m:]


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

    Returns
    -------
    LTIAgent
        ``2n`` states, ``n`` inputs, carrying `dt`.

    Examples
    --------
    >>> from mascore import agents
    >>> agent = agents.double_integrator(1, 0.1)
    >>> agent.A
    array([[1. , 0.1],
           [0. , 1. ]])
    >>> agent.B
    array([[0.005],
           [0.1  ]])
    """
    n = check_positive_int(n, "n")
    check_positive(dt, "dt", "seconds (the sampling time)")
    eye = np.eye(n)
    A = np.block([[eye, dt * eye], [np.zeros((n, n)), eye]])
    B = np.vstack([0.5 * dt**2 * eye, dt * eye])
    return LTIAgent(A, B, dt=float(dt))


def team_matrices(A: ArrayLike, B: ArrayLike, n_agents: int) -> tuple[np.ndarray, np.ndarray]:
    """Block-diagonal team matrices ``(I_N kron A, I_N kron B)``.

    Parameters
    ----------
    A : (m, m) array_like
        Agent state matrix.
    B : (m, p) array_like
        Agent input matrix.
    n_agents : int
        Number of agents N.

    Returns
    -------
    A_team : (N m, N m) ndarray
        ``I_N kron A``.
    B_team : (N m, N p) ndarray
        ``I_N kron B``.

    Examples
    --------
    >>> from mascore import agents
    >>> A_team, B_team = agents.team_matrices([[1.0]], [[0.5]], 3)
    >>> B_team
    array([[0.5, 0. , 0. ],
           [0. , 0.5, 0. ],
           [0. , 0. , 0.5]])
    """
    A = check_square(_float_array(A, "A"), "A")
    B = as_matrix(_float_array(B, "B"), "B", (A.shape[0], None))
    n_agents = check_positive_int(n_agents, "n_agents")
    eye = np.eye(n_agents)
    return np.kron(eye, A), np.kron(eye, B)


def team_state(agent_states_: ArrayLike) -> np.ndarray:
    """Stack per-agent states ``(..., N, m)`` into team vectors ``(..., N m)``.

    Parameters
    ----------
    agent_states_ : (..., N, m) array_like
        One state per agent (leading axes kept).

    Returns
    -------
    (..., N m) ndarray
        Agent 0's state first, then agent 1's, ...

    Examples
    --------
    >>> from mascore import agents
    >>> agents.team_state([[1.0, 2.0], [3.0, 4.0]])
    array([1., 2., 3., 4.])
    """
    x = _finite(_float_array(agent_states_, "agent_states_"), "agent_states_")
    if x.ndim < 2:
        raise ValueError(f"agent_states_ (the per-agent states) must have shape (..., N, m); got {x.shape}")
    return x.reshape(*x.shape[:-2], x.shape[-2] * x.shape[-1])


def agent_states(team: ArrayLike, n_states: int) -> np.ndarray:
    """Split team vectors ``(..., N m)`` into per-agent states ``(..., N, m)``.

    The inverse of :func:`team_state`.

    Parameters
    ----------
    team : (..., N m) array_like
        Team vectors.
    n_states : int
        State dimension m of one agent (must divide the last axis).

    Returns
    -------
    (..., N, m) ndarray
        One row per agent.

    Examples
    --------
    >>> from mascore import agents
    >>> agents.agent_states([1.0, 2.0, 3.0, 4.0], 2)
    array([[1., 2.],
           [3., 4.]])
    """
    n_states = check_positive_int(n_states, "n_states")
    X = _finite(_float_array(team, "team"), "team")
    if X.ndim < 1:
        raise ValueError("team must have shape (..., N m); got a scalar")
    if X.shape[-1] % n_states:
        raise ValueError(
            f"team state length {X.shape[-1]} is not a multiple of n_states={n_states}"
        )
    return X.reshape(*X.shape[:-1], X.shape[-1] // n_states, n_states)
