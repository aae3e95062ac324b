"""The team task: the estimators of the agents' own states in the rendezvous loop, and its simulation."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import estimation, graphs, kalman, rendezvous, set_membership, team_model
from .._validation import frozen_copy
from ..agents import double_integrator
from ..estimation import method_spec
from ..own_state import CentralizedOutputFilter, OwnStateForwardingFilter
from .benchmark import (
    ALL_TEAM_METHODS,
    POSITION_NOT_APPLICABLE,
    SENSINGS,
    SETTINGS,
    SM_CONFIDENCE,
    SWITCHING_GRAPHS,
    VLAHAKIS_PHI,
    BenchmarkSettings,
    benchmark_graph,
    bound_scale,
    check_n_agents,
    check_run,
    draw_noise,
    switching_graphs,
)

# --------------------------------------------------------------------------------------------
# the team task


@dataclass
class _Team:
    """Everything the estimators of one team-task cell share."""

    N: int
    A: np.ndarray
    B: np.ndarray
    K: np.ndarray
    Q: np.ndarray
    Q_filter: np.ndarray
    R: np.ndarray
    adjacency: np.ndarray
    laplacian: np.ndarray
    P0: np.ndarray
    noise: str
    s: BenchmarkSettings
    switching: bool = False  # adjacency and laplacian are this step's (simulate_team sets them at every step)

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


def team_setup(n_agents: int, noise: str, q_scale: float, s: BenchmarkSettings, graph: str = "ring") -> _Team:
    agent = double_integrator(2, s.dt)
    Q = np.diag([s.q_pos, s.q_pos, s.q_vel, s.q_vel])
    switching = graph == "switching"
    adjacency = switching_graphs(n_agents, 1, s)[0] if switching else benchmark_graph(graph, n_agents, s)
    return _Team(N=n_agents, A=agent.A, B=agent.B, K=rendezvous.rendezvous_gain(*s.rho, 2), Q=Q,
                 Q_filter=q_scale * Q, R=s.r * np.eye(4), adjacency=adjacency,
                 laplacian=graphs.laplacian(adjacency), P0=s.p0 * np.eye(4), noise=noise, s=s, switching=switching)


class _Estimator:
    """Interface: ``update(Z, S)`` at step k, ``views(Z, S)`` for the control, ``predict(U)``.

    ``own`` holds the posterior own-state estimates ``(R, N, 4)``; ``own_cov`` their
    covariances (broadcastable to ``(R, N, 4, 4)``) or None; ``link_borne`` says whether
    the neighbours' views travel over the (dropping) links.
    """

    link_borne = True
    own_cov: np.ndarray | None = None

    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        self.t = team
        self.own = x_hat0.copy()

    def views(self, Z: np.ndarray, S: np.ndarray) -> np.ndarray:
        """Own estimate of agent j as the view of j for every i (broadcast)."""
        R, N, m = self.own.shape
        return np.broadcast_to(self.own[:, None], (R, N, N, m))

    def containment(self, x: np.ndarray) -> np.ndarray | None:
        return None

    def agent_inputs(self, Z: np.ndarray, S: np.ndarray, U: np.ndarray, i: int) -> tuple:
        """``(estimator, own, messages)``: agent i's next step of run 0 (update with `Z`, `S`, prediction with `U`).

        The estimator's own ``agent_inputs``, given the state this adapter holds; ``estimator.agent_step(i,
        own, messages)`` is the step.
        """
        raise NotImplementedError(f"{type(self).__name__} has no agent-level step")

    def agent_state(self, i: int) -> tuple:
        """Agent i's state of run 0, as the estimator's ``agent_step`` returns it (to check one against the other)."""
        raise NotImplementedError(f"{type(self).__name__} has no agent-level step")


class _Centralized(_Estimator):
    link_borne = False

    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        super().__init__(team, x_hat0)
        self.filter = method_spec("centralized", "team").build(team, x_hat0)
        self.model = self.filter.model

    def update(self, Z, S):
        self.filter.update(Z, S)
        self.own = self.filter.x_hat

    def predict(self, U):
        self.filter.predict(U)
        self.own = self.filter.x_hat

    @property
    def own_cov(self):
        return _own_blocks(self.filter.P, self.model)

    def agent_inputs(self, Z, S, U, i):
        return (self.filter, *self.filter.agent_inputs(Z, S, U, i))


def _own_blocks(P: np.ndarray, model: team_model.TeamFilterModel) -> np.ndarray:
    """Agent i's own ``(4, 4)`` covariance from reduced team covariances: ``(B, N, 4, 4)``.

    `P` is ``(B, N m_r, N m_r)`` (one team covariance) or ``(B, N, N m_r, N m_r)`` (agent i's own
    team covariance, for each i); block ``(i, i)`` of the matrix of agent i is expanded to the full state.
    """
    N, mr = model.n_agents, model.m_r
    blocks = P.reshape(*P.shape[:-2], N, mr, N, mr)[..., np.arange(N), :, np.arange(N), :]  # (N, ..., mr, mr)
    blocks = np.moveaxis(blocks, 0, -3)
    if P.ndim == 4:  # (B, N agents, N blocks, mr, mr): agent i's block i
        blocks = blocks[:, np.arange(N), np.arange(N)]
    return team_model.expand_covariance(blocks, model.kron)


class _Local(_Estimator):
    """A Kalman filter per agent on its own state (:mod:`mascore.kalman`); one covariance serves all agents."""

    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        super().__init__(team, x_hat0)
        self.P = team.P0.copy()

    def update(self, Z, S):
        N = self.own.shape[1]
        self.own, self.P = kalman.update(self.own, self.P, Z[:, np.arange(N), np.arange(N)], np.eye(4), self.t.R)

    def predict(self, U):
        self.own, self.P = kalman.predict(self.own, self.P, self.t.A, self.t.Q_filter, self.t.B, U)

    @property
    def own_cov(self):
        return self.P

    def agent_inputs(self, Z, S, U, i):
        model = method_spec("local", "team").build(self.t, self.own)
        N = self.t.N
        return (model, *model.agent_inputs(self.own[0], self.P, Z[0, np.arange(N), np.arange(N)], U[0], i))

    def agent_state(self, i):
        return self.own[0, i], self.P


class _Song(_Estimator):
    """Song et al.'s filters; ``X`` is every agent's estimate of the team, ``(R, N, N, 4)``."""

    def __init__(self, team: _Team, x_hat0: np.ndarray, estimation_based: bool) -> None:
        super().__init__(team, x_hat0)
        self.eb = estimation_based
        self.link_borne = not estimation_based
        self.filter = method_spec("song-eb" if estimation_based else "song-mb", "team").build(team, x_hat0)
        self.model = self.filter.model

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
        return _own_blocks(self.filter.agent_covariances(), self.model)

    def agent_inputs(self, Z, S, U, i):
        return (self.filter, *self.filter.agent_inputs(Z, S, i))

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


class _Vlahakis(_Estimator):
    """The Vlahakis observer (:class:`mascore.network_observer.DiscreteNetworkObserver`) with its gains from the LMI."""

    def __init__(self, team: _Team, x_hat0: np.ndarray, name: str = "vlahakis") -> None:
        super().__init__(team, x_hat0)
        self.observer = method_spec(name, "team").build(team, x_hat0)  # the gains of the filter's Q

    def update(self, Z, S):
        self.own = self.observer.update(self.own, Z[..., :2], S)  # z_ij positions; the links delivered

    def predict(self, U):
        self.own = self.observer.predict(self.own, U)

    def agent_inputs(self, Z, S, U, i):
        return (self.observer, *self.observer.agent_inputs(self.own[0], Z[0, :, :, :2], U[0], i))

    def agent_state(self, i):
        return (self.own[0, i],)


class _Forwarding(_Estimator):
    """Measurement forwarding on the own states (:class:`mascore.own_state.OwnStateForwardingFilter`).

    With every agent measuring its own full state and the controls known, the team
    filter splits into one filter per agent, and this one-hop filter *is* the
    centralized one (the test checks it run by run). One covariance per agent and run
    (drop-outs change the count of measurements).
    """

    def __init__(self, team: _Team, x_hat0: np.ndarray, H: np.ndarray | None = None,
                 R: np.ndarray | None = None) -> None:
        super().__init__(team, x_hat0)
        self.P = np.broadcast_to(team.P0, (*x_hat0.shape[:2], 4, 4)).copy()
        self.filter = OwnStateForwardingFilter(team.A, team.B, team.Q_filter, np.eye(4) if H is None else H,
                                               team.R if R is None else R)  # each measurement z_ji = H x_i + nu_ji

    def update(self, Z, S):
        self.own, self.P = self.filter.update(self.own, self.P, Z, S)

    def predict(self, U):
        self.own, self.P = self.filter.predict(self.own, self.P, U)

    @property
    def own_cov(self):
        return self.P

    def agent_inputs(self, Z, S, U, i):
        return (self.filter, *self.filter.agent_inputs(self.own[0], self.P[0], Z[0], S[0], U[0], i))

    def agent_state(self, i):
        return self.own[0, i], self.P[0, i]


class _SetMembership(_Estimator):
    """The closed-form set-membership filter on each agent's own full state (:mod:`mascore.set_membership`).

    The shape and the gain of the closed form do not depend on the measurements (the S-procedure
    bound holds for every noise in its set), every agent and run starts from the same shape and
    measures its own state at every step (drop-outs and switching links do not reach it): the shape
    ``(4, 4)`` is computed once per step by the spec's :class:`mascore.set_membership.SetMembershipModel`
    and its gain applied to every agent and run, eq. (2), with the arithmetic of the batched step.
    """

    def __init__(self, team: _Team, x_hat0: np.ndarray, confidence: float | None = None,
                 name: str = "set-membership") -> None:
        super().__init__(team, x_hat0)
        s = team.s
        self.name = name
        confidence = s.sm_confidence if confidence is None else confidence
        self.model = method_spec(name, "team").build(team, x_hat0)  # bounds scale_noise Q_filter, scale_noise R
        self.shape = bound_scale("gaussian", 4, confidence) * team.P0  # (4, 4): the same for every agent and run

    def update(self, Z, S):
        N = self.t.N
        y = Z[:, np.arange(N), np.arange(N)]                                   # (R, N, 4)
        _, self.shape, L = self.model.correct(self.own[0, 0], self.shape, y[0, 0], check_consistency=False)
        nu = y - self.own @ self.model.C.T
        self.own = self.own + np.einsum("...ij,...j->...i", np.broadcast_to(L, (*nu.shape, 4)), nu)  # eq. (2)

    def predict(self, U):
        _, self.shape = self.model.predict(self.own[0, 0], self.shape, U[0, 0])
        self.own = self.own @ self.t.A.T + U @ self.t.B.T                      # eq. (4)

    def containment(self, x):
        e = x - self.own
        shape = np.broadcast_to(self.shape, (*e.shape, 4))
        return np.einsum("...i,...i->...", e, np.linalg.solve(shape, e[..., None])[..., 0]) <= 1.0 + 1e-9

    @property
    def set_shape(self):
        """The set's shape matrix ``(4, 4)``, the same for every agent and run."""
        return self.shape

    def agent_inputs(self, Z, S, U, i):
        N = self.t.N
        shape = np.broadcast_to(self.shape, (N, 4, 4))
        return (self.model, *self.model.agent_inputs(self.own[0], shape, Z[0, np.arange(N), np.arange(N)], U[0], i))

    def agent_state(self, i):
        return self.own[0, i], self.shape


