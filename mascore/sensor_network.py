"""One sensor network: N agents that sense one common target, checked once (the fusion filters' model).

N agents track one common target ``x[k+1] = F x[k] + w[k]``, ``w ~ N(0, Q)``;
agent i senses ``z_i[k] = H_i x[k] + v_i[k]``, ``v_i ~ N(0, R_i)`` (``q_i``
numbers; ``q_i = 0`` for an agent that does not sense), the noises independent
across agents and time, over an undirected communication graph.
:class:`SensorNetworkModel` holds this, checked once, and simulates it
(:meth:`SensorNetworkModel.simulate`, randomness only from the generator passed in);
:func:`metropolis_weights` gives the consensus weights of its graph. The filters that
run on it are in :mod:`mascore.fusion`, their costs in :mod:`mascore.fusion_cost`.

Shapes: a measurement is the stacked vector ``z = (z_1, ..., z_N)`` of shape
``(..., sum q_i)``; a distributed filter's state is ``x`` ``(..., N, n)`` and ``P``
``(..., N, n, n)``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from . import kalman
from ._fusion_kernels import (
    broadcast_batch,
    metropolis,
    psd_sqrt,
)
from ._validation import (
    Frozen,
    as_matrix,
    check_adjacency,
    check_covariance,
    check_fits_in_memory,
    check_generator,
    check_positive_int,
    check_square,
    finite_result,
    float_array,
    frozen_copy,
    require_finite,
    symmetric_part,
)
from .agents import is_system, system_matrices

__all__ = [
    "SensorNetworkModel",
    "metropolis_weights",
]


# --------------------------------------------------------------------------------------------
# graph weights


def metropolis_weights(adjacency: ArrayLike) -> np.ndarray:
    """Metropolis consensus weights of an undirected graph (Xiao, Boyd and Lall 2005).

    ``W[i, j] = 1 / (1 + max(d_i, d_j))`` for each neighbour j of i,
    ``W[i, i] = 1 - sum_j W[i, j]``, 0 elsewhere; ``d_i`` is the number of
    neighbours of i. W is symmetric and doubly stochastic, so ``W^L -> 11^T / N``
    on a connected graph.

    Parameters
    ----------
    adjacency : (N, N) array_like
        Symmetric adjacency (``adjacency[i, j] > 0``: i and j communicate); weights
        other than zero/non-zero are ignored.

    Returns
    -------
    (N, N) ndarray
        The weights.

    Raises
    ------
    ValueError
        `adjacency` not a symmetric, non-negative matrix with a zero diagonal.

    Examples
    --------
    >>> from mascore import graphs, sensor_network
    >>> sensor_network.metropolis_weights(graphs.path_graph(3))
    array([[0.66666667, 0.33333333, 0.        ],
           [0.33333333, 0.33333333, 0.33333333],
           [0.        , 0.33333333, 0.66666667]])
    """
    A = check_adjacency(float_array(adjacency, "adjacency"), "adjacency", undirected=True,
                        why="Metropolis weights are defined on undirected graphs")
    return metropolis(A > 0)


# --------------------------------------------------------------------------------------------
# the model


class SensorNetworkModel(Frozen):
    """A common target sensed by N agents on an undirected graph, checked once, when it is built.

    ``x[k+1] = F x[k] + w[k]``, ``w ~ N(0, Q)``; agent i measures
    ``z_i[k] = H_i x[k] + v_i[k]``, ``v_i ~ N(0, R_i)``, independent across agents
    and steps. The constructor checks every matrix and keeps read-only copies; the
    filters built on the model check only the per-step arrays.

    Parameters
    ----------
    F : (n, n) array_like, or LTIAgent or StateSpace
        State-transition matrix, finite; or a discrete-time system whose ``A`` it is.
    Q : (n, n) array_like
        Process-noise covariance, symmetric positive semidefinite.
    H : sequence of N (q_i, n) array_like
        Measurement matrices; ``q_i = 0`` (an array of shape ``(0, n)``) for an
        agent that does not sense. At least one agent must sense.
    R : sequence of N (q_i, q_i) array_like
        Measurement-noise covariances, symmetric positive definite (``(0, 0)`` or
        None for an agent that does not sense).
    adjacency : (N, N) array_like
        Undirected communication graph (``adjacency[i, j] > 0``: i and j exchange
        messages), symmetric, no self-loops. It need not be connected, but the
        consensus filters approach the centralized one only on a connected graph.

    Attributes
    ----------
    F, Q : ndarray (read-only)
        The dynamics.
    H, R : tuple of ndarray (read-only)
        Each agent's sensing.
    adjacency : (N, N) ndarray (read-only)
        The graph.
    H_stacked, R_stacked : ndarray (read-only)
        ``H = [H_1; ...; H_N]`` of shape ``(sum q_i, n)`` and ``R = blockdiag(R_i)``:
        the centralized measurement model.
    information_matrices : (N, n, n) ndarray (read-only)
        ``H_i^T R_i^{-1} H_i`` (zero for an agent that does not sense).
    weights : (N, N) ndarray (read-only)
        The Metropolis weights of the graph (:func:`metropolis_weights`).

    Raises
    ------
    ValueError, TypeError
        A bad matrix, named in the message (``H[2]``, ``R[0]``, ``adjacency``).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, sensor_network
    >>> F = [[1.0, 0.1], [0.0, 1.0]]                                      # position, velocity; dt = 0.1 s
    >>> H = [[[1.0, 0.0]], np.zeros((0, 2)), [[1.0, 0.0]]]                # agent 1 does not sense
    >>> R = [[[0.5]], None, [[2.0]]]
    >>> model = sensor_network.SensorNetworkModel(F, 0.01 * np.eye(2), H, R, graphs.path_graph(3))
    >>> model
    SensorNetworkModel(N = 3 agents, n = 2 states, q = (1, 0, 1) measurements)
    >>> model.information_matrices[:, 0, 0]                                # 1 / R_i
    array([2. , 0. , 0.5])
    """

    __slots__ = ("F", "Q", "H", "R", "adjacency", "H_stacked", "R_stacked", "information_matrices", "weights",
                 "_kf", "_owner", "_Rinv", "_neighbourhood", "_sqrt_Q", "_slices")

    def __init__(self, F: ArrayLike, Q: ArrayLike, H: Sequence[ArrayLike], R: Sequence[ArrayLike],
                 adjacency: ArrayLike) -> None:
        if is_system(F):
            F = system_matrices(F, "discrete", name="F", needed_by="SensorNetworkModel, x[k+1] = F x[k] + w[k],")[0]
        F = check_square(F, "F")
        n = F.shape[0]
        Q = check_covariance(Q, "Q", size=n)
        A = check_adjacency(float_array(adjacency, "adjacency"), "adjacency", undirected=True,
                            why="the consensus weights and the information exchange are symmetric")
        N = A.shape[0]
        Hs, Rs = _checked_sensing(H, R, n, N)
        links = A > 0
        self._set(F=frozen_copy(F), Q=frozen_copy(Q), adjacency=frozen_copy(A), weights=frozen_copy(metropolis(links)),
                  _neighbourhood=frozen_copy(links + np.eye(N)),  # N_i together with i
                  _sqrt_Q=frozen_copy(psd_sqrt(Q)))
        H_st, R_st, sizes = _stacked(Hs, Rs)
        self._set(**_sensing_parts(H_st, R_st, sizes, n, N, kalman.LinearGaussianModel(F, Q, H_st, R_st)))

    def _args(self) -> tuple:
        return (self.F, self.Q, self.H, self.R, self.adjacency)

    def on_graph(self, adjacency: ArrayLike) -> SensorNetworkModel:
        """The same dynamics and sensing on another communication graph (a switching topology's step).

        Only `adjacency` is checked: the dynamics and the sensing were checked when this model was
        built and are shared, read-only, with the new one, which equals
        ``SensorNetworkModel(F, Q, H, R, adjacency)`` (in a fraction of its time).

        Parameters
        ----------
        adjacency : (N, N) array_like
            The new undirected graph on the same N agents (symmetric, no self-loops).

        Returns
        -------
        SensorNetworkModel
            The model on that graph (its Metropolis weights and neighbourhoods are the graph's).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2)] * 4, [np.eye(2)] * 4,
        ...                                           graphs.ring_graph(4))
        >>> path = model.on_graph(graphs.path_graph(4))
        >>> path == sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2)] * 4, [np.eye(2)] * 4,
        ...                                           graphs.path_graph(4))
        True
        """
        N = self.n_agents
        A = check_adjacency(float_array(adjacency, "adjacency"), "adjacency", size=N, undirected=True,
                            why="the consensus weights and the information exchange are symmetric")
        links = A > 0
        new = object.__new__(type(self))
        new._set(**{name: getattr(self, name) for name in self.__slots__})
        new._set(adjacency=frozen_copy(A), weights=frozen_copy(metropolis(links)),
                 _neighbourhood=frozen_copy(links + np.eye(N)))
        return new

    def with_sensing(self, H: Sequence[ArrayLike], R: Sequence[ArrayLike]) -> SensorNetworkModel:
        """The same dynamics and graph with other sensing (a step's ``H_i``, ``R_i``, or who senses).

        The dynamics and the graph were checked when this model was built and are shared,
        read-only, with the new model, which equals ``SensorNetworkModel(F, Q, H, R, adjacency)``
        (in a fraction of its time: the graph's weights are not computed again).

        Parameters
        ----------
        H : sequence of N (q_i, n) array_like
            Measurement matrices, finite (``(0, n)`` for an agent that does not sense).
        R : sequence of N (q_i, q_i) array_like
            Measurement-noise covariances, symmetric positive definite (``(0, 0)`` or None for
            an agent that does not sense).

        Returns
        -------
        SensorNetworkModel
            The model with that sensing.

        Raises
        ------
        ValueError, TypeError
            A bad matrix, named in the message (``H[2]``, ``R[0]``).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2)] * 3, [np.eye(2)] * 3,
        ...                                           graphs.ring_graph(3))
        >>> far = model.with_sensing([np.eye(2)] * 3, [np.eye(2), 4.0 * np.eye(2), 9.0 * np.eye(2)])
        >>> far.information_matrices[:, 0, 0]                            # 1 / R_i: noise that grows with range
        array([1.        , 0.25      , 0.11111111])
        """
        return self._with_stacked_sensing(*_stacked(*_checked_sensing(H, R, self.n_states, self.n_agents)))

    def _with_stacked_sensing(self, H_st: np.ndarray, R_st: np.ndarray, sizes: Sequence[int]) -> SensorNetworkModel:
        """:meth:`with_sensing` from checked stacked arrays: ``H`` ``(..., sum q_i, n)``, block-diagonal ``R``
        ``(..., sum q_i, sum q_i)``, the ``q_i``. Leading axes: one sensing per run of a batch (:func:`mascore.fusion.track`;
        such a model's ``H_i``, ``R_i`` and information matrices have them too, and only its filtering is used)."""
        new = object.__new__(type(self))
        new._set(**{name: getattr(self, name) for name in self.__slots__})
        new._set(**_sensing_parts(H_st, R_st, sizes, self.n_states, self.n_agents,
                                  self._kf.with_measurement(H_st, R_st)))
        return new

    @property
    def _sqrt_R(self) -> np.ndarray:
        """The symmetric square root of ``R = blockdiag(R_i)`` (drawing the measurement noise)."""
        return psd_sqrt(self.R_stacked)

    def __repr__(self) -> str:
        return (f"SensorNetworkModel(N = {self.n_agents} agents, n = {self.n_states} states, "
                f"q = {self.measurement_sizes} measurements)")

    @property
    def n_agents(self) -> int:
        """N, the number of agents."""
        return self.adjacency.shape[0]

    @property
    def n_states(self) -> int:
        """n, the length of the state."""
        return self.F.shape[0]

    @property
    def measurement_sizes(self) -> tuple[int, ...]:
        """``(q_1, ..., q_N)``, the length of each agent's measurement."""
        return tuple(h.shape[-2] for h in self.H)

    @property
    def n_measurements(self) -> int:
        """``sum q_i``, the length of the stacked measurement ``z``."""
        return self.H_stacked.shape[-2]

    def agent_measurement(self, z: ArrayLike, i: int) -> np.ndarray:
        """Agent i's part ``z_i`` of a stacked measurement.

        Parameters
        ----------
        z : (..., sum q_i) array_like
            Stacked measurement(s).
        i : int
            Agent index, ``0 <= i < N``.

        Returns
        -------
        (..., q_i) ndarray
            A view of `z`.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2), np.eye(1, 2)],
        ...                                           [np.eye(2), np.eye(1)], graphs.path_graph(2))
        >>> model.agent_measurement([1.0, 2.0, 3.0], 1)
        array([3.])
        """
        z = self._check_z(z)
        i = check_positive_int(i, "i", minimum=0)
        if i >= self.n_agents:
            raise ValueError(f"i must be an agent index below N = {self.n_agents}; got {i}")
        return require_finite(z, "z")[..., self._slices[i]]

    def information_vectors(self, z: ArrayLike) -> np.ndarray:
        """Each agent's information vector ``H_i^T R_i^{-1} z_i`` (zero for an agent that does not sense).

        Parameters
        ----------
        z : (..., sum q_i) array_like
            Stacked measurement(s), finite (checked: shape and entries, one pass over `z`).

        Returns
        -------
        (..., N, n) ndarray
            Row i is agent i's vector.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2), np.eye(1, 2)],
        ...                                           [4.0 * np.eye(2), np.eye(1)], graphs.path_graph(2))
        >>> model.information_vectors([1.0, 2.0, 3.0])
        array([[0.25, 0.5 ],
               [3.  , 0.  ]])
        """
        return self._information_vectors(require_finite(self._check_z(z), "z"))

    def _information_vectors(self, z: np.ndarray) -> np.ndarray:
        """:meth:`information_vectors` of a checked `z` (the filters' steps, which check it once at their entry)."""
        # (..., sum q): R^{-1} z, block by block (a model built by fusion.track for per-run sensing has batch axes)
        y = z @ self._Rinv if self._Rinv.ndim == 2 else (z[..., None, :] @ self._Rinv)[..., 0, :]
        # agent i: sum over its rows r of y_r H_r  ->  owner (N, sum q) @ (y_r H_r) (..., sum q, n)
        return self._owner @ (y[..., :, None] * self.H_stacked)

    def _check_z(self, z: ArrayLike, name: str = "z") -> np.ndarray:
        z = float_array(z, name)
        if z.ndim < 1 or z.shape[-1] != self.n_measurements:
            raise ValueError(f"Incompatible dimensions of {name}; expected (..., {self.n_measurements}) (the stacked "
                             f"measurements z_1..z_N of sizes {self.measurement_sizes}) but found {z.shape}")
        return z

    def check_state(self, x: ArrayLike, P: ArrayLike, names: tuple[str, str] = ("x0", "P0"),
                    per_agent: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """An initial state, checked in full: what a filter's ``run`` does once.

        Parameters
        ----------
        x : (..., N, n) or (n,) array_like
            Mean(s), finite; an ``(n,)`` mean is given to every agent.
        P : (..., N, n, n) or (n, n) array_like
            Covariance(s), symmetric positive definite (the information filters invert it).
        names : (str, str)
            Names of `x` and `P` in error messages.
        per_agent : bool
            True: the state of N agents, ``(..., N, n)``; False: one (centralized)
            state ``(..., n)``.

        Returns
        -------
        x, P : ndarray
            Float arrays of shapes ``(..., N, n)``, ``(..., N, n, n)`` (or ``(..., n)``,
            ``(..., n, n)``), copies.

        Raises
        ------
        ValueError, TypeError
            A bad mean or covariance, named.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2)] * 3, [np.eye(2)] * 3,
        ...                                           graphs.ring_graph(3))
        >>> x, P = model.check_state(np.zeros(2), np.eye(2))
        >>> x.shape, P.shape
        ((3, 2), (3, 2, 2))
        """
        xname, Pname = names
        n, N = self.n_states, self.n_agents
        x = require_finite(float_array(x, xname), xname)
        if x.ndim < 1 or x.shape[-1] != n:
            raise ValueError(f"Incompatible dimensions of {xname}; expected (..., {n}) but found {x.shape}")
        P = check_covariance(float_array(P, Pname), Pname, size=n, definite=True)
        if per_agent:
            if x.ndim == 1:
                x = np.broadcast_to(x, (N, n))
            if P.ndim == 2:
                P = np.broadcast_to(P, (N, n, n))
            if x.shape[-2] != N or P.shape[-3] != N:
                raise ValueError(f"Incompatible dimensions of {xname} {x.shape} and {Pname} {P.shape}; expected "
                                 f"(..., N, n) = (..., {N}, {n}) and (..., {N}, {n}, {n}) (or one (n,) mean and "
                                 f"(n, n) covariance for every agent)")
            batch = broadcast_batch(xname, x.shape[:-2], Pname, P.shape[:-3])
            shape = (*batch, N, n)
        else:
            batch = broadcast_batch(xname, x.shape[:-1], Pname, P.shape[:-2])
            shape = (*batch, n)
        return np.broadcast_to(x, shape).copy(), np.broadcast_to(P, (*shape, n)).copy()

    def simulate(self, x0: ArrayLike, P0: ArrayLike, n_steps: int, rng: np.random.Generator | int,
                 n_runs: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Draw a target trajectory and every agent's measurements: the same data for every filter.

        ``x[0] ~ N(x0, P0)``; for ``k = 1..n_steps``: ``x[k] = F x[k-1] + w``,
        ``z[k] = H x[k] + v`` (stacked over agents).

        Parameters
        ----------
        x0 : (n,) array_like
            Mean of the initial state.
        P0 : (n, n) array_like
            Its covariance, symmetric positive semidefinite.
        n_steps : int
            K >= 1 steps.
        rng : numpy.random.Generator or int
            The only source of randomness (an int seeds ``default_rng``).
        n_runs : int, optional
            Independent runs along a leading axis (default: one run, no axis).

        Returns
        -------
        x_true : (K + 1, [n_runs,] n) ndarray
            States ``x[0..K]``.
        z : (K, [n_runs,] sum q_i) ndarray
            Measurements of steps 1..K.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), 0.01 * np.eye(2), [np.eye(2)] * 3, [np.eye(2)] * 3,
        ...                                           graphs.ring_graph(3))
        >>> x, z = model.simulate(np.zeros(2), np.eye(2), 10, rng=1)
        >>> x.shape, z.shape
        ((11, 2), (10, 6))
        >>> bool(np.array_equal(z, model.simulate(np.zeros(2), np.eye(2), 10, rng=1)[1]))   # seeded: identical
        True
        """
        gen = check_generator(rng)
        n = self.n_states
        x0 = require_finite(float_array(x0, "x0"), "x0")
        if x0.shape != (n,):
            raise ValueError(f"Incompatible dimensions of x0; expected ({n},) but found {x0.shape}")
        P0 = check_covariance(float_array(P0, "P0"), "P0", size=n)
        if P0.ndim != 2:
            raise ValueError(f"P0 must be one ({n}, {n}) covariance; got shape {P0.shape}")
        from ._validation import check_steps

        K = check_steps(n_steps)
        runs = () if n_runs is None else (check_positive_int(n_runs, "n_runs"),)
        q = self.n_measurements
        check_fits_in_memory(8.0 * (K + 1) * math.prod(runs) * (n + q), "n_runs" if runs else "n_steps",
                             "the states and measurements drawn")
        x = np.empty((K + 1, *runs, n))
        z = np.empty((K, *runs, q))
        x[0] = x0 + gen.standard_normal((*runs, n)) @ psd_sqrt(P0).T
        sqrt_R = self._sqrt_R
        for k in range(K):
            x[k + 1] = x[k] @ self.F.T + gen.standard_normal((*runs, n)) @ self._sqrt_Q.T
            z[k] = x[k + 1] @ self.H_stacked.T + gen.standard_normal((*runs, q)) @ sqrt_R.T
        return x, z


# --------------------------------------------------------------------------------------------
# the sensing part of a model (its constructor and SensorNetworkModel.with_sensing)


def _checked_sensing(H: Sequence[ArrayLike], R: Sequence[ArrayLike], n: int, N: int,
                     ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Each agent's ``H_i`` ``(q_i, n)`` and ``R_i`` ``(q_i, q_i)``, checked (``(0, 0)`` for an agent that does not sense)."""
    if isinstance(H, np.ndarray) and H.ndim == 3:
        H = list(H)
    if isinstance(R, np.ndarray) and R.ndim == 3:
        R = list(R)
    for name, seq in (("H", H), ("R", R)):
        if isinstance(seq, (str, bytes, np.ndarray)) or not hasattr(seq, "__len__"):
            raise TypeError(f"{name} must be a sequence of N = {N} matrices (one per agent); got "
                            f"{type(seq).__name__}")
        if len(seq) != N:
            raise ValueError(f"{name} must hold one matrix per agent: N = {N} (the adjacency's size); got "
                             f"{len(seq)}")
    Hs, Rs = [], []
    for i in range(N):
        Hi = as_matrix(H[i], f"H[{i}]", (None, n))
        q = Hi.shape[0]
        if q == 0:
            if R[i] is not None and float_array(R[i], f"R[{i}]").size:
                raise ValueError(f"R[{i}] must be empty (shape (0, 0)) or None: agent {i} has no measurement "
                                 f"(H[{i}] has 0 rows)")
            Ri = np.zeros((0, 0))
        else:
            if R[i] is None:
                raise TypeError(f"R[{i}] must be a ({q}, {q}) covariance for H[{i}] of shape {Hi.shape}; "
                                "got None")
            Ri = check_covariance(float_array(R[i], f"R[{i}]"), f"R[{i}]", size=q, definite=True)
        Hs.append(Hi)
        Rs.append(Ri)
    if sum(h.shape[0] for h in Hs) == 0:
        raise ValueError("no agent senses (every H[i] has 0 rows): at least one measurement is needed")
    return Hs, Rs


def _stacked(Hs: list[np.ndarray], Rs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """``[H_1; ...; H_N]``, ``blockdiag(R_1, ..., R_N)`` and the ``q_i`` of checked per-agent matrices."""
    sizes = [h.shape[0] for h in Hs]
    total = sum(sizes)
    R_st = np.zeros((total, total))
    start = 0
    for q, Ri in zip(sizes, Rs):
        R_st[start:start + q, start:start + q] = Ri
        start += q
    return np.concatenate(Hs, axis=0), R_st, sizes


def _sensing_parts(H_st: np.ndarray, R_st: np.ndarray, sizes: Sequence[int], n: int, N: int,
                   kf: kalman.LinearGaussianModel) -> dict[str, object]:
    """The model's sensing attributes from checked stacked ``H`` and block-diagonal ``R`` of agents of ``q_i``
    measurements (`kf`: the stacked Kalman model). The agents with ``q_i`` measurements are done at once, per ``q_i``.
    """
    starts = [0, *itertools.accumulate(sizes)]
    batch = R_st.shape[:-2]
    Rinv = np.zeros(R_st.shape)
    owner = np.repeat(np.eye(N), sizes, axis=1)  # (N, sum q): agent i's rows
    info = np.zeros((*batch, N, n, n))
    H_of: list[np.ndarray] = [frozen_copy(np.zeros((*batch, 0, n)))] * N  # read-only views of one copy per size
    R_of: list[np.ndarray] = [frozen_copy(np.zeros((*batch, 0, 0)))] * N
    for q in sorted(set(sizes) - {0}):
        agents = [i for i, size in enumerate(sizes) if size == q]
        rows = np.add.outer([starts[i] for i in agents], np.arange(q))  # (g, q): their rows of the stacked measurement
        Ri, Hi = R_st[..., rows[:, :, None], rows[:, None, :]], H_st[..., rows, :]  # (..., g, q, q), (..., g, q, n)
        with np.errstate(over="ignore", invalid="ignore"):  # an R too close to singular: refused by name below
            Ri_inv = symmetric_part(np.linalg.inv(Ri))
            info[..., agents, :, :] = symmetric_part(np.swapaxes(Hi, -1, -2) @ Ri_inv @ Hi)
        Rinv[..., rows[:, :, None], rows[:, None, :]] = Ri_inv
        Hi, Ri = frozen_copy(Hi), frozen_copy(Ri)
        for j, i in enumerate(agents):
            H_of[i], R_of[i] = Hi[..., j, :, :], Ri[..., j, :, :]
    finite_result("model's information matrices", info, Rinv, advice="R is too close to singular")
    return dict(H=tuple(H_of), R=tuple(R_of), H_stacked=frozen_copy(H_st), R_stacked=frozen_copy(R_st),
                information_matrices=frozen_copy(info), _kf=kf, _owner=frozen_copy(owner), _Rinv=frozen_copy(Rinv),
                _slices=tuple(map(slice, starts[:-1], starts[1:])))
