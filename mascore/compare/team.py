"""The team task: the estimators of the agents' own states in the rendezvous loop, and its simulation.

A method of the team task is its spec's (:class:`mascore.estimation.MethodSpec`, beside its filter):
``build(team, x_hat0)`` gives its filter on this task's ``TeamTask``. The loop steps it through
:func:`make_estimator`, which holds the filter's state between the steps for the package's filters
(by their class) and steps any other object directly: a new team method is one class, with
``update(Z, S)``, ``predict(U)`` and the own-state estimates ``own`` ``(R, N, 4)`` (optionally ``own_cov``,
``views``, ``link_borne``, ``containment``, ``set_shape``, ``team_estimates`` and the per-agent steps
``agent_inputs(Z, S, U, i)`` / ``agent_step`` / ``agent_state(i)`` of ``TeamEstimator``), and one spec.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import estimation, graphs
from .._validation import check_positive, float_array, frozen_copy, require_finite
from ..agents import double_integrator
from ..estimation import MethodSpec
from .benchmark import (
    SENSINGS,
    SETTINGS,
    SWITCHING_GRAPHS,
    BenchmarkSettings,
    benchmark_graph,
    bound_scale,
    check_n_agents,
    check_run,
    draw_noise,
    switching_graphs,
)

#: The position-only output matrix of one agent, ``C = [I_2 0]`` (m).
_C_POS = frozen_copy(np.hstack([np.eye(2), np.zeros((2, 2))]))


@dataclass
class TeamTask:
    """Everything the estimators of one team-task cell share (the ``team`` of a spec's ``build(team, x_hat0)``).

    Parameters
    ----------
    N : int
        Team size.
    A, B : ndarray
        One agent's double integrator ``(4, 4)``, ``(4, 2)`` (s).
    K : ndarray
        The rendezvous gain ``(2, 4)``.
    Q, Q_filter : ndarray
        The true process-noise covariance ``(4, 4)`` and the filters' (``q_scale`` times it).
    C : ndarray
        What a measurement holds of an agent's state, ``(m, 4)``: ``I_4`` or the position ``[I_2 0]``.
    R : ndarray
        The covariance of one measurement ``z_ij = C x_j + nu_ij``, ``(m, m)`` (m² or m²/s²).
    adjacency, laplacian : ndarray
        The graph ``(N, N)`` (this step's on the switching topology: :func:`simulate_team` sets them).
    P0 : ndarray
        Initial estimation-error covariance ``(4, 4)``.
    noise : str
        The noise distribution.
    s : BenchmarkSettings
        The benchmark's settings.
    switching : bool
        The graph switches.
    sensing : {"full", "position"}
        What a measurement holds (:data:`SENSINGS`).

    Examples
    --------
    >>> from mascore import compare
    >>> compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS, sensing="position").C.shape
    (2, 4)
    """

    N: int
    A: np.ndarray
    B: np.ndarray
    K: np.ndarray
    Q: np.ndarray
    Q_filter: np.ndarray
    C: np.ndarray
    R: np.ndarray
    adjacency: np.ndarray
    laplacian: np.ndarray
    P0: np.ndarray
    noise: str
    s: BenchmarkSettings
    switching: bool = False
    sensing: str = "full"

    def bound_scale(self, dim: int, confidence: float | None = None) -> float:
        """The scale of the covariance ellipsoid given to a set-membership filter as its bound (:func:`bound_scale`)."""
        return bound_scale(self.noise, dim, self.s.sm_confidence if confidence is None else confidence)

    def vlahakis_design(self, phi: float | None) -> tuple[np.ndarray, float, np.ndarray]:
        """The Vlahakis observer's discrete gain ``(4, 2)``, coupling ``Phi`` and output matrix on this team.

        The gains of :func:`_vlahakis_gains` (per axis, from the filter's noise), on ``[p; v]`` of both axes
        sampled at ``dt``; the outputs are the positions.
        """
        L, Phi = _vlahakis_gains(self.adjacency, self.Q_filter[2, 2], self.s.r, self.s.dt, phi)
        return self.s.dt * np.kron(L, np.eye(2)), Phi, _C_POS


def team_setup(n_agents: int, noise: str, q_scale: float, s: BenchmarkSettings, graph: str = "ring",
               sensing: str = "full") -> TeamTask:
    """The team task of one cell: the agents, the graph, the noise, the filters' Q and what is measured.

    Parameters
    ----------
    n_agents : int
        Team size N.
    noise : {"gaussian", "uniform", "student-t"}
        The noise distribution.
    q_scale : float
        The filters' process-noise covariance over the true one.
    s : BenchmarkSettings
        The benchmark's settings.
    graph : {"ring", "geometric", "switching"}
        The graph (the first of the switching topology's).
    sensing : {"full", "position"}
        What a measurement holds (:data:`SENSINGS`).

    Returns
    -------
    TeamTask
        The cell's task.

    Examples
    --------
    >>> from mascore import compare
    >>> compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS).R.shape
    (4, 4)
    """
    if sensing not in SENSINGS:
        raise ValueError(f"sensing must be one of {SENSINGS}; got {sensing!r}")
    q_scale = check_positive(q_scale, "q_scale")
    from ..rendezvous import rendezvous_gain

    agent = double_integrator(2, s.dt)
    Q = np.diag([s.q_pos, s.q_pos, s.q_vel, s.q_vel])
    switching = graph == "switching"
    adjacency = switching_graphs(n_agents, 1, s)[0] if switching else benchmark_graph(graph, n_agents, s)
    C = np.eye(4) if sensing == "full" else _C_POS
    return TeamTask(N=n_agents, A=agent.A, B=agent.B, K=rendezvous_gain(*s.rho, 2), Q=Q,
                    Q_filter=q_scale * Q, C=C, R=s.r * np.eye(len(C)), adjacency=adjacency,
                    laplacian=graphs.laplacian(adjacency), P0=s.p0 * np.eye(4), noise=noise, s=s,
                    switching=switching, sensing=sensing)


class TeamEstimator:
    """A filter of the team task stepped by the loop: its state between the steps, the loop's data cut for it.

    Built by :func:`make_estimator` from a method's spec. The loop calls ``update(Z, S)`` with the
    measurements ``Z`` ``(R, N, N, m)`` (``Z[r, i, j]``: agent i's measurement of agent j) and the
    delivered links ``S`` ``(R or 1, N, N)``, reads the views of the control ``views(Z, S)``
    ``(R, N, N, 4)``, then calls ``predict(U)`` with the controls applied ``(R, N, 2)``. It holds the
    filter's state between the steps: one object per run loop, not for concurrent use.

    Parameters
    ----------
    spec : MethodSpec
        The method.
    filt : object
        Its filter, ``spec.build(team, x_hat0)``.
    team : TeamTask
        The cell's task.
    x_hat0 : ndarray
        The initial estimates ``(R, N, 4)``.

    Attributes
    ----------
    own : ndarray
        The posterior own-state estimates ``(R, N, 4)``.
    own_cov : ndarray or None
        Their covariances, broadcastable to ``(R, N, 4, 4)`` (None: the filter has none).
    link_borne : bool
        The neighbours' views travel over the (dropping) links.
    set_shape : ndarray or None
        A set-membership filter's shape matrices, broadcastable to ``(R, N, 4, 4)``.
    team_estimates : ndarray or None
        Every agent's estimate of every agent ``(R, N, N, 4)`` (a whole-team filter's).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import compare
    >>> team = compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS)
    >>> compare.make_estimator("local", team, np.zeros((2, 4, 4))).own.shape
    (2, 4, 4)
    """

    link_borne = True
    own_cov: np.ndarray | None = None
    set_shape: np.ndarray | None = None
    team_estimates: np.ndarray | None = None

    def __init__(self, spec: MethodSpec, filt, team: TeamTask, x_hat0: np.ndarray) -> None:
        self.filter, self.t = filt, team  # not the spec: an estimator is deep-copied (the cost table's agent step)
        self.own = x_hat0.copy()

    def update(self, Z: np.ndarray, S: np.ndarray) -> None:
        """The filter's correction with the step's measurements `Z` on the delivered links `S`."""
        self.filter.update(Z, S)
        self.own = self.filter.own

    def predict(self, U: np.ndarray) -> None:
        """The filter's prediction with the controls applied `U`."""
        self.filter.predict(U)
        self.own = self.filter.own

    def views(self, Z: np.ndarray, S: np.ndarray) -> np.ndarray:
        """What agent i uses of agent j in its control, ``(R, N, N, 4)``: j's own estimate (broadcast)."""
        R, N, m = self.own.shape
        return np.broadcast_to(self.own[:, None], (R, N, N, m))

    def containment(self, x: np.ndarray) -> np.ndarray | None:
        """Whether each agent's true state `x` ``(R, N, 4)`` lies in its set (None: not a set-membership filter)."""
        return None

    def agent_inputs(self, Z: np.ndarray, S: np.ndarray, U: np.ndarray, i: int) -> tuple:
        """``(own, messages)`` of agent i's next step of run 0 (update with `Z`, `S`, prediction with `U`)."""
        return self.filter.agent_inputs(Z, S, U, i)

    def agent_step(self, i: int, own, messages: Sequence):
        """Agent i's step alone (the filter's ``agent_step``)."""
        return self.filter.agent_step(i, own, messages)

    def agent_state(self, i: int) -> tuple:
        """Agent i's state of run 0, as :meth:`agent_step` returns it (to check one against the other)."""
        return self.filter.agent_state(i)


class _Direct(TeamEstimator):
    """A filter that is a team estimator itself (a new method's class): its optional parts read from it."""

    @property
    def own_cov(self):
        return getattr(self.filter, "own_cov", None)

    @property
    def link_borne(self):
        return getattr(self.filter, "link_borne", True)

    @property
    def set_shape(self):
        return getattr(self.filter, "set_shape", None)

    @property
    def team_estimates(self):
        return getattr(self.filter, "team_estimates", None)

    def views(self, Z, S):
        views = getattr(self.filter, "views", None)
        return super().views(Z, S) if views is None else views(Z, S)

    def containment(self, x):
        inside = getattr(self.filter, "containment", None)
        return None if inside is None else inside(x)


class _Centralized(TeamEstimator):
    """:class:`mascore.centralized_team_filter.CentralizedTeamFilter`: the centre's filter of the team."""

    link_borne = False

    def update(self, Z, S):
        self.filter.update(Z, S)
        self.own = self.filter.x_hat

    def predict(self, U):
        self.filter.predict(U)
        self.own = self.filter.x_hat

    @property
    def own_cov(self):
        return _own_blocks(self.filter.P, self.filter.model)

    def agent_state(self, i):
        raise NotImplementedError("the centre runs the whole filter: no agent state of its own")


def _own_blocks(P: np.ndarray, model) -> np.ndarray:
    """Agent i's own ``(4, 4)`` covariance from reduced team covariances: ``(B, N, 4, 4)``.

    `P` is ``(B, N m_r, N m_r)`` (one team covariance) or ``(B, N, N m_r, N m_r)`` (agent i's own
    team covariance, for each i); block ``(i, i)`` of the matrix of agent i is expanded to the full state.
    """
    N, mr = model.n_agents, model.m_r
    blocks = P.reshape(*P.shape[:-2], N, mr, N, mr)[..., np.arange(N), :, np.arange(N), :]  # (N, ..., mr, mr)
    blocks = np.moveaxis(blocks, 0, -3)
    if P.ndim == 4:  # (B, N agents, N blocks, mr, mr): agent i's block i
        blocks = blocks[:, np.arange(N), np.arange(N)]
    from ..team_model import expand_covariance

    return expand_covariance(blocks, model.kron)


def _own_measurements(Z: np.ndarray) -> np.ndarray:
    """Each agent's measurement of itself, ``Z[:, i, i]``: ``(R, N, m)``."""
    N = Z.shape[1]
    return Z[:, np.arange(N), np.arange(N)]


class _Local(TeamEstimator):
    """A Kalman filter per agent on its own state (:class:`mascore.kalman.LinearGaussianModel`); one covariance."""

    def __init__(self, spec, filt, team, x_hat0):
        super().__init__(spec, filt, team, x_hat0)
        self.P = team.P0.copy()

    def update(self, Z, S):
        from ..kalman import update

        self.own, self.P = update(self.own, self.P, _own_measurements(Z), self.filter.H, self.filter.R)

    def predict(self, U):
        from ..kalman import predict

        self.own, self.P = predict(self.own, self.P, self.t.A, self.t.Q_filter, self.t.B, U)

    @property
    def own_cov(self):
        return self.P

    def agent_inputs(self, Z, S, U, i):
        return self.filter.agent_inputs(self.own[0], self.P, _own_measurements(Z)[0], U[0], i)

    def agent_state(self, i):
        return self.own[0, i], self.P


class _Song(TeamEstimator):
    """Song et al.'s filters (:class:`mascore.distributed_kf.TeamFilter`); every agent estimates the team."""

    def __init__(self, spec, filt, team, x_hat0):
        super().__init__(spec, filt, team, x_hat0)
        self.eb = filt.mode == "eb"
        self.link_borne = not self.eb

    def update(self, Z, S):
        self.filter.update(Z, S)
        N = self.t.N
        self.own = self.filter.view("X_hat")[:, np.arange(N), np.arange(N)]  # fancy indexing copies

    def views(self, Z, S):
        return self.filter.X_hat if self.eb else Z

    @property
    def team_estimates(self):
        """Every agent's estimate of every agent, ``(R, N, N, 4)``."""
        return self.filter.X_hat

    def predict(self, U):
        # switching: every agent predicts with the Laplacian of the control just applied (Song et al.'s
        # Remark 7: the topology known from the neighbours; Theorem 1 itself assumes a fixed one)
        self.filter.predict(self.t.laplacian if self.t.switching else None)

    @property
    def own_cov(self):
        return _own_blocks(self.filter.agent_covariances(), self.filter.model)

    def agent_inputs(self, Z, S, U, i):
        return self.filter.agent_inputs(Z, S, i)

    def agent_state(self, i):
        return self.filter.view("X_hat")[0, i], self.filter.view("Sigma")[0, i]


def _vlahakis_gains(adjacency: np.ndarray, q_vel: float, r: float, dt: float,
                    phi: float | None = None) -> tuple[np.ndarray, float]:
    """Per-axis observer gain ``L`` (2, 1) and coupling ``Phi`` for the graph `adjacency` (a few ms: one per run).

    The weights read the noise as continuous-time intensities: disturbance
    ``q_vel / dt`` on the velocity (``R = dt / q_vel``, with `q_vel` the *filter's*
    velocity variance), measurement ``r dt`` (``Q1 = 1 / (r dt)``), relative outputs
    twice as noisy (``Q2 = Q1 / 2``). `phi` None: the ``Phi`` of LMI (56)-(62) as our
    solver returns it; the LMI's value is flat in ``Phi`` here, and the solver's
    small ``|Y2|`` tie-break term (ours, not the paper's) picks ``Phi`` near 0.
    A number: that ``Phi`` (another point of the optimal interval, see :func:`vlahakis_profile`).
    """
    from .. import observers

    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    obs = observers.distributed_observer(A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]),
                                         Q1=np.eye(1) / (r * dt), Q2=np.eye(1) / (2 * r * dt), R=np.eye(1) * dt / q_vel,
                                         adjacency=adjacency)
    L, Phi = obs.L, float(obs.Phi[0, 0]) if phi is None else float(phi)
    Ad = np.array([[1.0, dt], [0.0, 1.0]])
    C = np.array([[1.0, 0.0]])
    for lam in obs.lam:  # the discretized error dynamics, mode by mode
        radius = max(abs(np.linalg.eigvals(Ad @ (np.eye(2) - dt * (1 + lam * Phi) * L @ C))))
        if radius >= 1.0:
            raise ValueError(f"the forward-Euler discretization of the Vlahakis observer is unstable at dt = {dt} "
                             f"(spectral radius {radius:.3f} for Laplacian eigenvalue {lam:.3f}); use a smaller dt")
    return L, Phi