# ---------------------------------------------------------------- position-only sensing: z_ij = C x_j + nu_ij

#: The position-only output matrix of one agent, ``C = [I_2 0]`` (m).
_C_POS = frozen_copy(np.hstack([np.eye(2), np.zeros((2, 2))]))


class _CentralizedPosition(_Estimator):
    """The centre's Kalman filter of the team with every position measurement.

    :class:`mascore.own_state.CentralizedOutputFilter`, with ``C = [I 0]``.
    """

    link_borne = False

    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        super().__init__(team, x_hat0)
        self.filter = CentralizedOutputFilter(team.A, team.B, team.Q_filter, _C_POS, team.s.r, team.N)
        self.P = np.kron(np.eye(team.N), team.P0)[None]

    def update(self, Z, S):
        self.own, self.P = self.filter.update(self.own, self.P, Z, S)

    def predict(self, U):
        self.own, self.P = self.filter.predict(self.own, self.P, U)

    @property
    def own_cov(self):
        return self.filter.own_covariances(self.P)  # (B, N, 4, 4)


class _LocalPosition(_Local):
    """A Kalman filter per agent on its own state from its own position measurement (``H = C``, ``R = r I_2``)."""

    def update(self, Z, S):
        N = self.own.shape[1]
        self.own, self.P = kalman.update(self.own, self.P, Z[:, np.arange(N), np.arange(N)], _C_POS,
                                         self.t.s.r * np.eye(2))


