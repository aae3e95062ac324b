"""Second-order consensus (rendezvous) of Song et al. (2023), eqs. (4), (5), (21).

All laws share one form. Agent ``i`` holds a *view* ``Y[i, j]`` of every agent
``j`` (the true state, its measurement ``z_{i,x_j}`` or its estimate
``x̂_{i,j}``) and applies::

    u_i = K sum_{j in N_i} (Y[i, j] - Y[i, i]) = -K sum_j L_ij Y[i, j],
    K = [rho_1 I_n, rho_2 I_n]

* eq. (4): ``Y[i, j] = x_j`` (true states, the noise-free reference);
* eq. (5): ``Y[i, j] = z_{i,x_j}`` (raw measurements, "conventional");
* eq. (21)/(23): ``Y[i, j] = x̂_{i,j}`` (the agent's own team estimate).

Units: positions in m, velocities in m/s, inputs in m/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from . import centralized_team_filter, team_model, team_observability
from . import distributed_kf as dkf
from ._fusion_kernels import psd_factor
from ._progress import progress_bar
from ._sensing_kernels import masked_measurement
from ._systems import full_state_only, output_matrices
from ._team_kernels import check_team_laplacian, control_inputs, undirected_message
from ._validation import (
    Frozen,
    as_matrix,
    check_adjacency_stack,
    check_covariance,
    check_fits_in_memory,
    check_flag,
    check_generator,
    check_positive,
    check_positive_int,
    check_square,
    check_steps,
    frozen_copy,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .agents import LTIAgent, check_sampling_time, system_matrices
from .graphs import laplacian as graph_laplacian
from .graphs import require_connected
from .sensing import sensing_mask, team_noise_covariance

__all__ = [
    "MODES",
    "RendezvousModel",
    "RendezvousResult",
    "simulate_rendezvous",
    "rendezvous_gain",
    "consensus_control",
    "true_state_views",
    "propagate_team",
    "team_spread",
    "expected_spread",
]


def rendezvous_gain(rho1: float, rho2: float, n: int) -> np.ndarray:
    """``K = [rho_1 I_n, rho_2 I_n]`` of eq. (4).

    Parameters
    ----------
    rho1 : float
        Position gain (1/s²), positive.
    rho2 : float
        Velocity gain (1/s), positive.
    n : int
        Spatial dimension.

    Returns
    -------
    (n, 2n) ndarray
        The consensus gain.

    Examples
    --------
    >>> from mascore import rendezvous
    >>> rendezvous.rendezvous_gain(0.5, 1.5, 1)
    array([[0.5, 1.5]])
    """
    rho1 = check_positive(rho1, "rho1", "(a positive gain)")
    rho2 = check_positive(rho2, "rho2", "(a positive gain)")
    n = check_positive_int(n, "n")
    return np.hstack([rho1 * np.eye(n), rho2 * np.eye(n)])


def consensus_control(views: ArrayLike, laplacian: ArrayLike, K: ArrayLike) -> np.ndarray:
    """Inputs ``u_i = -K sum_j L_ij Y[i, j]`` for every agent (eqs. (4), (5), (23)).

    Parameters
    ----------
    views : (..., N, N, m) array_like
        ``views[..., i, j, :]``: agent ``i``'s view of agent ``j``. Only
        entries with ``L_ij != 0`` are used, so unsensed entries may hold
        anything finite (e.g. the zeros of :func:`mascore.sensing.measure`).
    laplacian : (N, N) or (..., N, N) array_like
        Graph Laplacian ``L = D - A`` (broadcast over the leading axes).
    K : (p, m) array_like
        Feedback gain, e.g. :func:`rendezvous_gain`.

    Returns
    -------
    U : (..., N, p) ndarray

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous
    >>> views = rendezvous.true_state_views(np.array([[0.0, 0.0], [1.0, 0.0]]))   # 1-D, [p, v]
    >>> rendezvous.consensus_control(views, graphs.laplacian(graphs.path_graph(2)), [[1.0, 2.0]])
    array([[ 1.],
           [-1.]])
    """
    Y = _finite(_float_array(views, "views"), "views")
    if Y.ndim < 3 or Y.shape[-3] != Y.shape[-2] or Y.shape[-2] == 0 or Y.shape[-1] == 0:
        raise ValueError(f"views must have shape (..., N, N, m) with N, m >= 1; got {Y.shape}")
    N, m = Y.shape[-2:]
    L = check_team_laplacian(laplacian, N, any_batch=True)
    K = as_matrix(_float_array(K, "K"), "K", (None, m))
    try:
        np.broadcast_shapes(L.shape[:-2], Y.shape[:-3])
    except ValueError:
        raise ValueError(
            f"the leading (batch) axes of laplacian {L.shape} and views {Y.shape} do not broadcast"
        ) from None
    return control_inputs(Y, L, K)


def true_state_views(states: ArrayLike) -> np.ndarray:
    """Views ``Y[i, j] = x_j`` for the noise-free law (4).

    Parameters
    ----------
    states : (..., N, m) array_like
        True agent states, finite.

    Returns
    -------
    (..., N, N, m) ndarray
        Every agent sees every agent's true state.

    Examples
    --------
    >>> from mascore import rendezvous
    >>> rendezvous.true_state_views([[0.0], [1.0]])[:, :, 0]
    array([[0., 1.],
           [0., 1.]])
    """
    x = _finite(_float_array(states, "states"), "states")
    if x.ndim < 2:
        raise ValueError(f"states must have shape (..., N, m); got {x.shape}")
    N = x.shape[-2]
    return np.broadcast_to(x[..., None, :, :], (*x.shape[:-1][:-1], N, N, x.shape[-1]))


def propagate_team(
    rng: np.random.Generator | int,
    states: ArrayLike,
    inputs: ArrayLike,
    A: ArrayLike,
    B: ArrayLike,
    Q: ArrayLike,
) -> np.ndarray:
    """One step of eq. (1) for every agent: ``x+ = A x + B u + w``, ``w ~ N(0, Q)``.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of the process noise.
    states : (..., N, m) array_like
        Current states.
    inputs : (..., N, p) array_like
        Inputs.
    A : (m, m) array_like
        Agent state matrix.
    B : (m, p) array_like
        Agent input matrix.
    Q : (m, m) array_like
        Process-noise covariance, symmetric PSD, in (state unit)^2: m^2 and m^2/s^2 on the position and
        velocity entries.

    Returns
    -------
    (..., N, m) ndarray
        The next states.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous
    >>> agent = agents.double_integrator(1, 0.1)
    >>> x = rendezvous.propagate_team(0, np.zeros((3, 2)), np.ones((3, 1)), agent.A, agent.B, np.zeros((2, 2)))
    >>> x[0]                                                    # no noise: p = dt^2 / 2, v = dt
    array([0.005, 0.1  ])
    """
    rng = check_generator(rng)
    x = _finite(_float_array(states, "states"), "states")
    u = _finite(_float_array(inputs, "inputs"), "inputs")
    if x.ndim < 2 or x.shape[-1] == 0:
        raise ValueError(f"states must have shape (..., N, m) with m >= 1; got {x.shape}")
    if u.ndim < 2 or u.shape[-2] != x.shape[-2]:
        raise ValueError(f"Incompatible dimensions of inputs; expected (..., {x.shape[-2]}, p) but found {u.shape}")
    m = x.shape[-1]
    A = check_square(_float_array(A, "A"), "A", m)
    B = as_matrix(_float_array(B, "B"), "B", (m, u.shape[-1]))
    Q = check_covariance(_float_array(Q, "Q"), "Q", size=m)
    if Q.ndim != 2:
        raise ValueError(f"Q must be a single ({m}, {m}) matrix; got shape {Q.shape}")
    try:
        np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
    except ValueError:
        raise ValueError(f"the leading axes of states {x.shape} and inputs {u.shape} do not broadcast") from None
    w = rng.standard_normal(x.shape) @ psd_factor(Q, cholesky_first=True).T
    return x @ A.T + u @ B.T + w


def team_spread(values: ArrayLike) -> np.ndarray:
    """Standard deviation of the agents about their mean.

    ``sqrt(mean_i ||y_i - mean_j y_j||^2)`` over the agent axis (``-2``) of
    ``(..., N, d)`` data, e.g. positions (m) or velocities (m/s). Song et al.
    (2023) Fig. 3 plots its root mean square over Monte Carlo runs.

    Parameters
    ----------
    values : (..., N, d) array_like
        One row per agent.

    Returns
    -------
    (...) ndarray
        The spread, in the unit of `values`.

    Examples
    --------
    >>> from mascore import rendezvous
    >>> float(rendezvous.team_spread([[0.0, 0.0], [2.0, 0.0]]))
    1.0
    """
    y = _finite(_float_array(values, "values"), "values")
    if y.ndim < 2 or y.shape[-2] == 0:
        raise ValueError(f"values must have shape (..., N, d) with N >= 1 agents; got {y.shape}")
    if y.size and np.abs(y).max() > 1e150:
        raise ValueError(f"values has entries of magnitude {np.abs(y).max():.3g}: squared they overflow floating "
                         f"point; rescale their units")
    dev = y - y.mean(axis=-2, keepdims=True)
    return np.sqrt(np.mean(np.sum(dev**2, axis=-1), axis=-1))


@dataclass(frozen=True, eq=False)
class RendezvousModel(Frozen):
    """The rendezvous loop's model: identical agents, consensus gain and noise (Song et al. eqs. (1)-(4)).

    Checked once when built, then passed to :func:`simulate_rendezvous` and
    :func:`expected_spread` (instead of repeating the same nine arguments). The
    model keeps read-only copies of its matrices: changing the arrays it was built
    from, or writing into ``model.Q``, cannot bypass the check.

    Parameters
    ----------
    A : (m, m) array_like
        Agent state matrix, ``x_{k+1} = A x_k + B u_k + w_k`` (eq. (1)).
    B : (m, p) array_like
        Agent input matrix.
    K : (p, m) array_like
        Consensus gain of eq. (4), e.g. :func:`rendezvous_gain`.
    Q : (m, m) array_like
        Process-noise covariance of each agent, symmetric PSD, in (state unit)^2 (m^2, m^2/s^2).
    R : (m, m) or (m N, m N) array_like
        Measurement-noise covariance: per sensed agent (the team covariance is then
        ``I_N ⊗ R``) or the full covariance of one observer's noise vector; symmetric PSD.
    dt : float
        Sampling time (s) that ``A`` and ``B`` were discretized with; it gives the time
        axis. Build the model with :meth:`from_agent` to take it from the agent
        (e.g. :func:`mascore.agents.double_integrator`) instead of repeating it. A
        double-integrator ``A = [[I, h I], [0, I]]`` with ``h != dt`` is refused (the
        time axis would be wrong).
    C : (p, m) or (N, p, m) array_like, optional
        Output matrix of the measurements, ``z_ij = C_j x_j + nu_ij`` (one for every agent or
        one per agent; e.g. positions only, ``C = [I 0]``), with `R` then of ``(p, p)`` or
        ``(p N, p N)``. ``None`` (default) or the identity: full states (eq. (2)). Only the
        control laws that do not steer with raw measurements take it (:func:`simulate_rendezvous`
        modes ``"true"`` and ``"estimation"``).

    Raises
    ------
    ValueError
        Shapes that do not fit together, a covariance that is not symmetric PSD, a
        non-positive `dt`, or a `dt` that contradicts ``A``.
    TypeError
        If `dt` is not a number.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, rendezvous
    >>> agent = agents.double_integrator(2, 0.1)
    >>> model = rendezvous.RendezvousModel(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.0, 2),
    ...                                    Q=1e-4 * np.eye(4), R=0.04 * np.eye(4), dt=0.1)
    >>> model.m, model.p
    (4, 2)
    """

    A: np.ndarray
    B: np.ndarray
    K: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    dt: float
    C: np.ndarray | None = None

    def __post_init__(self) -> None:
        A = check_square(_float_array(self.A, "A"), "A")
        m = A.shape[0]
        B = as_matrix(_float_array(self.B, "B"), "B", (m, None))
        K = as_matrix(_float_array(self.K, "K"), "K", (B.shape[1], m))
        Q = check_covariance(_float_array(self.Q, "Q"), "Q", size=m)
        if Q.ndim != 2:
            raise ValueError(f"Q must be a single ({m}, {m}) matrix; got shape {Q.shape}")
        C = None if self.C is None else _output_matrix(self.C, m)
        R = check_covariance(_float_array(self.R, "R"), "R")
        if C is None and R.ndim == 2 and 0 < R.shape[0] < m:  # partial sensing without C: say how
            raise ValueError(full_state_only(m, R.shape))
        if C is None and (R.ndim != 2 or R.shape[0] % m):
            raise ValueError(f"R must be ({m}, {m}) per sensed agent or (m N, m N) for the team; got {R.shape}")
        if C is not None and (R.ndim != 2 or R.shape[0] % C.shape[-2]):
            p = C.shape[-2]
            raise ValueError(f"R must be ({p}, {p}) per sensed agent or (p N, p N) for the team (p = {p}: the rows "
                             f"of the output matrix C); got {R.shape}")
        dt = self.dt
        if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
            raise TypeError(f"dt must be a positive sampling time in seconds; got {type(dt).__name__} {dt!r}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive sampling time in seconds; got {dt!r}")
        _check_time_base(A, B, float(dt))
        check_sampling_time(self.A, float(dt))  # an A from LTIAgent.from_continuous knows its dt
        self._set(A=frozen_copy(A), B=frozen_copy(B), K=frozen_copy(K), Q=frozen_copy(Q), R=frozen_copy(R),
                  dt=float(dt), C=None if C is None else frozen_copy(C))

    @classmethod
    def from_agent(
        cls, agent: LTIAgent, K: ArrayLike, Q: ArrayLike, R: ArrayLike, dt: float | None = None, *,
        C: ArrayLike | None = None,
    ) -> RendezvousModel:
        """The model of a team of copies of `agent`, on the agent's own time base.

        Parameters
        ----------
        agent : mascore.agents.LTIAgent or python-control StateSpace
            The discrete-time agent, carrying its sampling time ``agent.dt`` (as
            :func:`mascore.agents.double_integrator`,
            :meth:`mascore.agents.LTIAgent.from_continuous` and ``control.c2d`` build it).
        K, Q, R : array_like
            As in the class (gain; process- and measurement-noise *covariances*).
        dt : float, optional
            Only for an agent without ``dt``; a `dt` different from ``agent.dt`` is refused.
        C : (p, m) or (N, p, m) array_like, optional
            Output matrix of the measurements, as in the class (default: full states).

        Returns
        -------
        RendezvousModel

        Raises
        ------
        ValueError
            A `dt` that contradicts ``agent.dt`` (or no time base at all).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, rendezvous
        >>> agent = agents.double_integrator(2, 0.05)
        >>> model = rendezvous.RendezvousModel.from_agent(agent, rendezvous.rendezvous_gain(0.5, 1.0, 2),
        ...                                               Q=1e-4 * np.eye(4), R=0.04 * np.eye(4))
        >>> model.dt
        0.05
        >>> try:
        ...     rendezvous.RendezvousModel.from_agent(agent, model.K, model.Q, model.R, dt=0.1)
        ... except ValueError as exc:
        ...     print(str(exc)[:46])
        dt = 0.1 s contradicts the agent's sampling ti
        """
        if not isinstance(agent, LTIAgent):
            if not all(hasattr(agent, a) for a in ("A", "B", "dt")):
                raise TypeError(f"agent must be a mascore.agents.LTIAgent or a discrete-time python-control "
                                f"StateSpace; got {type(agent).__name__}")
            A, B, sampled = system_matrices(agent, "discrete", name="agent", needed_by="RendezvousModel.from_agent")
            if sampled is True:  # a discrete StateSpace without a sampling time: dt must say it
                if dt is None:
                    raise ValueError("agent is a discrete-time system without a sampling time (dt = True): pass "
                                     "dt, the sampling time (s) its A and B were discretized with")
                return cls(A, B, K, Q, R, dt, C)
            agent = LTIAgent(A, B, dt=float(sampled))
        if agent.dt is None:
            if dt is None:
                raise ValueError("the agent carries no sampling time (agent.dt is None): pass dt, the sampling "
                                 "time (s) its A and B were discretized with")
        elif dt is not None and not np.isclose(check_positive(dt, "dt", "seconds"), agent.dt, rtol=1e-9, atol=0):
            raise ValueError(f"dt = {dt!r} s contradicts the agent's sampling time agent.dt = {agent.dt!r} s that its "
                             "A and B were discretized with: leave dt out, or rebuild the agent with this dt")
        return cls(agent.A, agent.B, K, Q, R, agent.dt if agent.dt is not None else dt, C)

    @property
    def m(self) -> int:
        """State dimension of one agent."""
        return self.A.shape[0]

    @property
    def p(self) -> int:
        """Input dimension of one agent."""
        return self.B.shape[1]


def _check_time_base(A: np.ndarray, B: np.ndarray, dt: float) -> None:
    """Refuse a double integrator ``A = [[I, h I], [0, I]]`` sampled with ``h`` other than `dt`."""
    m = A.shape[0]
    if m % 2:
        return
    n = m // 2
    eye = np.eye(n)
    h = A[0, n]
    if h <= 0 or not np.array_equal(A[:n, :n], eye) or not np.array_equal(A[n:, n:], eye) or np.any(A[n:, :n]):
        return
    if not np.allclose(A[:n, n:], h * eye, rtol=1e-12, atol=0):
        return
    if not np.isclose(h, dt, rtol=1e-9, atol=0):
        raise ValueError(
            f"dt = {dt:g} s contradicts A: A is a double integrator sampled with h = {h:g} s (A[:n, n:] = h I), so "
            f"the time axis would be wrong by a factor {dt / h:g}; pass dt = {h:g}, or build A with dt "
            "(RendezvousModel.from_agent(agents.double_integrator(n, dt), ...) takes dt from the agent)"
        )


def _output_matrix(C: ArrayLike, m: int) -> np.ndarray | None:
    """An output matrix ``(p, m)`` or ``(N, p, m)``, finite; ``None`` for the identity (full states)."""
    arr = _float_array(C, "C")
    if arr.ndim not in (2, 3) or arr.shape[-1] != m or arr.shape[-2] == 0 or (arr.ndim == 3 and arr.shape[0] == 0):
        raise ValueError(f"Incompatible dimensions of C; expected (p, {m}) for every agent or (N, p, {m}) one per "
                         f"agent (p >= 1 outputs of the m = {m} states), but found {arr.shape}")
    arr = _finite(arr, "C")
    if arr.shape[-2] == m and np.array_equal(arr, np.broadcast_to(np.eye(m), arr.shape)):
        return None
    return arr


def _check_model(model: object) -> RendezvousModel:
    if not isinstance(model, RendezvousModel):
        raise TypeError(f"model must be a RendezvousModel(A, B, K, Q, R, dt); got {type(model).__name__}")
    return model


def _states(x0: ArrayLike, m: int) -> tuple[np.ndarray, bool]:
    """x0 as (R, N, m) runs, and whether it was a single (N, m) run."""
    x = np.array(_float_array(x0, "x0"), dtype=float)
    given = x.shape
    single = x.ndim == 2
    if single:
        x = x[None]
    if x.ndim != 3 or 0 in x.shape:
        raise ValueError(f"x0 must have shape (N, m) for one run or (R, N, m) for R runs; got {given}")
    if x.shape[-1] != m:
        raise ValueError(f"x0 must hold states of the model's size m = {m} on its last axis; got shape {given}")
    _finite(x, "x0")
    return x, single


def expected_spread(
    model: RendezvousModel,
    x0: ArrayLike,
    adjacency: ArrayLike,
    n_steps: int,
    mode: str,
) -> np.ndarray:
    """Exact expected squared spread of laws (4) and (5) on a fixed topology, no sampling.

    Both laws are linear with white noise, ``X+ = F_1 X + (noise)`` with
    ``F_1 = I_N ⊗ A - L ⊗ BK`` (eq. (11)) and, per agent, noise covariance
    ``Q`` (law (4), ``mode="true"``) or ``Q + BK (L_i ⊗ I) R (L_i ⊗ I)^T BK^T``
    (law (5), ``mode="measurement"``: agent ``i``'s own measurement noise
    enters its input). The mean and covariance of ``X`` are propagated from
    the known ``x0``; the result is the cross-check of the Monte Carlo spread
    of :func:`simulate_rendezvous` + :func:`team_spread` (same horizon, same
    graphs).

    Parameters
    ----------
    model : RendezvousModel
        Agents, gain and noise.
    x0 : (N, m) or (R, N, m) array_like
        Initial states of one run or of R runs (known exactly).
    adjacency : (N, N) or (R, N, N) array_like
        Fixed topology, shared or one per run.
    n_steps : int
        Number of steps T.
    mode : {"true", "measurement"}
        Law (4) or law (5).

    Returns
    -------
    (T+1, m) or (T+1, R, m) ndarray
        ``E[mean_i (x_ic - mean_j x_jc)^2]`` for every state component ``c``;
        the squared position spread of :func:`team_spread` is the sum over the
        position components (m^2), the velocity one over the velocity
        components (m^2/s^2).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous
    >>> agent = agents.double_integrator(2, 0.1)
    >>> model = rendezvous.RendezvousModel(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 2),
    ...                                    Q=1e-4 * np.eye(4), R=0.01 * np.eye(4), dt=0.1)
    >>> x0 = np.random.default_rng(1).normal(scale=5.0, size=(4, 4))
    >>> exact = rendezvous.expected_spread(model, x0, graphs.ring_graph(4), 50, "measurement")
    >>> exact.shape                                             # (T+1, m)
    (51, 4)
    """
    if not isinstance(mode, str) or mode not in ("true", "measurement"):
        raise ValueError(f"mode must be 'true' or 'measurement' (linear laws with white noise); got {mode!r}")
    model = _check_model(model)
    if mode == "measurement" and model.C is not None:
        raise ValueError("mode 'measurement' steers with the raw measurements (eq. (5)), which must be full states; "
                         "the model has an output matrix C (use mode 'true', or simulate_rendezvous in mode "
                         "'estimation')")
    x, single = _states(x0, model.m)
    n_runs, N, m = x.shape
    A, BK, Q, R = model.A, model.B @ model.K, model.Q, model.R
    n_steps = check_steps(n_steps)
    check_fits_in_memory(8.0 * (n_steps + 1) * n_runs * m, "n_steps", "the expected spreads")
    Adj = check_adjacency_stack(adjacency)
    sensing_mask(Adj)  # isolated-agent check
    if Adj.shape[-1] != N or Adj.ndim not in (2, 3) or (Adj.ndim == 3 and Adj.shape[0] != n_runs):
        raise ValueError(f"adjacency must be ({N}, {N}) or ({n_runs}, {N}, {N}); got {Adj.shape}")
    Lb = graph_laplacian(Adj).reshape(-1, N, N)  # (G, N, N), G = 1 or R
    Nm = N * m
    F1 = np.stack([team_model.closed_loop_matrices(A, BK, Lg)[0] for Lg in Lb])  # eq. (11), one per graph
    noise = np.broadcast_to(Q, (Lb.shape[0], N, m, m)).copy()
    if mode == "measurement":
        Rr = team_noise_covariance(R, N, m).reshape(N, m, N, m)
        check_covariance(Rr.reshape(Nm, Nm), "R", definite=True)
        C = np.einsum("gil,gik,lakc->giac", Lb, Lb, Rr)  # cov of (L_i ⊗ I) nu_i
        noise += BK @ C @ BK.T
    D = np.zeros((Lb.shape[0], N, m, N, m))
    D[:, np.arange(N), :, np.arange(N), :] = np.moveaxis(noise, 1, 0)
    D = D.reshape(-1, Nm, Nm)
    mean = x.reshape(n_runs, Nm, 1)
    P = np.zeros_like(D)
    out = np.empty((n_steps + 1, n_runs, m))
    eye_c = np.eye(N) - 1.0 / N  # centring matrix
    for k in range(n_steps + 1):
        dev = mean.reshape(n_runs, N, m) - mean.reshape(n_runs, N, m).mean(axis=1, keepdims=True)
        Pc = np.diagonal(P.reshape(-1, N, m, N, m), axis1=2, axis2=4)  # (G, N, N, m): cov(x_ic, x_jc)
        out[k] = np.mean(dev**2, axis=1) + np.einsum("ij,gjic->gc", eye_c, Pc) / N
        if k < n_steps:
            mean = F1 @ mean
            P = F1 @ P @ np.swapaxes(F1, -1, -2) + D
    if not np.all(np.isfinite(out)):
        raise ValueError(
            "the expected spread overflowed (NaN or inf) over n_steps: the closed loop is unstable for these "
            "gains and dt, or the horizon is too long; use fewer steps or a stable gain"
        )
    return out[:, 0] if single else out


#: Control laws / estimator loops understood by :func:`simulate_rendezvous`.
MODES = ("true", "measurement", "measurement-filter", "estimation")


@dataclass(frozen=True)
class RendezvousResult:
    """Output of :func:`simulate_rendezvous` (``T`` steps, ``R`` runs, ``N`` agents).

    A run's output: its arrays are the caller's, writeable and shared with no model or filter.

    With one run (``x0`` of shape ``(N, m)``) the run axis ``R`` is absent.

    Parameters
    ----------
    mode : str
        The control law and estimator loop (one of :data:`MODES`).
    dt : float
        Sampling time (s); ``time = dt * arange(T + 1)``.
    states : (T+1, R, N, m) ndarray
        True agent states ``[p; v]``.
    pos_error : (T+1, R, N) or None
        ``sqrt(sum_j ||p_j - p̂_{i,j}||^2)`` (m): agent ``i``'s position error
        over the whole team (Song et al. Fig. 2(c)).
    pos_std : (T+1, B, N) or None
        ``sqrt(trace)`` of the position block of ``Σ_i`` (m) (Fig. 2(d)).
    nees : (T+1, R, N) or None
        ``e_i^T Σ_i^{-1} e_i`` (eq. (45)); chi-square with ``m N`` dof.
    central_pos_std : (T+1, B) or None
        The same statistic for the centralized Kalman filter over all
        measurements (applied inputs known): a lower bound.
    central_pos_error : (T+1, R) or None
        Position error of the centralized filter (m).
    sigma_i : (T+1, N, M_r, M_r) or None
        Reduced ``Σ̄_i[k]`` (only when the covariance is shared, ``B = 1``).
    gains : (T+1, N, M_r, M_r) or None
        Reduced ``G_i H_i[k]`` (only when ``B = 1``; entry 0 is zero).
    f2_cross : (T+1, N, M_r, M_r) or None
        ``F_2 E[e e_i^T]`` (estimation mode, ``B = 1``), for Theorem 1.
    model : TeamFilterModel or None
        The team filter model (filter modes).
    estimates : (T+1, R, N, N, m) ndarray or None
        With ``return_estimates=True`` (filter modes): ``estimates[k, r, i, j]`` is
        agent ``i``'s estimate ``x̂_{i,j}`` of agent ``j``'s state after the update of
        step ``k`` (m, m/s), so ``states[k, r, j] - estimates[k, r, i, j]`` is its error.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous
    >>> agent = agents.double_integrator(2, 0.1)
    >>> model = rendezvous.RendezvousModel(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 2),
    ...                                    Q=1e-4 * np.eye(4), R=0.01 * np.eye(4), dt=0.1)
    >>> run = rendezvous.simulate_rendezvous(0, model, np.zeros((4, 4)), graphs.ring_graph(4), 10, "true")
    >>> run.states.shape, run.pos_error is None
    ((11, 4, 4), True)
    """

    mode: str
    dt: float
    states: np.ndarray
    pos_error: np.ndarray | None = None
    pos_std: np.ndarray | None = None
    nees: np.ndarray | None = None
    central_pos_std: np.ndarray | None = None
    central_pos_error: np.ndarray | None = None
    sigma_i: np.ndarray | None = None
    gains: np.ndarray | None = None
    f2_cross: np.ndarray | None = None
    model: team_model.TeamFilterModel | None = None
    estimates: np.ndarray | None = None

    @property
    def time(self) -> np.ndarray:
        """Time stamps (s), ``(T+1,)``."""
        return self.dt * np.arange(self.states.shape[0])


def simulate_rendezvous(
    rng: np.random.Generator | int,
    model: RendezvousModel,
    x0: ArrayLike,
    adjacency: ArrayLike,
    n_steps: int,
    mode: str,
    *,
    x_hat0: ArrayLike | None = None,
    P0: ArrayLike | None = None,
    exact_control_noise: bool = False,
    central: bool = False,
    progress: bool = False,
    switching: bool = False,
    return_estimates: bool = False,
) -> RendezvousResult:
    """Closed-loop rendezvous on a fixed or switching topology, batched over Monte Carlo runs.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Source of process and measurement noise (two independent child
        streams, so every mode sees the same noise for the same seed).
    model : RendezvousModel
        Agents ``A, B``, consensus gain ``K`` (eq. (4)), noise covariances ``Q, R``, sampling time.
    x0 : (N, m) or (R, N, m) array_like
        Initial true states of one run, or of R Monte Carlo runs. With one run the
        results carry no run axis (e.g. ``states`` is ``(T+1, N, m)``).
    adjacency : (N, N), (R, N, N) or, with `switching`, (T+1, N, N) array_like
        Sensing topology: fixed (one for all runs, or one per run), or the
        topology of every step ``k = 0..T`` shared by all runs. The control
        of step k uses graph k, the measurements of step k+1 use graph k+1.
        With one shared topology (fixed or switching) the filters'
        covariance recursion is computed once for all runs.
    n_steps : int
        Number of steps T.
    mode : {"true", "measurement", "measurement-filter", "estimation"}
        Control law: eq. (4) on true states, eq. (5) on measurements (no
        filter), eq. (5) with every agent also running the filter of
        eqs. (8)-(20), or eq. (21) on the agents' own estimates with the
        filter of eqs. (29)-(34).
    x_hat0 : (N m,), (R, N m), (N, m) or (R, N, m) array_like
        Common initial team estimate of all agents (filter modes), one per run (the
        per-agent rows ``(N, m)`` are stacked into the team vector).
    P0 : (m, m) or (m N, m N) array_like
        Covariance of the initial estimate error (filter modes): per agent, or the
        full team covariance.
    exact_control_noise : bool
        "measurement-filter" only: add the correlation between an agent's own
        measurement noise in its control and its estimate that eq. (15)
        neglects.
    central : bool
        Also run the centralized Kalman filter reference (filter modes).
    progress : bool
        Show a tqdm progress bar.
    switching : bool
        Read `adjacency` as one graph per step (Theorem 1 assumes a fixed
        one; with "estimation" every graph must make system (43) observable).
    return_estimates : bool
        Filter modes: also keep every agent's team estimate at every step in
        ``result.estimates``, ``(T+1, R, N, N, m)`` floats (``8 (T+1) R N^2 m`` bytes).

    Returns
    -------
    RendezvousResult
        True states and, in the filter modes, the estimation errors, covariances and NEES.

    Raises
    ------
    ValueError
        Unknown mode, bad shapes, an isolated agent, (the filter modes) a directed
        graph: the team filter needs an undirected one, or (mode "estimation") a
        disconnected graph (named as such) or a topology for which system (43) is
        not observable.

    Notes
    -----
    The loop of mode "estimation", written out with the public objects (what this
    function runs; the "Apply it to your own system" chapter runs it and checks
    it against this function)::

        proc_rng, meas_rng = np.random.default_rng(seed).spawn(2)
        x, L = x0[None], graphs.laplacian(adjacency)                         # one run: (1, N, m)
        team = distributed_kf.TeamFilter(distributed_kf.team_filter_model(A, B, K, Q, R, N), L,
                                         x_hat0[None], P0, mode="eb")       # every agent's x̂_i(0)
        Z, S = sensing.measure(meas_rng, x, adjacency, R)                    # step 0 (law (5) uses it)
        for k in range(n_steps):
            U = consensus_control(team.view("X_hat"), L, K)  # eq. (21): u_i from agent i's own estimates
            x = propagate_team(proc_rng, x, U, A, B, Q) # eq. (1)
            team.predict()                              # eqs. (29), (30), (32), (34)
            Z, S = sensing.measure(meas_rng, x, adjacency, R)   # eq. (2): z_{i,x_j} = x_j + nu_ij
            team.update(Z, S)                           # eqs. (31), (33)

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous
    >>> agent = agents.double_integrator(2, 0.1)
    >>> model = rendezvous.RendezvousModel(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 2),
    ...                                    Q=1e-4 * np.eye(4), R=0.01 * np.eye(4), dt=0.1)
    >>> x0 = np.random.default_rng(1).normal(scale=5.0, size=(4, 4))      # one run, 4 agents
    >>> run = rendezvous.simulate_rendezvous(2, model, x0, graphs.ring_graph(4), 300, "estimation",
    ...                                      x_hat0=x0.ravel(), P0=np.eye(4), central=True)
    >>> spread = rendezvous.team_spread(run.states[..., :2])
    >>> bool(spread[-1] < 0.05 * spread[0]), bool(abs(run.nees[1:].mean() / 16 - 1) < 0.5)   # meets; NEES ~ 4N
    (True, True)
    """
    if not isinstance(mode, str) or mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}; got {mode!r}")
    rng = check_generator(rng)
    model = _check_model(model)
    x, single = _states(x0, model.m)
    n_runs, N, m = x.shape
    A, B, K, Q, R, dt = model.A, model.B, model.K, model.Q, model.R, model.dt
    Cs = None if model.C is None else output_matrices(model.C, m, N)
    if Cs is not None and mode not in ("true", "estimation"):
        raise ValueError(f"mode {mode!r} steers with the raw measurements (eq. (5)), which must be full states; with "
                         "an output matrix C use mode 'estimation' (eq. (21): the control uses every agent's "
                         "estimates, Song et al.'s estimation-based filter) or 'true'")
    R_team = team_noise_covariance(R, N, m if Cs is None else Cs.shape[1])
    n_steps = check_steps(n_steps)
    check_fits_in_memory(8.0 * (n_steps + 1) * n_runs * N * m * (1 + (N if return_estimates else 0)), "n_steps",
                         "the state histories")
    for flag, value in (("exact_control_noise", exact_control_noise), ("central", central),
                        ("progress", progress), ("switching", switching), ("return_estimates", return_estimates)):
        check_flag(value, flag)
    Adj = check_adjacency_stack(adjacency)
    if mode in ("measurement-filter", "estimation") and not np.array_equal(Adj != 0, np.swapaxes(Adj, -1, -2) != 0):
        raise ValueError(undirected_message("adjacency", f"a directed graph, for the team filter of mode {mode!r}"))
    S = sensing_mask(Adj)  # raises on isolated agents
    if switching:
        if S.shape != (n_steps + 1, N, N):
            raise ValueError(f"with switching=True, adjacency must be ({n_steps + 1}, {N}, {N}); got {Adj.shape}")
    elif S.shape[-1] != N or S.ndim not in (2, 3) or (S.ndim == 3 and S.shape[0] != n_runs):
        raise ValueError(f"adjacency must be ({N}, {N}) or ({n_runs}, {N}, {N}); got {Adj.shape}")
    Laps = graph_laplacian(Adj)

    def topology(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Adjacency, sensing mask and Laplacian in force at step k."""
        return (Adj[k], S[k], Laps[k]) if switching else (Adj, S, Laps)

    filt = mode in ("measurement-filter", "estimation")
    filter_model = team_model.team_filter_model(A, B, K, Q, R, N, C=Cs) if filt else None
    if filt:  # the shapes first, then the theory's conditions on the graph
        if x_hat0 is None or P0 is None:
            raise ValueError(f"mode {mode!r} needs x_hat0 and P0 (initial estimate and its covariance)")
        xh0 = _float_array(x_hat0, "x_hat0")
        if xh0.shape in ((N, m), (n_runs, N, m)):  # one row per agent: stack it into the team vector
            xh0 = xh0.reshape(-1, N * m)
        if single and xh0.shape == (N * m,):
            xh0 = xh0[None]
        if xh0.shape != (n_runs, N * m):
            raise ValueError(f"Incompatible dimensions of x_hat0; expected the team estimate ({n_runs}, N m) = "
                             f"({n_runs}, {N * m}) (or one row per agent, ({N}, {m})) but found {xh0.shape}")
        if not np.all(np.isfinite(xh0)):
            raise ValueError("x_hat0 contains NaN or infinite entries")
    if mode == "estimation":
        for adj in np.unique(Adj.reshape(-1, N, N), axis=0):  # each distinct graph once
            require_connected(adj, "mode 'estimation' (every agent estimates the whole team, system (43) "
                              "observable)", "adjacency" if Adj.ndim == 2 else "a graph of adjacency")
            team_observability.require_observable(filter_model.A, filter_model.BK, adj, C=filter_model.C)
    proc_rng, meas_rng = rng.spawn(2)
    states = np.empty((n_steps + 1, n_runs, N, m))
    states[0] = x
    out: dict[str, np.ndarray | None] = {}
    team = central_filter = None
    if filt:
        # one covariance for a shared topology (fixed or switching), else one per run's fixed graph
        team = dkf.TeamFilter(filter_model, topology(0)[2], xh0, P0, mode="eb" if mode == "estimation" else "mb",
                              exact_control_noise=exact_control_noise and mode == "measurement-filter")
        nb = team.view("Sigma").shape[0]
        n = filter_model.kron
        pos = _position_index(filter_model)
        out["pos_error"] = np.empty((n_steps + 1, n_runs, N))
        out["pos_std"] = np.empty((n_steps + 1, nb, N))
        out["nees"] = np.empty((n_steps + 1, n_runs, N))
        if return_estimates:
            out["estimates"] = np.empty((n_steps + 1, n_runs, N, N, m))
        if nb == 1:
            out["sigma_i"] = np.empty((n_steps + 1, N, filter_model.M_r, filter_model.M_r))
            out["gains"] = np.zeros((n_steps + 1, N, filter_model.M_r, filter_model.M_r))
            if mode == "estimation":
                out["f2_cross"] = np.empty((n_steps + 1, N, filter_model.M_r, filter_model.M_r))
        if central:
            central_filter = centralized_team_filter.CentralizedTeamFilter(filter_model, B, xh0, P0, batch=nb)
            out["central_pos_std"] = np.empty((n_steps + 1, nb))
            out["central_pos_error"] = np.empty((n_steps + 1, n_runs))

        def record(k: int) -> None:
            Sig_i = team.agent_covariances()
            e = x[:, None] - team.view("X_hat")
            err = e[..., pos_slice]
            out["pos_error"][k] = np.sqrt(np.sum(err**2, axis=(-1, -2)))
            diag = np.diagonal(Sig_i, axis1=-2, axis2=-1)[..., pos]
            out["pos_std"][k] = np.sqrt(n * diag.sum(axis=-1))
            out["nees"][k] = team.nees(x)
            if return_estimates:
                out["estimates"][k] = team.view("X_hat")
            if nb == 1:
                out["sigma_i"][k] = Sig_i[0]
                out["gains"][k] = team.view("KH")[0]
                if mode == "estimation":
                    out["f2_cross"][k] = team.f2_cross(topology(k)[2])[0]
            if central:
                Pc, xc = central_filter.view("P"), central_filter.view("x_hat")
                out["central_pos_std"][k] = np.sqrt(n * np.diagonal(Pc, axis1=-2, axis2=-1)[..., pos].sum(-1))
                out["central_pos_error"][k] = np.sqrt(np.sum((x - xc)[..., pos_slice] ** 2, axis=(-1, -2)))

        pos_slice = slice(0, m // 2)
        record(0)
    def observe(x: np.ndarray) -> np.ndarray:
        """What the agents measure of the states: all of them, or the outputs ``C_j x_j``."""
        return x if Cs is None else np.einsum("...jm,jpm->...jp", x, Cs)

    Z, _ = masked_measurement(meas_rng, observe(x), topology(0)[1], R_team)
    for k in progress_bar(range(n_steps), enabled=progress, desc=f"rendezvous ({mode})", leave=False):
        Lap = topology(k)[2]
        if mode == "true":
            U = consensus_control(true_state_views(x), Lap, K)
        elif mode in ("measurement", "measurement-filter"):
            U = consensus_control(Z, Lap, K)
        else:
            U = consensus_control(team.view("X_hat"), Lap, K)
        x_new = propagate_team(proc_rng, x, U, A, B, Q)
        if central_filter is not None:
            central_filter.predict(U)
        if filt:
            team.predict(Lap if switching else None)
        x = x_new
        _, S_next, _ = topology(k + 1)
        Z, _ = masked_measurement(meas_rng, observe(x), S_next, R_team)
        if filt:
            team.update(Z, S_next)
        if central_filter is not None:
            central_filter.update(Z, S_next)
        states[k + 1] = x
        if filt:
            record(k + 1)
    for name, value in out.items():
        if value is not None and not np.all(np.isfinite(value)):
            raise ValueError(
                f"the simulation produced NaN or inf in {name}: the closed loop diverged (unstable gains for "
                "this dt, or values beyond floating point); check K, dt and n_steps"
            )
    if not np.all(np.isfinite(states)):
        raise ValueError(
            "the simulation produced NaN or inf states: the closed loop diverged (unstable gains for this dt, "
            "or values beyond floating point); check K, dt and n_steps"
        )
    if single:  # one run in, no run axis out
        states = states[:, 0]
        out = {k: (v if v is None or k in ("sigma_i", "gains", "f2_cross") else v[:, 0]) for k, v in out.items()}
    return RendezvousResult(mode=mode, dt=float(dt), states=states, model=filter_model, **out)


def _position_index(model: team_model.TeamFilterModel) -> np.ndarray:
    """Reduced-coordinate indices of the position entries (first half of each agent block)."""
    mr = model.m_r
    half = model.m // 2
    per_agent = np.arange(mr)[(np.arange(mr) * model.kron) < half]
    return (np.arange(model.n_agents)[:, None] * mr + per_agent).reshape(-1)