def vlahakis_profile(n_agents: int = 8, phis: Sequence[float] = (-0.1, 0.0, 0.31, 1.0),
                     settings: BenchmarkSettings = SETTINGS) -> dict[str, float]:
    """The value Gamma(Phi) of the Vlahakis program (56)-(58) at fixed coupling gains, on the ring of `n_agents`.

    Parameters
    ----------
    n_agents : int
        Ring size.
    phis : sequence of float
        Coupling gains at which to evaluate the program.
    settings : BenchmarkSettings
        The benchmark's settings (the weights of :func:`_vlahakis_gains`).

    Returns
    -------
    dict
        ``"Phi = v"`` -> Gamma(v), plus ``"LMI Phi"`` (the solver's choice) and ``"LMI bound"``.
        Equal values over the gains: the program does not determine ``Phi``.

    Examples
    --------
    >>> from mascore import compare
    >>> g = compare.vlahakis_profile(8, (0.0, 1.0))
    >>> bool(abs(g["Phi = 1"] / g["Phi = 0"] - 1) < 1e-3)        # flat: every Phi is optimal
    True
    """
    from .. import observers

    s = settings
    A, Bbar, C = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
    Q1, Q2 = np.eye(1) / (s.r * s.dt), np.eye(1) / (2 * s.r * s.dt)
    obs = observers.distributed_observer(A, Bbar, C, Q1=Q1, Q2=Q2, R=np.eye(1) * s.dt / s.q_vel,
                                         adjacency=graphs.ring_graph(check_n_agents(n_agents)))
    G = [Bbar * np.sqrt(s.q_vel / s.dt)] * len(obs.lam)  # R^{-1/2} Bbar: the disturbance factor
    Rw = [Q1 + lam * Q2 for lam in obs.lam]
    values = observers.bound_at_fixed_phi(A, C, obs.L, obs.lam, G, Rw, np.asarray(phis, float))
    out = {f"Phi = {p:g}": float(v) for p, v in zip(phis, np.atleast_1d(values))}
    out["LMI Phi"] = float(obs.Phi[0, 0])
    out["LMI bound"] = float(obs.bound)
    return out