class _ForwardingPosition(_Forwarding):
    """Forwarding with positions only: agent i corrects with its own and its neighbours' position measurements of i."""

    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        super().__init__(team, x_hat0, H=_C_POS, R=team.s.r * np.eye(2))


class _SetMembershipPosition(_Estimator):
    """The closed-form set-membership filter on each agent's own state from its own position (``C = [I 0]``).

    Bounds: the initial set ``s_4 P_0``, the process set ``s_4 Q``, the measurement set ``s_2 r I_2``,
    with ``s_d`` the chi-square quantile of ``d`` degrees of freedom at the confidence level (bounded
    noise: ``3 d``, which holds the box of the uniform draws: a guaranteed bound). The shape and the gain
    of the closed form do not depend on the measurements (the S-procedure bound holds for every noise
    in its set), and every agent starts from the same shape: they are computed once per step by
    :class:`mascore.set_membership.SetMembershipModel` and the gain applied to every agent and run, eq. (2).
    """

    def __init__(self, team: _Team, x_hat0: np.ndarray, confidence: float | None = None) -> None:
        super().__init__(team, x_hat0)
        s = team.s
        confidence = s.sm_confidence if confidence is None else confidence
        self.model = set_membership.SetMembershipModel(
            A=team.A, G=np.eye(4), C=_C_POS, D=np.eye(2), B=team.B,
            Q=bound_scale(team.noise, 4, confidence) * team.Q_filter,
            R=bound_scale(team.noise, 2, confidence) * s.r * np.eye(2))
        self.shape = bound_scale(team.noise, 4, confidence) * team.P0  # (4, 4): the same for every agent

    def update(self, Z, S):
        N = self.t.N
        y = Z[:, np.arange(N), np.arange(N)]                                   # (R, N, 2)
        _, self.shape, L = self.model.correct(self.own[0, 0], self.shape, y[0, 0], check_consistency=False)
        self.own = self.own + (y - self.own @ _C_POS.T) @ L.T               # eq. (2), every agent and run

    def predict(self, U):
        _, self.shape = self.model.predict(self.own[0, 0], self.shape, U[0, 0])
        self.own = self.own @ self.t.A.T + U @ self.t.B.T                   # eq. (4)

    def containment(self, x):
        e = x - self.own
        return np.einsum("...i,...i->...", e, e @ np.linalg.inv(self.shape)) <= 1.0 + 1e-9

    @property
    def set_shape(self):
        """The set's shape matrix ``(4, 4)``, the same for every agent and run."""
        return self.shape


