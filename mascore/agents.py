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
    "is_system",
    "system_matrices",
    "check_sampling_time",
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
        if _sampled_with(self.A) is not None:
            object.__setattr__(self, "dt", check_sampling_time(self.A, self.dt))
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
            self._set(A=_SampledMatrix.tag(A, self.dt))  # so a later contradicting dt is caught

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
        ``2n`` states, ``n`` inputs, carrying `dt` and both time bases: the sampled
        ``(A, B)`` and the continuous ``A_c = [[0, I], [0, 0]]``, ``B_c = [[0], [I]]``.

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
    >>> agent.A_c                                          # the continuous-time agent it samples
    array([[0., 1.],
           [0., 0.]])
    """
    n = check_positive_int(n, "n")
    check_positive(dt, "dt", "seconds (the sampling time)")
    eye, zero = np.eye(n), np.zeros((n, n))
    A = np.block([[eye, dt * eye], [zero, eye]])
    B = np.vstack([0.5 * dt**2 * eye, dt * eye])
    A_c = np.block([[zero, eye], [zero, zero]])
    B_c = np.vstack([zero, eye])
    return LTIAgent(A, B, dt=float(dt), A_c=A_c, B_c=B_c)


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


def is_system(obj: object) -> bool:
    """Whether `obj` is a system a design function takes in place of ``(A, B)``.

    An :class:`LTIAgent`, or any object with ``A``, ``B`` and ``dt`` (python-control's
    ``StateSpace``, duck-typed: no import needed); not an array.

    Parameters
    ----------
    obj : object
        Anything.

    Returns
    -------
    bool
        True for a system (read it with :func:`system_matrices`).

    Examples
    --------
    >>> from mascore import agents
    >>> agents.is_system(agents.double_integrator(1, 0.1)), agents.is_system([[1.0]])
    (True, False)
    """
    if isinstance(obj, LTIAgent):
        return True
    return not isinstance(obj, np.ndarray) and all(hasattr(obj, name) for name in ("A", "B", "dt"))


def system_matrices(system: object, time: str | None = None, name: str = "sys",
                    needed_by: str = "") -> tuple[np.ndarray, np.ndarray, float | bool]:
    """``(A, B, dt)`` of a linear system given as an :class:`LTIAgent` or a python-control ``StateSpace``.

    One notion of a system for every design function: an :class:`LTIAgent` (discrete,
    and continuous too when it carries ``A_c, B_c``) or any object with ``A``, ``B``
    and ``dt`` (python-control's ``StateSpace``: ``dt`` 0 or None is continuous time,
    ``dt > 0`` or True discrete). The time base is checked against what the caller
    expects, and a ``dt`` that is negative, NaN or infinite is refused by name.

    Parameters
    ----------
    system : LTIAgent or StateSpace
        The system.
    time : {"continuous", "discrete"}, optional
        The time base the caller needs (default: the system's own). An
        :class:`LTIAgent` built with :meth:`LTIAgent.from_continuous` (or
        :func:`double_integrator`) gives either.
    name : str
        The argument's name in error messages.
    needed_by : str
        What needs that time base, for the error message (e.g. ``"top_down_lqr"``).

    Returns
    -------
    A : (n, n) ndarray
        State matrix (1/s in continuous time, per step in discrete time).
    B : (n, m) ndarray
        Input matrix.
    dt : float or True
        0.0 for continuous time; the sampling time (s), or True when a discrete
        ``StateSpace`` leaves it unspecified.

    Raises
    ------
    TypeError
        `system` is neither an :class:`LTIAgent` nor a state-space object.
    ValueError
        A bad ``dt``, or a system in the other time base (the message says how to convert).

    Examples
    --------
    >>> from mascore import agents
    >>> agent = agents.double_integrator(1, 0.1)
    >>> A, B, dt = agents.system_matrices(agent, "continuous")
    >>> A.tolist(), dt
    ([[0.0, 1.0], [0.0, 0.0]], 0.0)
    >>> agents.system_matrices(agent, "discrete")[2]
    0.1
    """
    if time not in (None, "continuous", "discrete"):
        raise ValueError(f"time must be 'continuous', 'discrete' or None; got {time!r}")
    who = f" ({needed_by} needs {time} time)" if needed_by and time else ""
    if isinstance(system, LTIAgent):
        if time == "continuous":
            if system.A_c is None:
                raise ValueError(
                    f"{name} is a discrete-time LTIAgent without its continuous-time matrices{who}; build it "
                    f"with LTIAgent.from_continuous(A_c, B_c, dt) so that it carries both, or pass (A_c, B_c)")
            return system.A_c, system.B_c, 0.0
        return system.A, system.B, (system.dt if system.dt is not None else True)
    if isinstance(system, np.ndarray) or not all(hasattr(system, a) for a in ("A", "B", "dt")):
        raise TypeError(f"{name} must be an LTIAgent or a state-space system with A, B and dt (a python-control "
                        f"StateSpace); got {type(system).__name__}")
    dt = system.dt
    if dt is None or (dt is not True and isinstance(dt, (int, float, np.integer, np.floating))
                      and not isinstance(dt, bool) and dt == 0):
        dt = 0.0
    elif dt is not True:
        if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)) or not (
                np.isfinite(dt) and dt > 0):
            raise ValueError(f"{name}.dt must be 0 or None (continuous time), True or a finite sampling time > 0 s "
                             f"(discrete time); got {dt!r}")
        dt = float(dt)
    A = check_square(_finite(_float_array(system.A, f"{name}.A"), f"{name}.A"), f"{name}.A")
    B = as_matrix(_finite(_float_array(system.B, f"{name}.B"), f"{name}.B"), f"{name}.B", (A.shape[0], None))
    if time == "continuous" and dt != 0:
        raise ValueError(f"{name} is a discrete-time system (dt = {dt!r}){who}; pass the continuous-time system "
                         f"(before control.c2d), or an LTIAgent built with LTIAgent.from_continuous")
    if time == "discrete" and dt == 0:
        raise ValueError(f"{name} is a continuous-time system (dt = 0){who}; sample it first: control.c2d(sys, dt) "
                         f"or LTIAgent.from_continuous(sys.A, sys.B, dt)")
    return A, B, dt


def check_sampling_time(A: ArrayLike, dt: float | None = None, name: str = "dt") -> float | None:
    """The sampling time of a model built on `A`: `dt`, checked against the one `A` was sampled with.

    The ``A`` of an agent that carries its continuous-time matrices (built by
    :meth:`LTIAgent.from_continuous` or :func:`double_integrator`) remembers the `dt` it
    was sampled with; a `dt` that contradicts it is refused (the time axis would be
    wrong), and a missing `dt` is taken from it. Arrays computed from such an ``A``
    (products, copies, slices) carry nothing, and then `dt` is returned as given.

    Parameters
    ----------
    A : (m, m) array_like
        State matrix, finite.
    dt : float, optional
        The sampling time (s) the caller was given, if any.
    name : str
        Its name in error messages.

    Returns
    -------
    float or None
        The sampling time to use.

    Raises
    ------
    ValueError
        A `dt` that contradicts ``A``, a bad `dt`, or a non-finite or non-square ``A``.

    Examples
    --------
    >>> from mascore import agents
    >>> A = agents.double_integrator(2, 0.05).A
    >>> agents.check_sampling_time(A, None)
    0.05
    >>> agents.check_sampling_time(A, 0.1)                   # doctest: +ELLIPSIS
    Traceback (most recent call last):
        ...
    ValueError: dt = 0.1 s contradicts A, which was sampled over dt = 0.05 s (LTIAgent.from_continuous); ...
    """
    tagged = _sampled_with(A)
    check_square(_finite(_float_array(A, "A"), "A"), "A")
    if dt is not None:
        dt = check_positive(dt, name, "seconds (the sampling time)")
    if tagged is None:
        return dt
    if dt is None:
        return tagged
    if not np.isclose(dt, tagged, rtol=1e-9, atol=0):
        raise ValueError(f"{name} = {dt!r} s contradicts A, which was sampled over dt = {tagged:g} s "
                         f"(LTIAgent.from_continuous); pass {name} = {tagged:g}, or sample the continuous agent again "
                         f"with LTIAgent.from_continuous(A_c, B_c, {dt!r})")
    return dt


def _sampled_with(A: object) -> float | None:
    """The sampling time (s) remembered by a state matrix of :meth:`LTIAgent.from_continuous`, else None."""
    return getattr(A, "_sampled_dt", None) if isinstance(A, _SampledMatrix) else None


class _SampledMatrix(np.ndarray):
    """A read-only state matrix that remembers its sampling time (see :func:`check_sampling_time`)."""

    _sampled_dt: float | None = None

    @classmethod
    def tag(cls, A: np.ndarray, dt: float) -> np.ndarray:
        view = frozen_copy(A).view(cls)  # on immutable memory: no .base can be made writeable
        view._sampled_dt = float(dt)
        return view

    def __array_finalize__(self, obj: object) -> None:
        self._sampled_dt = None  # derived arrays (slices, copies, transposes) do not carry the tag

    def __array_wrap__(self, arr, context=None, return_scalar=False):
        arr = np.asarray(arr)  # results of arithmetic are plain arrays
        return arr[()] if return_scalar else arr

    def __reduce__(self):
        return (np.array, (np.asarray(self),))

    def __repr__(self) -> str:
        return repr(np.asarray(self))

    def __str__(self) -> str:
        return str(np.asarray(self))