class _Vlahakis(TeamEstimator):
    """The Vlahakis observer (:class:`mascore.network_observer.DiscreteNetworkObserver`) with its gains from the LMI."""

    @property
    def observer(self):
        return self.filter

    def update(self, Z, S):
        self.own = self.filter.update(self.own, Z[..., :2], S)  # z_ij positions; the links delivered

    def predict(self, U):
        self.own = self.filter.predict(self.own, U)

    def agent_inputs(self, Z, S, U, i):
        return self.filter.agent_inputs(self.own[0], Z[0, :, :, :2], U[0], i)

    def agent_state(self, i):
        return (self.own[0, i],)


class _Forwarding(TeamEstimator):
    """Measurement forwarding on the own states (:class:`mascore.own_state.OwnStateForwardingFilter`).

    With every agent measuring its own full state and the controls known, the team
    filter splits into one filter per agent, and this one-hop filter *is* the
    centralized one (the test checks it run by run). One covariance per agent and run
    (drop-outs change the count of measurements).
    """

    def __init__(self, spec, filt, team, x_hat0):
        super().__init__(spec, filt, team, x_hat0)
        self.P = np.broadcast_to(team.P0, (*x_hat0.shape[:2], 4, 4)).copy()

    def update(self, Z, S):
        self.own, self.P = self.filter.update(self.own, self.P, Z, S)

    def predict(self, U):
        self.own, self.P = self.filter.predict(self.own, self.P, U)

    @property
    def own_cov(self):
        return self.P

    def agent_inputs(self, Z, S, U, i):
        return self.filter.agent_inputs(self.own[0], self.P[0], Z[0], S[0], U[0], i)

    def agent_state(self, i):
        return self.own[0, i], self.P[0, i]