def make_estimator(method: str, team: _Team, x_hat0: np.ndarray, sensing: str = "full") -> _Estimator:
    if sensing == "position":
        position = {"centralized": _CentralizedPosition, "local": _LocalPosition, "forwarding": _ForwardingPosition}
        if method in position:
            return position[method](team, x_hat0)
        if method in SM_CONFIDENCE:
            return _SetMembershipPosition(team, x_hat0, SM_CONFIDENCE[method])
        if method in POSITION_NOT_APPLICABLE:
            raise ValueError(f"method {method!r} does not apply under position-only sensing: "
                             f"{POSITION_NOT_APPLICABLE[method]}")
    if method in SM_CONFIDENCE and method != "set-membership":
        return _SetMembership(team, x_hat0, SM_CONFIDENCE[method], method)
    if method == "centralized":
        return _Centralized(team, x_hat0)
    if method == "local":
        return _Local(team, x_hat0)
    if method in ("song-mb", "song-eb"):
        return _Song(team, x_hat0, estimation_based=method == "song-eb")
    if method in VLAHAKIS_PHI:
        return _Vlahakis(team, x_hat0, method)
    if method == "forwarding":
        return _Forwarding(team, x_hat0)
    if method == "set-membership":
        return _SetMembership(team, x_hat0)
    raise ValueError(f"method must be one of {ALL_TEAM_METHODS}; got {method!r}")


#: Team methods that do not apply on the switching topology, with the reason (the chapter shows them).
SWITCHING_NOT_APPLICABLE = estimation.not_applicable("switching")