class _CentralizedPosition(_Forwarding):
    """The centre's Kalman filter of the team with every position measurement.

    :class:`mascore.own_state.CentralizedOutputFilter`, with ``C = [I 0]``.
    """

    link_borne = False

    def __init__(self, spec, filt, team, x_hat0):
        TeamEstimator.__init__(self, spec, filt, team, x_hat0)
        self.P = np.kron(np.eye(team.N), team.P0)[None]

    @property
    def own_cov(self):
        return self.filter.own_covariances(self.P)  # (B, N, 4, 4)

    def agent_state(self, i):
        raise NotImplementedError("the centre runs the whole filter: no agent state of its own")


class _SetMembership(TeamEstimator):
    """The closed-form set-membership filter on each agent's own state (:class:`mascore.set_membership.SetMembershipModel`).

    Positions only (``C = [I 0]``): the bounds are the initial set ``s_4 P_0``, the process set
    ``s_4 Q``, the measurement set ``s_2 r I_2``, with ``s_d`` the chi-square quantile of ``d`` degrees
    of freedom at the confidence level (bounded noise: ``3 d``, which holds the box of the uniform draws:
    a guaranteed bound). The shape and the gain of the closed form do not depend on the measurements
    (the S-procedure bound holds for every noise in its set), every agent starts from the same shape and
    measures its own state at every step (drop-outs and switching links do not reach it): they are
    computed once per step, a ``(4, 4)`` shape, and the gain applied to every agent and run, eq. (2) (with
    full-state sensing by the batched step's arithmetic, so its numbers are those of one set per agent
    and run, bit for bit).
    """

    def __init__(self, spec, filt, team, x_hat0):
        super().__init__(spec, filt, team, x_hat0)
        self.model = filt
        self.position = team.sensing == "position"
        if self.position:  # (4, 4): the same for every agent and run
            self.shape = team.bound_scale(4, spec.setting) * team.P0
        else:
            confidence = team.s.sm_confidence if spec.setting is None else spec.setting
            self.shape = bound_scale("gaussian", 4, confidence) * team.P0

    def update(self, Z, S):
        y, m = _own_measurements(Z), self.model
        _, self.shape, L = m.correct(self.own[0, 0], self.shape, y[0, 0], check_consistency=False)
        if self.position:
            self.own = self.own + (y - self.own @ m.C.T) @ L.T               # eq. (2), every agent and run
        else:
            nu = y - self.own @ m.C.T
            self.own = self.own + np.einsum("...ij,...j->...i", np.broadcast_to(L, (*nu.shape, 4)), nu)  # eq. (2)

    def predict(self, U):
        m = self.model
        _, self.shape = m.predict(self.own[0, 0], self.shape, U[0, 0])
        self.own = self.own @ m.A.T + U @ m.B.T                                # eq. (4)

    def containment(self, x):
        e = x - self.own
        if self.position:
            return np.einsum("...i,...i->...", e, e @ np.linalg.inv(self.shape)) <= 1.0 + 1e-9
        shape = np.broadcast_to(self.shape, (*e.shape, 4))
        return np.einsum("...i,...i->...", e, np.linalg.solve(shape, e[..., None])[..., 0]) <= 1.0 + 1e-9

    @property
    def set_shape(self):
        """The set's shape matrix ``(4, 4)``, the same for every agent and run."""
        return self.shape

    def agent_inputs(self, Z, S, U, i):
        if self.position:
            raise NotImplementedError("positions only: one shape for every agent, computed once per step")
        shape = np.broadcast_to(self.shape, (self.own.shape[1], 4, 4))
        return self.filter.agent_inputs(self.own[0], shape, _own_measurements(Z)[0], U[0], i)

    def agent_state(self, i):
        return self.own[0, i], self.shape


def _stepper(filt) -> type[TeamEstimator]:
    """The estimator that steps a filter of the package by its class (another class steps itself: ``_Direct``)."""
    from ..centralized_team_filter import CentralizedTeamFilter
    from ..distributed_kf import TeamFilter
    from ..kalman import LinearGaussianModel
    from ..network_observer import DiscreteNetworkObserver
    from ..own_state import CentralizedOutputFilter, OwnStateForwardingFilter
    from ..set_membership import SetMembershipModel

    stepped_by = ((CentralizedTeamFilter, _Centralized), (CentralizedOutputFilter, _CentralizedPosition),
                  (TeamFilter, _Song), (LinearGaussianModel, _Local), (OwnStateForwardingFilter, _Forwarding),
                  (DiscreteNetworkObserver, _Vlahakis), (SetMembershipModel, _SetMembership))
    return next((est for cls, est in stepped_by if isinstance(filt, cls)), _Direct)


def make_estimator(method: str, team: TeamTask, x_hat0: np.ndarray) -> TeamEstimator:
    """Method `method`'s filter on the team task, ready to step: its spec's ``build(team, x_hat0)``.

    Parameters
    ----------
    method : str
        A method of the team task (its :class:`~mascore.estimation.MethodSpec`).
    team : TeamTask
        The cell's task (:func:`team_setup`).
    x_hat0 : (R, N, 4) array_like
        The initial estimates, finite.

    Returns
    -------
    TeamEstimator
        The filter with its state.

    Raises
    ------
    ValueError
        An unknown method, or one that does not apply under the team's sensing.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import compare
    >>> team = compare.team_setup(4, "gaussian", 1.0, compare.SETTINGS)
    >>> type(compare.make_estimator("song-mb", team, np.zeros((1, 4, 4))).filter).__name__
    'TeamFilter'
    """
    spec = estimation.method_spec(method, "team")
    x_hat0 = require_finite(float_array(x_hat0, "x_hat0"), "x_hat0")
    n = team.A.shape[0]
    if x_hat0.ndim != 3 or x_hat0.shape[1:] != (team.N, n):
        raise ValueError(f"x_hat0 must have shape (R, N, n) = (R, {team.N}, {n}): one estimate per run and agent; "
                         f"got {x_hat0.shape}")
    return _make_estimator(spec, team, x_hat0)