def simulate_team(
    method: str,
    n_agents: int,
    seed: np.random.SeedSequence | int,
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
        One of :data:`TEAM_METHODS` (or a set-membership variant of :data:`SM_CONFIDENCE`);
        under position sensing one of :data:`POSITION_METHODS`.
    n_agents : int
        Team size N (a ring, N >= 3).
    seed : numpy.random.SeedSequence or int
        Source of every random number; the same seed gives the same noise to every method.
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

    Examples
    --------
    >>> from mascore import compare
    >>> m = compare.simulate_team("local", 4, 0, runs=20)
    >>> bool(0.5 < m["nees_own"].mean() < 1.5)          # a correct Kalman filter is consistent
    True
    """
    n_agents, runs = check_run(n_agents, noise, dropout, q_scale, runs, settings, seed)
    if sensing not in SENSINGS:
        raise ValueError(f"sensing must be one of {SENSINGS}; got {sensing!r}")
    if method not in ALL_TEAM_METHODS:
        raise ValueError(f"method must be one of {ALL_TEAM_METHODS}; got {method!r}")
    if sensing == "position" and method in POSITION_NOT_APPLICABLE:
        raise ValueError(f"method {method!r} does not apply under position-only sensing: "
                         f"{POSITION_NOT_APPLICABLE[method]}")
    if graph not in SWITCHING_GRAPHS:
        raise ValueError(f"graph must be one of {SWITCHING_GRAPHS}; got {graph!r}")
    if graph == "switching" and method in SWITCHING_NOT_APPLICABLE:
        raise ValueError(f"{method} does not apply on graph='switching': {SWITCHING_NOT_APPLICABLE[method]}")
    team = team_setup(int(n_agents), noise, float(q_scale), settings, graph)
    topology = switching_graphs(int(n_agents), settings.n_steps, settings) > 0 if team.switching else None
    init_rng, proc_rng, meas_rng, drop_rng = np.random.default_rng(seed).spawn(4)
    N, s = team.N, settings
    x = np.concatenate([s.init_pos * init_rng.standard_normal((runs, N, 2)),
                        s.init_vel * init_rng.standard_normal((runs, N, 2))], axis=-1)
    if sensing == "full":
        x_hat0 = x + np.sqrt(s.p0) * init_rng.standard_normal(x.shape)
    else:  # the noise's distribution: bounded under uniform noise (the set-membership filter's initial set)
        x_hat0 = x + np.sqrt(s.p0) * draw_noise(init_rng, noise, x.shape)
    est = make_estimator(method, team, x_hat0, sensing)
    measured = 4 if sensing == "full" else 2  # z_ij = x_j + nu_ij, or its position [I 0] x_j + nu_ij
    cpu = 0.0  # the estimator's own work only: not its design (offline), not the simulation around it
    q_std, r_std = np.sqrt(np.diag(team.Q)), np.sqrt(s.r)
    nominal = team.adjacency > 0
    eye = np.eye(N, dtype=bool)
    held = None
    acc = {k: np.zeros(runs) for k in ("own", "view", "nees", "contained", "spread", "far", "set_size")}
    acc["far_steps"] = 0  # steps with an agent out of reach (every step on a fixed graph that is not complete)
    for k in range(s.n_steps):
        if topology is not None:  # this step's graph: sensing, messages and the control's Laplacian
            nominal = topology[k]
            team.adjacency = nominal.astype(float)
            team.laplacian = graphs.laplacian(team.adjacency)
        lost = (drop_rng.random((runs, N, N)) < dropout) & ~eye
        S = (nominal | eye) & ~lost
        nu = r_std * draw_noise(meas_rng, noise, (runs, N, N, measured))
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
        U = rendezvous.consensus_control(view, team.laplacian, team.K)
        tic = time.thread_time()
        est.predict(U)
        cpu += time.thread_time() - tic
        w = q_std * draw_noise(proc_rng, noise, (runs, N, 4))
        x = x @ team.A.T + U @ team.B.T + w
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{method}: the closed loop diverged (non-finite states at step {k})")
    n = s.n_steps - s.steady_from
    nan = np.full(runs, np.nan)
    return {
        "rmse_own": np.sqrt(acc["own"] / n), "rmse_view": np.sqrt(acc["view"] / n),
        "nees_own": acc["nees"] / n if est.own_cov is not None else nan,
        "containment": acc["contained"] / n if method in SM_CONFIDENCE else nan,
        "set_size": acc["set_size"] / n if method in SM_CONFIDENCE else nan,
        "rmse_far": np.sqrt(acc["far"] / acc["far_steps"]) if getattr(est, "team_estimates", None) is not None
        and acc["far_steps"] > 0 else nan,
        "spread": np.sqrt(acc["spread"] / n), "cpu_s": np.full(runs, cpu),
    }


def _accumulate(acc: dict, est: _Estimator, x: np.ndarray, view: np.ndarray, seen: np.ndarray) -> None:
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
    shape = getattr(est, "set_shape", None)
    if shape is not None:  # the largest semi-axis of the position block (m)
        axis = np.sqrt(np.linalg.eigvalsh(shape[..., :2, :2])[..., -1])
        acc["set_size"] += np.broadcast_to(axis, e.shape[:2]).mean(-1)
    centred = x[..., :2] - x[..., :2].mean(-2, keepdims=True)
    acc["spread"] += np.mean(np.sum(centred**2, -1), -1)
    team = getattr(est, "team_estimates", None)
    far = ~seen
    if team is not None and far.any():  # agent i's estimates of the agents it neither senses nor hears from
        ef = np.sum((team[..., :2] - x[:, None, :, :2]) ** 2, -1)  # (R, N, N)
        acc["far"] += np.sum(ef * far, (-1, -2)) / far.sum()
        acc["far_steps"] += 1