def _make_estimator(spec: MethodSpec, team: TeamTask, x_hat0: np.ndarray) -> TeamEstimator:
    """:func:`make_estimator` of the method of `spec`."""
    why = spec.not_applicable.get("position") if team.sensing == "position" else None
    if why is not None:
        raise ValueError(f"method {spec.name!r} does not apply under position-only sensing: {why}")
    filt = spec.build(team, x_hat0)
    return _stepper(filt)(spec, filt, team, x_hat0)


def simulate_team(
    method: str,
    n_agents: int,
    seed: np.random.SeedSequence | int | Sequence[np.random.SeedSequence | int],
    *,
    noise: str = "gaussian",
    dropout: float = 0.0,
    q_scale: float = 1.0,
    graph: str = "ring",
    runs: int | None = None,
    settings: BenchmarkSettings = SETTINGS,
    sensing: str = "full",
) -> dict[str, np.ndarray]:
    """Run one estimator in the rendezvous loop, batched over Monte Carlo runs.

    Parameters
    ----------
    method : str
        A method of the team task (:data:`ALL_TEAM_METHODS`: their specs'); under position sensing one of
        :data:`POSITION_METHODS`.
    n_agents : int
        Team size N (a ring, N >= 3).
    seed : numpy.random.SeedSequence or int, or a sequence of them
        Source of every random number; the same seed gives the same noise to every method. A
        sequence: one block of `runs` runs per seed, each block's initial states, noise and link
        drops drawn from its own seed's streams, so that each block's numbers are those of the
        call with its seed alone; the blocks are stepped as one batch (Python's work per step, a
        filter's design and a covariance recursion that does not depend on the data done once).
    noise : {"gaussian", "uniform", "student-t"}
        Distribution of process and measurement noise (same covariance).
    dropout : float
        Probability that a link's measurement and message are lost at a step.
    q_scale : float
        The filters' process-noise covariance over the true one (1: correct).
    graph : {"ring", "geometric", "switching"}
        The sensing and communication graph (:func:`benchmark_graph`). ``"switching"``: at
        step k the graph ``switching_graphs(N, settings.n_steps)[k]`` (:func:`switching_graphs`)
        carries the measurements, the messages and the rendezvous law's Laplacian; the
        centralized filter and forwarding use the measurements of the current links, Song et
        al.'s filters predict with the current Laplacian, a view of an agent out of reach stays
        the last one received (as with drop-outs). The Vlahakis observers do not apply
        (:data:`SWITCHING_NOT_APPLICABLE`): a ValueError.
    runs : int, optional
        Monte Carlo runs (default ``settings.runs``).
    settings : BenchmarkSettings
        The benchmark's settings.
    sensing : {"full", "position"}
        ``"full"``: every measurement is a full state, ``z_ij = x_j + nu_ij`` (Song et al.
        eq. (2)); ``"position"``: its position only, ``z_ij = [I 0] x_j + nu_ij`` with
        noise covariance ``r I_2``, and the initial estimation errors are drawn from the
        noise's distribution (bounded under uniform noise, so that the set-membership
        filter's initial set holds them). Song et al.'s filters do not apply
        (:data:`POSITION_NOT_APPLICABLE`).

    Returns
    -------
    dict of str to ndarray
        Per run ``(runs,)``: ``rmse_own`` (m), RMS error of each agent's own
        position estimate over the steady window; ``rmse_view`` (m), of the
        positions its control uses (itself and its neighbours at that step); ``nees_own``,
        mean normalized estimation error squared of the own state per degree
        of freedom (NaN without a covariance); ``rmse_far`` (m), of the positions of the
        agents it neither senses nor hears from (Song et al.'s filters only, which estimate
        the whole team; NaN otherwise); ``containment``, fraction of
        agent-steps whose true state lies in the set-membership ellipsoid (NaN
        for the other methods); ``set_size`` (m), the set-membership set's largest position
        semi-axis (square root of the largest eigenvalue of the position block of its
        shape), averaged over the steady window and the agents (NaN for the other
        methods); ``spread`` (m), steady-state RMS distance of
        the agents to their centroid; and ``cpu_s``, the CPU time (s) of this
        thread spent in the estimator's updates and predictions for the whole
        batch (not its design, not the simulation around it; one value, repeated).
        With a sequence of seeds: ``(len(seed) runs,)``, the blocks one after the other.

    Examples
    --------
    >>> from mascore import compare
    >>> m = compare.simulate_team("local", 4, 0, runs=20)
    >>> bool(0.5 < m["nees_own"].mean() < 1.5)          # a correct Kalman filter is consistent
    True
    """
    seeds = list(seed) if isinstance(seed, (list, tuple)) else [seed]
    if not seeds:
        raise ValueError("seed must be a seed or a non-empty sequence of seeds (one per block of runs)")
    for sd in seeds:
        n_agents, runs = check_run(n_agents, noise, dropout, q_scale, runs, settings, sd)
    total = runs * len(seeds)  # every block's runs, stepped at once
    check_run(n_agents, noise, dropout, q_scale, total, settings)
    if sensing not in SENSINGS:
        raise ValueError(f"sensing must be one of {SENSINGS}; got {sensing!r}")
    specs = {spec.name: spec for spec in estimation.method_specs("team")}  # one scan of the package
    if method not in specs:
        raise ValueError(f"method must be one of {tuple(specs)}; got {method!r}")
    if graph not in SWITCHING_GRAPHS:
        raise ValueError(f"graph must be one of {SWITCHING_GRAPHS}; got {graph!r}")
    why = specs[method].not_applicable.get("switching")
    if graph == "switching" and why is not None:
        raise ValueError(f"{method} does not apply on graph='switching': {why}")
    from .._team_kernels import control_inputs

    team = team_setup(int(n_agents), noise, float(q_scale), settings, graph, sensing)
    topology = switching_graphs(int(n_agents), settings.n_steps, settings) > 0 if team.switching else None
    init_rngs, proc_rngs, meas_rngs, drop_rngs = zip(*(np.random.default_rng(sd).spawn(4) for sd in seeds))
    N, s = team.N, settings
    x, x_hat0 = (np.concatenate(a) for a in zip(*(_initial_states(rng, runs, N, s, sensing, noise)
                                                   for rng in init_rngs)))
    est = _make_estimator(specs[method], team, x_hat0)  # refuses a method that does not apply to the sensing
    measured = len(team.C)  # z_ij = x_j + nu_ij, or its position [I 0] x_j + nu_ij
    cpu = 0.0  # the estimator's own work only: not its design (offline), not the simulation around it
    q_std, r_std = np.sqrt(np.diag(team.Q)), np.sqrt(s.r)
    nominal = team.adjacency > 0
    eye = np.eye(N, dtype=bool)
    held = None
    acc = {k: np.zeros(total) for k in ("own", "view", "nees", "contained", "spread", "far", "set_size")}
    acc["far_steps"] = 0  # steps with an agent out of reach (every step on a fixed graph that is not complete)
    for k in range(s.n_steps):
        if topology is not None:  # this step's graph: sensing, messages and the control's Laplacian
            nominal = topology[k]
            team.adjacency = nominal.astype(float)
            team.laplacian = graphs.laplacian(team.adjacency)
        if dropout > 0:  # the drop-outs' own streams (without drop-outs nothing is drawn from them)
            S = (nominal | eye) & ~((_blocks(drop_rngs, lambda rng: rng.random((runs, N, N))) < dropout) & ~eye)
        else:
            S = np.broadcast_to(nominal | eye, (total, N, N))
        nu = r_std * _blocks(meas_rngs, lambda rng: draw_noise(rng, noise, (runs, N, N, measured)))
        Z = np.where(S[..., None], x[:, None, :, :measured] + nu, 0.0)
        tic = time.thread_time()
        est.update(Z, S if dropout > 0 else S[:1])
        fresh = est.views(Z, S)
        cpu += time.thread_time() - tic
        if est.link_borne:
            held = fresh.copy() if held is None else np.where(S[..., None], fresh, held)
            view = held
        else:
            view = fresh
        if k >= s.steady_from:
            _accumulate(acc, est, x, view, nominal | eye)
        U = control_inputs(view, team.laplacian, team.K)  # rendezvous.consensus_control's law (its arguments are ours)
        tic = time.thread_time()
        est.predict(U)
        cpu += time.thread_time() - tic
        w = q_std * _blocks(proc_rngs, lambda rng: draw_noise(rng, noise, (runs, N, 4)))
        x = x @ team.A.T + U @ team.B.T + w
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{method}: the closed loop diverged (non-finite states at step {k})")
    n = s.n_steps - s.steady_from
    nan = np.full(total, np.nan)
    return {
        "rmse_own": np.sqrt(acc["own"] / n), "rmse_view": np.sqrt(acc["view"] / n),
        "nees_own": acc["nees"] / n if est.own_cov is not None else nan,
        "containment": acc["contained"] / n if est.set_shape is not None else nan,
        "set_size": acc["set_size"] / n if est.set_shape is not None else nan,
        "rmse_far": np.sqrt(acc["far"] / acc["far_steps"]) if est.team_estimates is not None
        and acc["far_steps"] > 0 else nan,
        "spread": np.sqrt(acc["spread"] / n), "cpu_s": np.full(total, cpu),
    }


def _initial_states(rng: np.random.Generator, runs: int, N: int, s: BenchmarkSettings, sensing: str,
                    noise: str) -> tuple[np.ndarray, np.ndarray]:
    """One block's true initial states and initial estimates, ``(runs, N, 4)`` each (m, m/s), from `rng`."""
    x = np.concatenate([s.init_pos * rng.standard_normal((runs, N, 2)),
                        s.init_vel * rng.standard_normal((runs, N, 2))], axis=-1)
    if sensing == "full":
        return x, x + np.sqrt(s.p0) * rng.standard_normal(x.shape)
    # the noise's distribution: bounded under uniform noise (the set-membership filter's initial set)
    return x, x + np.sqrt(s.p0) * draw_noise(rng, noise, x.shape)


def _blocks(rngs: Sequence[np.random.Generator], draw) -> np.ndarray:
    """``draw(rng)`` of every block's stream, the blocks one after the other along the first (run) axis."""
    return draw(rngs[0]) if len(rngs) == 1 else np.concatenate([draw(rng) for rng in rngs])


def _accumulate(acc: dict, est: TeamEstimator, x: np.ndarray, view: np.ndarray, seen: np.ndarray) -> None:
    """Add one step's squared errors (averaged over agents) to the per-run sums."""
    e = x - est.own
    acc["own"] += np.mean(np.sum(e[..., :2] ** 2, -1), -1)
    ev = np.sum((view[..., :2] - x[:, None, :, :2]) ** 2, -1)  # (R, N, N)
    acc["view"] += np.sum(ev * seen, (-1, -2)) / seen.sum()
    if est.own_cov is not None:
        P = np.broadcast_to(est.own_cov, (*e.shape, 4))
        acc["nees"] += np.mean(np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0]), -1) / 4
    inside = est.containment(x)
    if inside is not None:
        acc["contained"] += inside.mean(-1)
    shape = est.set_shape
    if shape is not None:  # the largest semi-axis of the position block (m)
        axis = np.sqrt(np.linalg.eigvalsh(shape[..., :2, :2])[..., -1])
        acc["set_size"] += np.broadcast_to(axis, e.shape[:2]).mean(-1)
    centred = x[..., :2] - x[..., :2].mean(-2, keepdims=True)
    acc["spread"] += np.mean(np.sum(centred**2, -1), -1)
    team = est.team_estimates
    far = ~seen
    if team is not None and far.any():  # agent i's estimates of the agents it neither senses nor hears from
        ef = np.sum((team[..., :2] - x[:, None, :, :2]) ** 2, -1)  # (R, N, N)
        acc["far"] += np.sum(ef * far, (-1, -2)) / far.sum()
        acc["far_steps"] += 1
