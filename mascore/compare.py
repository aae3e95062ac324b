"""One benchmark for every estimator: accuracy, consistency, messages and CPU, side by side.

**The team task.** ``N`` identical planar double integrators (``dt = 0.1`` s,
state ``[p_x, p_y, v_x, v_y]``) run the rendezvous law of Song et al. eq. (4),
``u_i = -K sum_j a_ij (x_i - x_j)``, on a ring (or a geometric graph,
:func:`benchmark_graph`), with each agent's *views* of
itself and of its neighbours in place of the true states. Agent ``i`` measures
its own state and, on every link of the graph, its neighbours' states,
``z_ij = x_j + nu_ij`` (Song et al. eq. (2)). The methods differ only in how an
agent forms its views:

=================== ========================================================================
``centralized``     one Kalman filter over the whole team with every measurement (the bound;
                    all-to-all communication)
``local``           a Kalman filter per agent on its own state from its own measurement; the
                    neighbours' views are their broadcast estimates (no cooperation: the floor)
``song-mb``         Song et al.'s whole-team filter on every agent, control on measurements
                    (eqs. (5), (8)-(20))
``song-eb``         Song et al.'s estimation-based filter, control on the agent's own team
                    estimate (eqs. (21), (29)-(34))
``vlahakis``        the LQR-dual distributed observer (Vlahakis and Halikias), designed per
                    axis in continuous time and discretized (forward Euler), with own and
                    relative position measurements
``set-membership``  the closed-form set-membership filter of Bhattacharjee and Subbarao on
                    each agent's own state, given an ellipsoidal noise bound
=================== ========================================================================

**The shared task** (Ren et al.): every agent holds a prior estimate of one
common 2-D quantity, with its own covariance; the methods are the central
fusion (the bound), no fusion, average consensus and Ren et al.'s discrete
Kalman consensus, over the same ring.

**Robustness axes**: link drop-outs (each link's measurement and message lost with
probability ``dropout`` at each step; a lost message leaves the last received
view in place), noise distribution (Gaussian, bounded uniform, Student-t with 3
degrees of freedom, all with the same covariance) and a wrong process-noise
covariance in the filters (``q_scale`` times the true one).

Every random number of a cell comes from :func:`mascore.sweep.cell_seed` on the
seed axes :data:`SEED_AXES`, which leave out the method, the drop-out probability
and ``q_scale``: all methods see the same noise (common random numbers), and the
drop-out patterns are nested (a link lost at ``p = 0.1`` is also lost at ``0.3``).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from . import consensus, graphs, kalman, rendezvous, set_membership
from . import distributed_kf as dkf
from ._validation import check_fits_in_memory, check_positive, check_positive_int, check_probability, check_seed
from .agents import double_integrator
from .registry import FigureSpec, PaperRegistry, Study, TableSpec, check_settings, check_settings_type, setting
from .sweep import Grid, cell_seed

__all__ = [
    "FIGURES",
    "GRAPHS",
    "REGISTRY",
    "SEED_AXES",
    "SETTINGS",
    "SHARED_METHODS",
    "STUDY",
    "TABLES",
    "TEAM_METHODS",
    "BenchmarkSettings",
    "CompareResult",
    "benchmark_graph",
    "cell_cost",
    "claims",
    "compare_claims",
    "fitted_slopes",
    "floats_per_step",
    "grid_cells",
    "headline",
    "plot_cost",
    "plot_pareto",
    "plot_robustness",
    "run",
    "run_cell",
    "run_compare",
    "simulate_shared",
    "simulate_team",
    "summarize",
]

#: Estimators of the team task, in table order.
TEAM_METHODS = ("centralized", "local", "song-mb", "song-eb", "vlahakis", "set-membership")
#: Estimators of the shared-quantity task.
SHARED_METHODS = ("central-fusion", "no-fusion", "average-consensus", "ren-kc")
#: Sensing/communication graphs: a ring, or the proximity graph of a random layout.
GRAPHS = ("ring", "geometric")
#: Noise distributions, all with the covariance of the settings.
NOISES = ("gaussian", "uniform", "student-t")
#: Coordinates that choose a cell's random numbers (not the method, drop-out or q_scale: common random numbers).
SEED_AXES = ("task", "n_agents", "noise", "block")


#: Largest initial spread or noise std (m, m/s) the benchmark accepts: the squared errors stay far from overflow.
_MAX_SCALE = 1e6


@dataclass(frozen=True)
class BenchmarkSettings:
    """The common benchmark's settings (one place; the chapter shows them).

    Every field is checked when the settings are built or ``dataclasses.replace``-d
    (``mascore.registry.check_settings``): counts >= 1, variances and scales finite
    and non-negative (at most 1e6 m or m/s for the scales, 1e12 for the variances).

    Parameters
    ----------
    dt : float
        Sampling time (s).
    n_steps : int
        Steps per run of the team task.
    steady_from : int
        First step of the window over which the steady-state metrics are averaged.
    q_pos, q_vel : float
        Process-noise variance per step of each position and velocity entry (m², m²/s²).
    r : float
        Measurement-noise variance of each measured entry (m² or m²/s²).
    rho : tuple of float
        Rendezvous gain ``K = [rho_1 I, rho_2 I]`` (Song et al. eq. (4)).
    init_pos, init_vel : float
        Standard deviations of the initial positions (m) and velocities (m/s).
    p0 : float
        Initial estimation-error variance of every state entry (filters' ``P_0``).
    sensing_range, mean_degree : float
        The ``"geometric"`` graph: the proximity graph of range ``sensing_range``
        over a random layout in a square sized for this expected number of
        neighbours (see :func:`benchmark_graph`).
    sm_confidence : float
        Probability mass of the ellipsoid given to the set-membership filter as the
        noise bound when the noise is not bounded (Gaussian, Student-t).
    shared_steps : int
        Steps of the shared-quantity task.
    shared_var : tuple of float
        Range of the agents' prior variances in the shared task (m²), drawn log-uniformly.
    runs : int
        Monte Carlo runs per cell (one block of seeds).
    grid : {"quick", "full"}
        The sweep :func:`run` makes (:func:`grid_cells`): ``"quick"`` for the book and the
        published ledger, ``"full"`` for the command line.


    Examples
    --------
    >>> from mascore.compare import SETTINGS
    >>> SETTINGS.dt, SETTINGS.n_steps
    (0.1, 150)
    """

    dt: float = setting(0.1, source="chosen", unit="s", note="sampling time", low=0, low_open=True)
    n_steps: int = setting(150, source="chosen", note="steps per run of the team task", low=1)
    steady_from: int = setting(75, source="chosen", note="first step of the steady-state window", low=0)
    q_pos: float = setting(1e-4, source="chosen", unit="m²", note="process-noise variance per position entry",
                           low=0, high=_MAX_SCALE**2)
    q_vel: float = setting(1e-4, source="chosen", unit="m²/s²", note="process-noise variance per velocity entry",
                           low=0, high=_MAX_SCALE**2)
    r: float = setting(0.01, source="chosen", note="measurement-noise variance of each measured entry",
                       low=0, low_open=True, high=_MAX_SCALE**2)
    rho: tuple[float, float] = setting((0.5, 1.5), source="chosen", where="Song et al. eq. (4)",
                                       note="rendezvous gain K = [rho_1 I, rho_2 I]", length=2, low=0, low_open=True)
    init_pos: float = setting(5.0, source="chosen", unit="m", note="std of the initial positions",
                              low=0, high=_MAX_SCALE)
    init_vel: float = setting(1.0, source="chosen", unit="m/s", note="std of the initial velocities",
                              low=0, high=_MAX_SCALE)
    p0: float = setting(1.0, source="chosen", note="initial estimation-error variance of every state entry",
                        low=0, low_open=True, high=_MAX_SCALE**2)
    sm_confidence: float = setting(0.997, source="chosen", note="probability mass of the set-membership bound",
                                   low=0, low_open=True, high=1, high_open=True)
    sensing_range: float = setting(1.0, source="chosen", unit="m", note="range of the geometric graph",
                                   low=0, low_open=True)
    mean_degree: float = setting(4.0, source="chosen", note="expected neighbours of the geometric graph",
                                 low=0, low_open=True)
    shared_steps: int = setting(30, source="chosen", note="steps of the shared-quantity task", low=1)
    shared_var: tuple[float, float] = setting((0.5, 5.0), source="chosen", unit="m²",
                                              note="range of the prior variances of the shared task",
                                              length=2, low=0, low_open=True)
    runs: int = setting(50, source="chosen", note="Monte Carlo runs per cell", low=1)
    grid: str = setting("quick", source="chosen", note="the sweep run makes", choices=("quick", "full"))

    def __post_init__(self) -> None:
        check_settings(self)
        if self.steady_from >= self.n_steps:
            raise ValueError(f"BenchmarkSettings.steady_from must be a step before n_steps ({self.n_steps}); "
                             f"got {self.steady_from}")
        if self.shared_var[0] > self.shared_var[1]:
            raise ValueError(f"BenchmarkSettings.shared_var must be a range (low, high) with low <= high; "
                             f"got {self.shared_var}")


#: The settings used by the chapter and the CLI (the study's settings, :data:`STUDY`).
SETTINGS = BenchmarkSettings()


def benchmark_graph(kind: str, n_agents: int, settings: BenchmarkSettings = SETTINGS) -> np.ndarray:
    """The benchmark's sensing and communication graph, fixed during a run.

    Parameters
    ----------
    kind : {"ring", "geometric"}
        ``"ring"``: each agent senses its two ring neighbours. ``"geometric"``: the
        proximity graph (range ``settings.sensing_range``) of ``n_agents`` points
        drawn uniformly in a square whose side gives ``settings.mean_degree``
        expected neighbours; the layout is drawn from a seed fixed by ``n_agents``
        (the first connected one), so every cell and method of a sweep sees the same graph.
    n_agents : int
        Team size N >= 3.
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    (N, N) ndarray
        Symmetric 0/1 adjacency of a connected graph.

    Examples
    --------
    >>> from mascore import compare, graphs
    >>> A = compare.benchmark_graph("geometric", 16)
    >>> graphs.is_connected(A), A.shape
    (True, (16, 16))
    """
    check_settings_type(settings, BenchmarkSettings)
    n_agents = _check_n_agents(n_agents)
    if kind == "ring":
        return graphs.ring_graph(n_agents)
    if kind != "geometric":
        raise ValueError(f"kind must be one of {GRAPHS}; got {kind!r}")
    side = np.sqrt(n_agents * np.pi * settings.sensing_range**2 / settings.mean_degree)
    for attempt in range(1000):
        layout = np.random.default_rng([n_agents, attempt]).uniform(0.0, side, (n_agents, 2))
        A = graphs.proximity_graph(layout, settings.sensing_range)
        if graphs.is_connected(A):
            return A
    raise ValueError(f"no connected geometric graph of {n_agents} agents in 1000 layouts; raise mean_degree")


def floats_per_step(method: str, n_agents: int, degree: float = 2.0) -> float:
    """Floats one agent sends per step, by method (the communication cost).

    Parameters
    ----------
    method : str
        One of :data:`TEAM_METHODS` or :data:`SHARED_METHODS`.
    n_agents : int
        Team size N.
    degree : float
        Number of neighbours of the agent (2 on a ring; the mean degree of another graph).

    Returns
    -------
    float
        ``centralized``: its measurements up, ``4 (degree + 1)``, plus the
        estimates it needs down, ``4 (degree + 1)``, counted once at each end;
        ``local``, ``vlahakis``, ``set-membership``: one broadcast of the own
        estimate (4; Vlahakis's coupling uses its output part);
        ``song-mb``, ``song-eb``: 0 (they sense, they do not talk);
        ``ren-kc``: the estimate and its covariance (2 + 3);
        ``average-consensus``: 2; ``central-fusion``: 5 up, 2 down; ``no-fusion``: 0.

    Examples
    --------
    >>> from mascore.compare import floats_per_step
    >>> floats_per_step("centralized", 8), floats_per_step("song-eb", 8)
    (24.0, 0.0)
    """
    _check_n_agents(n_agents)
    degree = check_positive(degree, "degree", "(mean neighbours per agent)")
    table = {
        "centralized": 8.0 * (degree + 1), "local": 4.0, "song-mb": 0.0, "song-eb": 0.0,
        "vlahakis": 4.0, "set-membership": 4.0,
        "central-fusion": 7.0, "no-fusion": 0.0, "average-consensus": 2.0, "ren-kc": 5.0,
    }
    if method not in table:
        raise ValueError(f"method must be one of {TEAM_METHODS + SHARED_METHODS}; got {method!r}")
    return table[method]


def _check_n_agents(n_agents: object) -> int:
    return check_positive_int(n_agents, "n_agents", minimum=3)


def _check_run(n_agents: object, noise: object, dropout: object, q_scale: object, runs: object,
               settings: BenchmarkSettings, seed: object = 0) -> tuple[int, int]:
    """The arguments of a simulation, checked: ``(n_agents, runs)``."""
    if not isinstance(seed, np.random.SeedSequence):
        check_seed(seed, "seed")
    check_settings_type(settings, BenchmarkSettings)
    n_agents = _check_n_agents(n_agents)
    if noise not in NOISES:
        raise ValueError(f"noise must be one of {NOISES}; got {noise!r}")
    if check_probability(dropout, "dropout") >= 1.0:
        raise ValueError("dropout must be below 1 (every link lost at every step leaves nothing to compare)")
    check_positive(q_scale, "q_scale", "(the filters' Q over the true Q)")
    runs = check_positive_int(settings.runs if runs is None else runs, "runs")
    # the team filters hold (runs, N, N, 4) views and up to (runs, 4N, 4N) covariances at once
    check_fits_in_memory(8.0 * runs * (n_agents**2 * 4 * 8 + (4 * n_agents) ** 2 * 3), "runs",
                         "the estimates and covariances of one step")
    return n_agents, runs


# --------------------------------------------------------------------------------------------
# noise


def _check_cell(cell: object, name: str = "cell", full: bool = True) -> Mapping[str, Any]:
    """A cell of the grid, checked: its task, method, team size, drop-out and (`full`) noise and q_scale."""
    if not isinstance(cell, Mapping):
        raise TypeError(f"{name} must be a mapping of the cell's coordinates (task, method, n_agents, noise, "
                        f"dropout, q_scale); got {type(cell).__name__}")
    task = cell.get("task")
    if task not in ("team", "shared"):
        raise ValueError(f"{name}['task'] must be 'team' or 'shared'; got {task!r}")
    required = ("method", "n_agents", "dropout") + (("noise",) if full else ()) + (
        ("q_scale",) if full and task == "team" else ())
    missing = [k for k in required if k not in cell]
    if missing:
        raise ValueError(f"{name} lacks the coordinates {missing} (a {task} cell needs {list(required)})")
    methods = TEAM_METHODS if task == "team" else SHARED_METHODS
    if cell["method"] not in methods:
        raise ValueError(f"{name}['method'] of a {task} cell must be one of {methods}; got {cell['method']!r}")
    check_positive_int(cell["n_agents"], f"{name}['n_agents']", minimum=3)
    if "noise" in cell and cell["noise"] not in NOISES:
        raise ValueError(f"{name}['noise'] must be one of {NOISES}; got {cell['noise']!r}")
    if check_probability(cell["dropout"], f"{name}['dropout']") >= 1.0:
        raise ValueError(f"{name}['dropout'] must be below 1; got {cell['dropout']!r}")
    if task == "team" and "q_scale" in cell:
        check_positive(cell["q_scale"], f"{name}['q_scale']")
    if task == "team" and cell.get("graph", "ring") not in GRAPHS:
        raise ValueError(f"{name}['graph'] must be one of {GRAPHS}; got {cell.get('graph')!r}")
    return cell


def _draw(rng: np.random.Generator, noise: str, shape: tuple) -> np.ndarray:
    """Zero-mean, unit-variance samples of the chosen distribution."""
    if noise == "gaussian":
        return rng.standard_normal(shape)
    if noise == "uniform":
        return rng.uniform(-np.sqrt(3.0), np.sqrt(3.0), shape)
    return rng.standard_t(3.0, shape) / np.sqrt(3.0)  # Student-t(3) has variance 3


def _bound_scale(noise: str, dim: int, confidence: float) -> float:
    """``s`` such that the ellipsoid ``{w : w^T (s Cov)^{-1} w <= 1}`` is the bound given to the set-membership filter.

    Uniform noise: the box of half-widths ``sqrt(3 var)`` lies inside ``3 dim Cov``
    (a guaranteed bound). Otherwise the chi-square quantile at `confidence`.
    """
    if noise == "uniform":
        return 3.0 * dim
    from scipy.stats import chi2

    return float(chi2.ppf(confidence, dim))


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


def _team(n_agents: int, noise: str, q_scale: float, s: BenchmarkSettings, graph: str = "ring") -> _Team:
    agent = double_integrator(2, s.dt)
    Q = np.diag([s.q_pos, s.q_pos, s.q_vel, s.q_vel])
    adjacency = benchmark_graph(graph, n_agents, s)
    return _Team(N=n_agents, A=agent.A, B=agent.B, K=rendezvous.rendezvous_gain(*s.rho, 2), Q=Q,
                 Q_filter=q_scale * Q, R=s.r * np.eye(4), adjacency=adjacency,
                 laplacian=graphs.laplacian(adjacency), P0=s.p0 * np.eye(4), noise=noise, s=s)


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


class _Centralized(_Estimator):
    link_borne = False

    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        super().__init__(team, x_hat0)
        self.model = dkf.team_filter_model(team.A, team.B, team.K, team.Q_filter, team.R, team.N)
        self.filter = dkf.CentralizedFilter(self.model, team.B, x_hat0, team.P0)

    def update(self, Z, S):
        self.filter.update(Z, S)
        self.own = self.filter.x_hat

    def predict(self, U):
        self.filter.predict(U)
        self.own = self.filter.x_hat

    @property
    def own_cov(self):
        return _own_blocks(self.filter.P, self.model)


def _own_blocks(P: np.ndarray, model: dkf.TeamFilterModel) -> np.ndarray:
    """Agent i's own ``(4, 4)`` covariance from reduced team covariances: ``(B, N, 4, 4)``.

    `P` is ``(B, N m_r, N m_r)`` (one team covariance) or ``(B, N, N m_r, N m_r)`` (agent i's own
    team covariance, for each i); block ``(i, i)`` of the matrix of agent i is expanded to the full state.
    """
    N, mr = model.n_agents, model.m_r
    blocks = P.reshape(*P.shape[:-2], N, mr, N, mr)[..., np.arange(N), :, np.arange(N), :]  # (N, ..., mr, mr)
    blocks = np.moveaxis(blocks, 0, -3)
    if P.ndim == 4:  # (B, N agents, N blocks, mr, mr): agent i's block i
        blocks = blocks[:, np.arange(N), np.arange(N)]
    return dkf.expand_covariance(blocks, model.kron)


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


class _Song(_Estimator):
    """Song et al.'s filters; ``X`` is every agent's estimate of the team, ``(R, N, N, 4)``."""

    def __init__(self, team: _Team, x_hat0: np.ndarray, estimation_based: bool) -> None:
        super().__init__(team, x_hat0)
        self.eb = estimation_based
        self.link_borne = not estimation_based
        self.model = dkf.team_filter_model(team.A, team.B, team.K, team.Q_filter, team.R, team.N)
        R, N, m = x_hat0.shape  # one common initial estimate; links dropping per run split the covariance
        self.filter = dkf.TeamFilter(self.model, team.laplacian, x_hat0.reshape(R, N * m), team.P0,
                                     mode="eb" if estimation_based else "mb")

    def update(self, Z, S):
        self.filter.update(Z, S)
        N = self.t.N
        self.own = self.filter.X_hat[:, np.arange(N), np.arange(N)]

    def views(self, Z, S):
        return self.filter.X_hat if self.eb else Z

    def predict(self, U):
        self.filter.predict()

    @property
    def own_cov(self):
        return _own_blocks(self.filter.agent_covariances(), self.model)


def _vlahakis_gains(adjacency: np.ndarray, q_vel: float, r: float, dt: float) -> tuple[np.ndarray, float]:
    """Per-axis observer gain ``L`` (2, 1) and coupling ``Phi`` for the graph `adjacency` (a few ms: one per run).

    The weights read the noise as continuous-time intensities: disturbance
    ``q_vel / dt`` on the velocity (``R = dt / q_vel``), measurement ``r dt``
    (``Q1 = 1 / (r dt)``), relative outputs twice as noisy (``Q2 = Q1 / 2``).
    """
    from . import observers

    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    obs = observers.distributed_observer(A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]),
                                         Q1=np.eye(1) / (r * dt), Q2=np.eye(1) / (2 * r * dt), R=np.eye(1) * dt / q_vel,
                                         adjacency=adjacency)
    L, Phi = obs.L, float(obs.Phi[0, 0])
    Ad = np.array([[1.0, dt], [0.0, 1.0]])
    C = np.array([[1.0, 0.0]])
    for lam in obs.lam:  # the discretized error dynamics, mode by mode
        radius = max(abs(np.linalg.eigvals(Ad @ (np.eye(2) - dt * (1 + lam * Phi) * L @ C))))
        if radius >= 1.0:
            raise ValueError(f"the forward-Euler discretization of the Vlahakis observer is unstable at dt = {dt} "
                             f"(spectral radius {radius:.3f} for Laplacian eigenvalue {lam:.3f}); use a smaller dt")
    return L, Phi


class _Vlahakis(_Estimator):
    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        super().__init__(team, x_hat0)
        s = team.s
        L, Phi = _vlahakis_gains(team.adjacency, s.q_vel / (team.Q_filter[2, 2] / team.Q[2, 2]), s.r, s.dt)
        self.gain = s.dt * np.kron(L, np.eye(2))  # (4, 2): per-axis gain on [p; v]
        self.Phi = Phi

    def update(self, Z, S):
        N = self.t.N
        p_hat = self.own[..., :2]
        z_pos = Z[..., :2]                          # (R, N, N, 2): z_ij positions
        own_z = z_pos[:, np.arange(N), np.arange(N)]
        links = self.t.adjacency * S               # links delivered at this step, (R, N, N)
        rel_meas = own_z[:, :, None] - z_pos       # y_i - y_j measured
        rel_est = p_hat[:, :, None] - p_hat[:, None]
        coupling = np.einsum("rij,rijd->rid", links, rel_meas - rel_est)
        innovation = (own_z - p_hat) + self.Phi * coupling
        self.own = self.own + innovation @ self.gain.T

    def predict(self, U):
        self.own = self.own @ self.t.A.T + U @ self.t.B.T


class _SetMembership(_Estimator):
    def __init__(self, team: _Team, x_hat0: np.ndarray) -> None:
        super().__init__(team, x_hat0)
        s = team.s
        self.shape = np.broadcast_to(_bound_scale("gaussian", 4, s.sm_confidence) * team.P0,
                                     (*x_hat0.shape[:2], 4, 4)).copy()
        scale = _bound_scale(team.noise, 4, s.sm_confidence)
        self.W_meas = scale * team.R
        self.W_proc = scale * team.Q_filter

    def update(self, Z, S):
        N = self.t.N
        y = Z[:, np.arange(N), np.arange(N)]
        self.own, self.shape, _ = set_membership.correct(self.own, self.shape, y, np.eye(4), np.eye(4), self.W_meas,
                                                         check_consistency=False)

    def predict(self, U):
        self.own, self.shape = set_membership.predict(self.own, self.shape, self.t.A, np.eye(4), self.W_proc,
                                                      self.t.B, U)

    def containment(self, x):
        e = x - self.own
        return np.einsum("...i,...i->...", e, np.linalg.solve(self.shape, e[..., None])[..., 0]) <= 1.0 + 1e-9


def _make(method: str, team: _Team, x_hat0: np.ndarray) -> _Estimator:
    if method == "centralized":
        return _Centralized(team, x_hat0)
    if method == "local":
        return _Local(team, x_hat0)
    if method in ("song-mb", "song-eb"):
        return _Song(team, x_hat0, estimation_based=method == "song-eb")
    if method == "vlahakis":
        return _Vlahakis(team, x_hat0)
    if method == "set-membership":
        return _SetMembership(team, x_hat0)
    raise ValueError(f"method must be one of {TEAM_METHODS}; got {method!r}")


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
) -> dict[str, np.ndarray]:
    """Run one estimator in the rendezvous loop, batched over Monte Carlo runs.

    Parameters
    ----------
    method : str
        One of :data:`TEAM_METHODS`.
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
    graph : {"ring", "geometric"}
        The sensing and communication graph (:func:`benchmark_graph`).
    runs : int, optional
        Monte Carlo runs (default ``settings.runs``).
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    dict of str to ndarray
        Per run ``(runs,)``: ``rmse_own`` (m), RMS error of each agent's own
        position estimate over the steady window; ``rmse_view`` (m), of the
        positions its control uses (itself and its neighbours); ``nees_own``,
        mean normalized estimation error squared of the own state per degree
        of freedom (NaN without a covariance); ``containment``, fraction of
        agent-steps whose true state lies in the set-membership ellipsoid (NaN
        for the other methods); ``spread`` (m), steady-state RMS distance of
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
    n_agents, runs = _check_run(n_agents, noise, dropout, q_scale, runs, settings, seed)
    if method not in TEAM_METHODS:
        raise ValueError(f"method must be one of {TEAM_METHODS}; got {method!r}")
    team = _team(int(n_agents), noise, float(q_scale), settings, graph)
    init_rng, proc_rng, meas_rng, drop_rng = np.random.default_rng(seed).spawn(4)
    N, s = team.N, settings
    x = np.concatenate([s.init_pos * init_rng.standard_normal((runs, N, 2)),
                        s.init_vel * init_rng.standard_normal((runs, N, 2))], axis=-1)
    x_hat0 = x + np.sqrt(s.p0) * init_rng.standard_normal(x.shape)
    est = _make(method, team, x_hat0)
    cpu = 0.0  # the estimator's own work only: not its design (offline), not the simulation around it
    q_std, r_std = np.sqrt(np.diag(team.Q)), np.sqrt(s.r)
    nominal = team.adjacency > 0
    eye = np.eye(N, dtype=bool)
    held = None
    acc = {k: np.zeros(runs) for k in ("own", "view", "nees", "contained", "spread")}
    for k in range(s.n_steps):
        lost = (drop_rng.random((runs, N, N)) < dropout) & ~eye
        S = (nominal | eye) & ~lost
        nu = r_std * _draw(meas_rng, noise, (runs, N, N, 4))
        Z = np.where(S[..., None], x[:, None] + nu, 0.0)
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
        w = q_std * _draw(proc_rng, noise, (runs, N, 4))
        x = x @ team.A.T + U @ team.B.T + w
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{method}: the closed loop diverged (non-finite states at step {k})")
    n = s.n_steps - s.steady_from
    nan = np.full(runs, np.nan)
    return {
        "rmse_own": np.sqrt(acc["own"] / n), "rmse_view": np.sqrt(acc["view"] / n),
        "nees_own": acc["nees"] / n if est.own_cov is not None else nan,
        "containment": acc["contained"] / n if method == "set-membership" else nan,
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
    centred = x[..., :2] - x[..., :2].mean(-2, keepdims=True)
    acc["spread"] += np.mean(np.sum(centred**2, -1), -1)


# --------------------------------------------------------------------------------------------
# the shared task


def simulate_shared(
    method: str,
    n_agents: int,
    seed: np.random.SeedSequence | int,
    *,
    noise: str = "gaussian",
    dropout: float = 0.0,
    runs: int | None = None,
    settings: BenchmarkSettings = SETTINGS,
) -> dict[str, np.ndarray]:
    """Fuse the agents' priors of one common 2-D quantity over the ring (Ren et al.'s task).

    Parameters
    ----------
    method : str
        One of :data:`SHARED_METHODS`.
    n_agents : int
        Team size N (a ring, N >= 3).
    seed : numpy.random.SeedSequence or int
        Source of the priors and drop-outs (the same for every method).
    noise : {"gaussian", "uniform", "student-t"}
        Distribution of the prior errors (covariance ``p_i I``).
    dropout : float
        Probability that a link's message is lost at a step.
    runs : int, optional
        Monte Carlo runs (default ``settings.runs``).
    settings : BenchmarkSettings
        The benchmark's settings (``shared_steps``, ``shared_var``).

    Returns
    -------
    dict of str to ndarray
        Per run: ``rmse_own`` (m), RMS error of the agents' final estimates;
        ``nees_own``, their NEES per degree of freedom (NaN for average consensus,
        which carries no covariance); ``cpu_s``.

    Examples
    --------
    >>> from mascore import compare
    >>> best = compare.simulate_shared("central-fusion", 6, 0, runs=200)
    >>> ren = compare.simulate_shared("ren-kc", 6, 0, runs=200)
    >>> bool(best["rmse_own"].mean() <= ren["rmse_own"].mean())
    True
    """
    n_agents, runs = _check_run(n_agents, noise, dropout, 1.0, runs, settings, seed)
    if method not in SHARED_METHODS:
        raise ValueError(f"method must be one of {SHARED_METHODS}; got {method!r}")
    start = time.thread_time()
    init_rng, _, _, drop_rng = np.random.default_rng(seed).spawn(4)
    N = int(n_agents)
    lo, hi = np.log(settings.shared_var[0]), np.log(settings.shared_var[1])
    var = np.exp(init_rng.uniform(lo, hi, (runs, N)))
    xi = np.sqrt(var)[..., None] * _draw(init_rng, noise, (runs, N, 2))  # truth is 0
    P = var[..., None, None] * np.eye(2)
    adjacency = graphs.ring_graph(N)
    nan = np.full(runs, np.nan)
    if method == "central-fusion":
        xi, P = consensus.central_fusion(xi, P)
        xi = np.broadcast_to(xi[:, None], (runs, N, 2))
        P = np.broadcast_to(P[:, None], (runs, N, 2, 2))
    elif method in ("average-consensus", "ren-kc"):
        G = adjacency * (drop_rng.random((settings.shared_steps, runs, N, N)) >= dropout)
        if method == "average-consensus":
            xi, P = _average(xi, G), None
        else:
            for G_k in G:
                xi, P = consensus.kalman_consensus_step(xi, P, G_k, Q=0.0, Omega=0.0)
    err = np.sum(xi**2, -1)
    nees = nan if P is None else np.mean(np.einsum("...i,...i->...", xi, np.linalg.solve(P, xi[..., None])[..., 0]),
                                         -1) / 2
    cpu = time.thread_time() - start
    return {"rmse_own": np.sqrt(err.mean(-1)), "nees_own": nees, "cpu_s": np.full(runs, cpu)}


def _average(xi: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Average consensus with Metropolis weights on the delivered links, step by step."""
    for G_k in G:
        deg = G_k.sum(-1)
        W = G_k / (1.0 + np.maximum(deg[..., :, None], deg[..., None, :]))
        W = W + np.eye(G_k.shape[-1]) * (1.0 - W.sum(-1))[..., None]
        xi = W @ xi
    return xi


# --------------------------------------------------------------------------------------------
# grids and cells


def grid_cells(name: str = "quick") -> list[dict[str, Any]]:
    """The cells of a named sweep: ``"quick"`` (the book, the tests) or ``"full"`` (the CLI).

    Both are unions of one-factor studies around the baseline (ring, Gaussian
    noise, no drop-out, correct Q): ``scaling`` over N, ``graph`` (the geometric
    graph at N = 16, and 32 in the full grid), ``dropout``, ``noise`` and ``wrong-q``
    at N = 8, and the ``shared`` task; each with
    ``blocks x settings.runs`` seeds (quick: 2 x 50, full: 4 x 50, N up to 64).

    Parameters
    ----------
    name : {"quick", "full"}
        Which sweep.

    Returns
    -------
    list of dict
        One dictionary of coordinates per cell.

    Examples
    --------
    >>> from mascore.compare import grid_cells
    >>> len(grid_cells("quick")) < len(grid_cells("full"))
    True
    """
    if name not in ("quick", "full"):
        raise ValueError(f"name must be 'quick' or 'full'; got {name!r}")
    quick = name == "quick"
    blocks = [0, 1] if quick else [0, 1, 2, 3]
    sizes = [4, 8, 16] if quick else [4, 8, 16, 32, 64]
    base = {"task": ["team"], "graph": ["ring"], "noise": ["gaussian"], "dropout": [0.0], "q_scale": [1.0],
            "block": blocks}
    studies = [
        ("scaling", {**base, "method": list(TEAM_METHODS), "n_agents": sizes}),
        ("graph", {**base, "method": list(TEAM_METHODS), "graph": ["geometric"], "n_agents": [16] if quick else [16, 32]}),
        ("dropout", {**base, "method": list(TEAM_METHODS), "n_agents": [8], "dropout": [0.1, 0.3]}),
        ("noise", {**base, "method": list(TEAM_METHODS), "n_agents": [8], "noise": ["uniform", "student-t"]}),
        ("wrong-q", {**base, "method": list(TEAM_METHODS), "n_agents": [8], "q_scale": [0.1, 10.0]}),
        ("shared", {**base, "task": ["shared"], "method": list(SHARED_METHODS), "n_agents": [8],
                    "dropout": [0.0, 0.1, 0.3]}),
    ]
    cells = []
    for study, axes in studies:
        for cell in Grid(axes).cells():
            if cell["method"] == "song-eb" and cell["n_agents"] > 32:
                continue  # its joint covariance is (2 N^2)^2 floats: 0.5 GB at N = 64
            cells.append({"study": study, **cell})
    return cells


def run_cell(cell: Mapping[str, Any], base_seed: int = 0, settings: BenchmarkSettings = SETTINGS) -> list[dict[str, Any]]:
    """Run one cell of a sweep: one row of metrics per Monte Carlo run.

    Parameters
    ----------
    cell : mapping
        Coordinates ``study, task, method, n_agents, graph, noise, dropout, q_scale, block``
        (``graph`` may be left out: a ring).
    base_seed : int
        The sweep's seed.
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    list of dict
        Rows with ``run`` (index inside the block), the metrics of
        :func:`simulate_team` or :func:`simulate_shared`, and ``floats``.

    Examples
    --------
    >>> from mascore.compare import run_cell
    >>> rows = run_cell({"study": "scaling", "task": "team", "method": "local", "n_agents": 4,
    ...                  "noise": "gaussian", "dropout": 0.0, "q_scale": 1.0, "block": 0})
    >>> len(rows), sorted(rows[0])[:3]
    (50, ['containment', 'cpu_s', 'floats'])
    """
    _check_cell(cell)
    check_settings_type(settings, BenchmarkSettings)
    seed = cell_seed(cell, SEED_AXES, base_seed)
    common = {"noise": cell["noise"], "dropout": float(cell["dropout"])}
    if cell["task"] == "team":
        metrics = simulate_team(cell["method"], int(cell["n_agents"]), seed, q_scale=float(cell["q_scale"]),
                                graph=cell.get("graph", "ring"), settings=settings, **common)
    else:
        metrics = simulate_shared(cell["method"], int(cell["n_agents"]), seed, settings=settings, **common)
        metrics.update(rmse_view=np.full_like(metrics["rmse_own"], np.nan), containment=metrics["rmse_own"] * np.nan,
                       spread=metrics["rmse_own"] * np.nan)
    adjacency = benchmark_graph(cell.get("graph", "ring"), int(cell["n_agents"]), settings)
    floats = floats_per_step(cell["method"], int(cell["n_agents"]), degree=float(adjacency.sum(1).mean()))
    runs = len(metrics["rmse_own"])
    return [{"run": r, "floats": floats, **{k: float(v[r]) for k, v in metrics.items()}} for r in range(runs)]


def summarize(table, by: Sequence[str] = ("study", "task", "method", "graph", "n_agents", "noise", "dropout",
                                         "q_scale"), settings: BenchmarkSettings = SETTINGS):
    """Means and 95 % confidence intervals per group, with the ratio to the bound.

    The ratio of a method's RMSE to the bound's (``centralized`` or
    ``central-fusion``) is formed run by run on common random numbers (same
    seed block and run), so its interval is much tighter than that of a
    ratio of means.

    Parameters
    ----------
    table : pandas.DataFrame
        Rows of :func:`run_cell` with their cell coordinates and ``cell`` identifier
        (the sweep's table).
    by : sequence of str
        Grouping columns.
    settings : BenchmarkSettings
        The benchmark's settings (its step counts give the CPU per step).

    Returns
    -------
    pandas.DataFrame
        One row per group: ``n`` runs, and ``mean``/``lo``/``hi`` of
        ``rmse_own``, ``ratio``, ``nees_own``, ``containment``, ``spread``,
        plus ``floats`` and ``cpu_us`` (CPU per agent per step and run, µs).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare import run_cell, summarize
    >>> cell = {"study": "scaling", "task": "team", "n_agents": 4, "noise": "gaussian", "dropout": 0.0,
    ...         "q_scale": 1.0, "block": 0}
    >>> rows = [{**r, **cell, "method": m, "cell": m} for m in ("centralized", "local")
    ...         for r in run_cell({**cell, "method": m})]
    >>> s = summarize(pd.DataFrame(rows))
    >>> bool((s.set_index("method").loc["local", "ratio_mean"] > 1.0))      # no cooperation costs accuracy
    True
    """
    import pandas as pd

    check_settings_type(settings, BenchmarkSettings)
    if not isinstance(table, pd.DataFrame):
        raise TypeError(f"table must be a pandas DataFrame of run_cell rows (the sweep's table); "
                        f"got {type(table).__name__}")
    if isinstance(by, str) or not isinstance(by, Sequence):
        raise TypeError(f"by must be a sequence of column names; got {by!r}")
    by = list(by)
    needed = {"task", "method", "n_agents", "cell", "block", "run", "rmse_own", "cpu_s", "floats", "nees_own",
              "containment", "spread"} | set(by) - {"graph"}
    missing = sorted(needed - set(table.columns))
    if missing:
        raise ValueError(f"table lacks the columns {missing} (rows of run_cell with their cell coordinates; "
                         f"by = {by})")
    t = table.copy()
    if "graph" not in t:
        t["graph"] = "ring"
    bound = t[t["method"].isin(["centralized", "central-fusion"])]
    keys = [c for c in by if c != "method"] + ["block", "run"]
    ref = bound.set_index(keys)["rmse_own"].rename("bound_rmse")
    t = t.join(ref, on=keys)
    t["ratio"] = t["rmse_own"] / t["bound_rmse"]
    steps = np.where(t["task"] == "team", settings.n_steps, settings.shared_steps)
    t["cpu_us"] = 1e6 * t["cpu_s"] / (t["n_agents"] * steps * t.groupby("cell")["run"].transform("size"))
    out = []
    for key, g in t.groupby(by, sort=False, dropna=False):
        row = dict(zip(by, key if isinstance(key, tuple) else (key,)))
        row["n"] = len(g)
        for col in ("rmse_own", "ratio", "nees_own", "containment", "spread"):
            m, half = _mean_ci(g[col].to_numpy())
            row[f"{col}_mean"], row[f"{col}_lo"], row[f"{col}_hi"] = m, m - half, m + half
        row["floats"] = float(g["floats"].iloc[0])
        row["cpu_us"] = float(g.drop_duplicates("cell")["cpu_us"].median())
        out.append(row)
    return pd.DataFrame(out).sort_values(by, kind="stable", ignore_index=True)  # N numerically, not as text


def _mean_ci(x: np.ndarray) -> tuple[float, float]:
    """Mean and the half-width of its 95 % normal-approximation interval (NaN-aware)."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan")
    half = 1.96 * x.std(ddof=1) / np.sqrt(x.size) if x.size > 1 else float("nan")
    return float(x.mean()), float(half)


# --------------------------------------------------------------------------------------------
# the whole comparison: sweep, summary, claims, figures


def run_compare(
    grid: str = "quick",
    out: str | Path = "results",
    *,
    workers: int = 0,
    scheduler: str | None = None,
    seed: int = 0,
    progress: bool = True,
):
    """Run a named sweep (resuming), and return its table and summary.

    Parameters
    ----------
    grid : {"quick", "full"}
        The sweep (:func:`grid_cells`).
    out : str or pathlib.Path
        Results folder; the table goes to ``out/compare/table-GRID-SEED.csv``.
    workers : int
        0: serially in this process; K: a local Dask cluster of K processes.
    scheduler : str, optional
        Address of a running Dask scheduler (overrides `workers`).
    seed : int
        The sweep's base seed.
    progress : bool
        Progress bar over cells.

    Returns
    -------
    table : pandas.DataFrame
        One row per Monte Carlo run and cell.
    summary : pandas.DataFrame
        :func:`summarize` of the table.

    Examples
    --------
    >>> import tempfile
    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", tempfile.mkdtemp(), progress=False)  # doctest: +SKIP
    """
    result = run(replace(SETTINGS, grid=grid), seed, progress, out=out, workers=workers, scheduler=scheduler)
    return result.table, result.summary


@dataclass(frozen=True, eq=False)
class CompareResult:
    """The comparison's sweep, once: its table and summary (see :func:`run`).

    Parameters
    ----------
    settings : BenchmarkSettings
        The run's settings (``settings.grid`` is the sweep).
    seed : int
        The sweep's base seed.
    table : pandas.DataFrame
        One row per Monte Carlo run and cell.
    summary : pandas.DataFrame
        :func:`summarize` of the table.
    slopes : dict
        Method -> fitted CPU slope in N (:func:`fitted_slopes`).
    phi : dict
        ``"N = n"`` -> the coupling gain the Vlahakis observer's LMI chooses on the ring of each size.

    Examples
    --------
    >>> from mascore.compare import CompareResult
    >>> sorted(CompareResult.__dataclass_fields__)[:3]
    ['phi', 'seed', 'settings']
    """

    settings: BenchmarkSettings
    seed: int
    table: Any
    summary: Any
    slopes: dict
    phi: dict


def run(settings: BenchmarkSettings = SETTINGS, seed: int = 0, progress: bool = False, *,
        out: str | Path | None = None, workers: int = 0, scheduler: str | None = None) -> CompareResult:
    """The comparison's study: the sweep ``settings.grid`` (resuming from `out`), its summary, slopes and gains.

    Parameters
    ----------
    settings : BenchmarkSettings
        The benchmark and the sweep (default :data:`SETTINGS`, the quick grid).
    seed : int
        The sweep's base seed (the published ledger's is 0).
    progress : bool
        Progress bar over cells.
    out : str or pathlib.Path, optional
        Results folder; the table goes to ``out/compare/table-GRID-SEED.csv`` and a later
        run resumes from it. Default: a temporary folder (nothing is kept).
    workers : int
        0: serially in this process; K: a local Dask cluster of K processes.
    scheduler : str, optional
        Address of a running Dask scheduler (overrides `workers`).

    Returns
    -------
    CompareResult
        Everything the figures, tables and claims need.

    Examples
    --------
    >>> from mascore import compare
    >>> result = compare.run(seed=0)  # doctest: +SKIP
    >>> result.summary["study"].unique().tolist()  # doctest: +SKIP
    ['dropout', 'graph', 'noise', 'scaling', 'shared', 'wrong-q']
    """
    check_settings_type(settings, BenchmarkSettings)
    import tempfile

    from .sweep import run_sweep

    if settings.grid not in ("quick", "full"):
        raise ValueError(f"settings.grid must be 'quick' or 'full'; got {settings.grid!r}")
    with tempfile.TemporaryDirectory(prefix="mascore-compare-") as scratch:
        folder = Path(scratch if out is None else out) / "compare"
        table = run_sweep(grid_cells(settings.grid), functools.partial(run_cell, base_seed=seed, settings=settings),
                          folder / f"table-{settings.grid}-{seed}.csv", workers=workers, scheduler=scheduler,
                          progress=progress, cost=cell_cost)
    summary = summarize(table, settings=settings)
    sizes = sorted(summary.loc[summary["study"] == "scaling", "n_agents"].unique())
    phi = {f"N = {n}": _vlahakis_gains(graphs.ring_graph(int(n)), settings.q_vel, settings.r, settings.dt)[1]
           for n in sizes}
    return CompareResult(settings, int(seed), table, summary, fitted_slopes(summary), phi)


def cell_cost(cell: Mapping[str, Any]) -> float:
    """A rough relative run time of a cell, to start the longest cells first on a cluster.

    Parameters
    ----------
    cell : mapping
        Coordinates with ``task``, ``method``, ``n_agents`` and ``dropout``.

    Returns
    -------
    float
        Proportional to the flops of one step for a block of runs: the whole-team
        filters grow like ``N^3``-``N^4`` (and keep one covariance per run when links drop),
        the per-agent ones like ``N``.

    Examples
    --------
    >>> from mascore.compare import cell_cost
    >>> base = {"task": "team", "n_agents": 32, "dropout": 0.0}
    >>> cell_cost({**base, "method": "song-eb"}) > cell_cost({**base, "method": "local"})
    True
    """
    _check_cell(cell, full=False)
    if cell["task"] != "team":
        return 1.0
    n = float(cell["n_agents"])
    whole_team = {"song-eb": n**4, "song-mb": n**3.5, "centralized": n**3}
    per_run = 20.0 if cell["dropout"] > 0 and cell["method"] in whole_team else 1.0
    return whole_team.get(cell["method"], 50.0 * n) * per_run


def fitted_slopes(summary) -> dict[str, float]:
    """Log-log slope of CPU per agent per step against N, per method (scaling study).

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    dict of str to float
        Method to the least-squares slope of ``log(cpu_us)`` on ``log(N)``.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare import fitted_slopes
    >>> s = pd.DataFrame({"study": "scaling", "method": "x", "n_agents": [4, 8, 16], "cpu_us": [1.0, 4.0, 16.0]})
    >>> round(fitted_slopes(s)["x"], 6)
    2.0
    """
    scaling = summary[summary["study"] == "scaling"]
    return {m: float(np.polyfit(np.log(g["n_agents"]), np.log(g["cpu_us"]), 1)[0])
            for m, g in scaling.groupby("method", sort=False)}


def headline(summary):
    """The practitioner's table: per method, accuracy, consistency, messages and cost.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    pandas.DataFrame
        Team methods at N = 8 on the baseline: RMSE ratio to the centralized
        filter with its 95 % interval, NEES per dof (or containment), the
        control performance (steady-state RMS distance of the agents to their
        centroid, m), floats sent per step, CPU per agent and step, and the CPU slope in N.

    Examples
    --------
    On the quick sweep (what ``python -m mascore compare`` prints):

    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", "results", workers=2)  # doctest: +SKIP
    >>> compare.headline(summary).loc["song-eb", "floats/step"]  # doctest: +SKIP
    0.0
    """
    import pandas as pd

    slopes = fitted_slopes(summary)
    base = summary[(summary["study"] == "scaling") & (summary["n_agents"] == 8)].set_index("method")
    rows = []
    for m in TEAM_METHODS:
        if m not in base.index:
            continue
        r = base.loc[m]
        consistency = (f"NEES {r['nees_own_mean']:.2f}" if np.isfinite(r["nees_own_mean"])
                       else f"contains {r['containment_mean']:.3f}" if np.isfinite(r["containment_mean"]) else "n/a")
        rows.append({"method": m, "RMSE ratio": f"{r['ratio_mean']:.3f} [{r['ratio_lo']:.3f}, {r['ratio_hi']:.3f}]",
                     "consistency": consistency, "spread (m)": round(r["spread_mean"], 3), "floats/step": r["floats"],
                     "CPU µs/agent/step": round(r["cpu_us"], 2), "CPU slope in N": round(slopes.get(m, np.nan), 2)})
    return pd.DataFrame(rows).set_index("method")


def compare_claims(summary, phi: dict | None = None) -> list:
    """The comparison's claims (``compare/...``), with verdicts computed from the summary.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize` on a sweep that holds every study of :func:`grid_cells`.
    phi : dict, optional
        The Vlahakis observer's coupling gain per ring size (:attr:`CompareResult.phi`);
        designed here from :data:`SETTINGS` if not given.

    Returns
    -------
    list of mascore.ledger.Claim
        Qualitative claims, each with the quantities that decide it.

    Examples
    --------
    On the quick sweep (the chapter "Comparing the methods" shows them all):

    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", "results", workers=2)  # doctest: +SKIP
    >>> [c.verdict for c in compare.compare_claims(summary)][:2]  # doctest: +SKIP
    ['holds', 'holds']
    """
    from .ledger import Claim

    s = summary
    team = s[s["task"] == "team"]
    base = team[team["study"] == "scaling"]
    where = "Comparing the methods"
    claims = []
    worst = {m: float(g["ratio_lo"].min()) for m, g in team[team["method"] != "centralized"].groupby("method")}
    claims.append(Claim.qualitative(
        "compare/centralized-bound", where,
        "The centralized Kalman filter's RMSE lower-bounds every other method's in every condition of the sweep "
        "(lowest lower end of the 95 % interval of the run-by-run ratio, per method).",
        worst, all(v >= 1.0 for v in worst.values()), rule="min ratio_lo >= 1 for every method",
        note="Under a wrong Q the centralized filter is wrong too; the ratio is still taken to it."))
    contained = team[(team["method"] == "set-membership") & (team["noise"] == "uniform")]["containment_mean"]
    claims.append(Claim.qualitative(
        "compare/set-membership-contains", where,
        "Under bounded (uniform) noise the set-membership filter's ellipsoid contains the true state at every "
        "agent-step of every run.", {"containment": float(contained.min())}, float(contained.min()) == 1.0,
        rule="containment == 1"))
    gauss = team[(team["method"] == "set-membership") & (team["noise"] != "uniform") & (team["study"] == "noise")]
    claims.append(Claim.qualitative(
        "compare/set-membership-unbounded", where,
        "Given a 99.7 % ellipsoid for heavy-tailed (Student-t) noise, the set-membership filter loses the true state "
        "more often than the 0.3 % the bound admits.",
        {"containment": float(gauss["containment_mean"].min())}, float(gauss["containment_mean"].min()) < 0.997,
        rule="containment < 0.997"))
    stochastic = ("centralized", "local", "song-mb", "song-eb")

    def nees_at(frame) -> dict:
        return {m: float(frame[frame["method"] == m]["nees_own_mean"].mean()) for m in stochastic}

    nees_base = nees_at(base)
    claims.append(Claim.qualitative(
        "compare/consistent-baseline", where,
        "On the baseline (Gaussian noise, correct Q, no drop-outs) the centralized, local and estimation-based "
        "filters are consistent (mean own-state NEES per degree of freedom within 10 % of 1); Song et al.'s "
        "measurement-based filter is not: eq. (15) neglects the correlation of an agent's own measurement noise "
        "in its control and in its estimate.", nees_base,
        all(abs(nees_base[m] - 1) < 0.1 for m in ("centralized", "local", "song-eb")) and nees_base["song-mb"] > 1.1,
        rule="|NEES - 1| < 0.1 for centralized, local, song-eb; > 1.1 for song-mb"))
    drop = team[(team["study"] == "dropout") & (team["dropout"] == team["dropout"].max())]
    nees_drop = nees_at(drop)
    consistent = sorted(m for m, v in nees_drop.items() if abs(v - 1) < 0.1)
    claims.append(Claim.qualitative(
        "compare/consistent-dropouts", where,
        "With 30 % of the links dropping at every step, the filters that were consistent stay consistent: "
        "the filters condition on the measurements that arrive.", {"nees": nees_drop, "consistent": consistent},
        set(consistent) >= {"centralized", "local", "song-eb"}, rule="centralized, local, song-eb within 10 % of 1"))
    low_q = nees_at(team[(team["study"] == "wrong-q") & (team["q_scale"] < 1)])
    claims.append(Claim.qualitative(
        "compare/wrong-q-overconfident", where,
        "With a process-noise covariance ten times too small, every Kalman-type filter becomes overconfident "
        "(NEES per dof above 1.1).", low_q, all(v > 1.1 for v in low_q.values()), rule="NEES > 1.1 for all"))
    b8 = base[base["n_agents"] == 8].set_index("method")
    gain = {m: float(b8.loc[m, "rmse_own_mean"] / b8.loc["local", "rmse_own_mean"]) for m in ("song-mb", "song-eb")}
    claims.append(Claim.qualitative(
        "compare/song-own-state", where,
        "Song et al.'s filters estimate the whole team, but an agent's estimate of its own state is no better than "
        "a local Kalman filter's (within 3 %): the neighbours' measurements of agent i are never sent to i. "
        "What they buy is the estimate of the others, without any communication.",
        gain, all(abs(v - 1) < 0.03 for v in gain.values()), rule="|RMSE / RMSE_local - 1| < 0.03"))
    if phi is None:
        phi = {f"N = {n}": _vlahakis_gains(graphs.ring_graph(n), SETTINGS.q_vel, SETTINGS.r, SETTINGS.dt)[1]
               for n in sorted(base["n_agents"].unique())}
    vl = float(b8.loc["vlahakis", "rmse_own_mean"] / b8.loc["local", "rmse_own_mean"])
    claims.append(Claim.qualitative(
        "compare/vlahakis-no-coupling", where,
        "On this benchmark the Vlahakis observer's LMI chooses almost no coupling (|Phi| < 1e-3 on every ring): "
        "a relative measurement y_i - y_j carries agent i's own measurement noise again, so it adds noise but no "
        "information about x_i. What is left, the continuous-time Kalman-Bucy gain applied by forward Euler, is "
        "10-25 % less accurate than the discrete local Kalman filter.",
        {"Phi": phi, "rmse_over_local": vl}, all(abs(v) < 1e-3 for v in phi.values()) and 1.1 < vl < 1.25,
        rule="|Phi| < 1e-3 and 1.1 < RMSE / RMSE_local < 1.25"))
    shared = s[(s["task"] == "shared") & (s["dropout"] == 0.0)].set_index("method")
    ren = {"ratio": float(shared.loc["ren-kc", "ratio_mean"]), "nees": float(shared.loc["ren-kc", "nees_own_mean"])}
    claims.append(Claim.qualitative(
        "compare/ren-accurate-overconfident", where,
        "On the shared quantity Ren et al.'s Kalman consensus reaches the central fusion's accuracy (ratio within 2 %) "
        "but its P is no error covariance: it keeps shrinking as the same information is counted again, so the NEES "
        "is far above 1.", ren, abs(ren["ratio"] - 1) < 0.02 and ren["nees"] > 10, rule="|ratio - 1| < 0.02, NEES > 10",
        note="With Q = 0 and noise-free messages (Omega = 0)."))
    return claims


def _plt():
    from ._optional import require

    return require("matplotlib.pyplot", "the comparison's figures")


def plot_pareto(summary):
    """Accuracy against communication: RMSE ratio to the centralized filter vs floats sent per step.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    matplotlib.figure.Figure
        One point per method and team size (scaling study), with 95 % intervals.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> summary = pd.DataFrame({"study": "scaling", "method": ["centralized", "local"], "n_agents": 8,
    ...                         "floats": [24.0, 4.0], "ratio_mean": [1.0, 1.4], "ratio_lo": [1.0, 1.38],
    ...                         "ratio_hi": [1.0, 1.42]})
    >>> compare.plot_pareto(summary).axes[0].get_ylabel()
    'own-position RMSE / centralized (log scale)'
    """
    plt = _plt()
    base = summary[summary["study"] == "scaling"]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    sizes = sorted(base["n_agents"].unique())
    for i, m in enumerate(TEAM_METHODS):
        g = base[base["method"] == m]
        if g.empty:
            continue
        jitter = 1 + 0.06 * (np.searchsorted(sizes, g["n_agents"]) - (len(sizes) - 1) / 2)
        x = (g["floats"] + 1) * jitter
        ax.errorbar(x, g["ratio_mean"], yerr=[g["ratio_mean"] - g["ratio_lo"], g["ratio_hi"] - g["ratio_mean"]],
                    fmt="o", color=f"C{i}", label=m, capsize=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("floats sent per agent per step + 1 (log scale; points of one method: N = "
                  + ", ".join(map(str, sizes)) + ")")
    ax.set_ylabel("own-position RMSE / centralized (log scale)")
    _plain_ticks(ax)
    top = float(base["ratio_hi"].max())
    ax.set_yticks([t for t in (1, 1.25, 1.5, 2, 3, 4, 6, 8) if t <= top * 1.05])
    ax.axhline(1.0, color="0.5", lw=0.8, ls="--")
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    return fig


def plot_cost(summary, slopes: dict | None = None):
    """CPU per agent per step against team size, log-log, with the fitted slopes.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.
    slopes : dict, optional
        Method -> CPU slope in N (:attr:`CompareResult.slopes`); fitted here if not given.

    Returns
    -------
    matplotlib.figure.Figure
        One line per method (scaling study).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> summary = pd.DataFrame({"study": "scaling", "method": "local", "n_agents": [4, 8, 16],
    ...                         "cpu_us": [0.4, 0.8, 1.6]})
    >>> compare.plot_cost(summary).axes[0].get_legend_handles_labels()[1]     # a slope of 1: linear in N
    ['local (slope 1.00)']
    """
    plt = _plt()
    slopes = fitted_slopes(summary) if slopes is None else slopes
    base = summary[summary["study"] == "scaling"]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for i, m in enumerate(TEAM_METHODS):
        g = base[base["method"] == m]
        if g.empty:
            continue
        ax.loglog(g["n_agents"], g["cpu_us"], "o-", color=f"C{i}", label=f"{m} (slope {slopes[m]:.2f})")
    ax.set_xlabel("team size N")
    ax.set_ylabel("CPU per agent per step and run (µs)")
    ax.set_xticks(sorted(base["n_agents"].unique()))
    _plain_ticks(ax)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_robustness(summary):
    """Own-position RMSE (m) under drop-outs, noise distributions and a wrong Q, at N = 8.

    Parameters
    ----------
    summary : pandas.DataFrame
        Output of :func:`summarize`.

    Returns
    -------
    matplotlib.figure.Figure
        Three panels: RMSE against the drop-out probability, against the noise
        distribution, and against ``q_scale``.

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import compare
    >>> rows = [("scaling", "gaussian", 0.0, 1.0), ("dropout", "gaussian", 0.3, 1.0),
    ...         ("noise", "uniform", 0.0, 1.0), ("wrong-q", "gaussian", 0.0, 10.0)]
    >>> summary = pd.DataFrame([{"study": st, "task": "team", "method": "local", "n_agents": 8, "noise": nz,
    ...                          "dropout": p, "q_scale": q, "rmse_own_mean": 0.05, "rmse_own_lo": 0.049}
    ...                         for st, nz, p, q in rows])
    >>> [ax.get_xlabel() for ax in compare.plot_robustness(summary).axes]
    ['link drop-out probability', 'noise distribution', 'filter Q / true Q']
    """
    plt = _plt()
    team = summary[(summary["task"] == "team") & (summary["n_agents"] == 8)]
    base = team[team["study"] == "scaling"]
    fig, axes = plt.subplots(1, 3, figsize=(11, 4.2), sharey=True)
    panels = (("dropout", "dropout", "link drop-out probability"), ("noise", "noise", "noise distribution"),
              ("wrong-q", "q_scale", "filter Q / true Q"))
    for ax, (study, col, label) in zip(axes, panels):
        frame = team[team["study"] == study]
        for i, m in enumerate(TEAM_METHODS):
            g = _concat(base[base["method"] == m], frame[frame["method"] == m]).sort_values(col, key=_order(col))
            if g.empty:
                continue
            x = np.arange(len(g)) if col == "noise" else g[col]
            ax.errorbar(x, g["rmse_own_mean"], yerr=g["rmse_own_mean"] - g["rmse_own_lo"], fmt="o-", color=f"C{i}",
                        label=m, capsize=2)
            if col == "noise":
                ax.set_xticks(np.arange(len(g)), g["noise"])
        if col == "q_scale":
            ax.set_xscale("log")
            ax.set_xticks(sorted(frame[col].unique().tolist() + [1.0]))
            ax.xaxis.set_major_formatter("{x:g}")
        ax.set_xlabel(label)
    axes[0].set_ylabel("own-position RMSE (m, log scale)")
    axes[0].set_yscale("log")
    axes[0].set_yticks([0.03, 0.04, 0.05, 0.07, 0.1, 0.15])
    axes[0].yaxis.set_major_formatter("{x:g}")
    axes[0].yaxis.set_minor_formatter("")
    handles, labels = axes[0].get_legend_handles_labels()
    ncol = (len(labels) + 1) // 2  # two rows, so that the legend is no wider than the column
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.13 if ncol < len(labels) else 0.07, 1, 1))
    return fig


def _plain_ticks(ax) -> None:
    """Tick labels as plain numbers (1, 2, 4, 16) on log axes, not powers of ten."""
    from matplotlib.ticker import FuncFormatter

    fmt = FuncFormatter(lambda v, _: f"{v:g}")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(fmt)
        axis.set_minor_formatter(FuncFormatter(lambda v, _: ""))


def _concat(*frames):
    import pandas as pd

    return pd.concat(frames, ignore_index=True)


def _order(col: str):
    if col == "noise":
        return lambda s: s.map({n: i for i, n in enumerate(NOISES)})
    return None


# --------------------------------------------------------------------------------------------
# the comparison as a study (the same contract as the papers' modules)


def claims(result: CompareResult) -> list:
    """The comparison's ledger (``compare/...`` claims), from `result` alone (:func:`compare_claims`).

    Parameters
    ----------
    result : CompareResult
        The output of :func:`run`.

    Returns
    -------
    list of mascore.ledger.Claim
        The claims with their computed verdicts.

    Examples
    --------
    >>> from mascore import compare
    >>> [c.id for c in compare.claims(compare.run())][:1]  # doctest: +SKIP
    ['compare/centralized-bound']
    """
    return compare_claims(result.summary, phi=result.phi)


FIGURES = (
    FigureSpec("pareto", "", "Accuracy against communication: each method's own-position RMSE over the centralized "
               "filter's (run by run, with 95 % intervals) against the floats it sends per agent and step, for "
               "N = 4, 8 and 16 on the ring.", lambda r: plot_pareto(r.summary)),
    FigureSpec("cost", "", "CPU time per agent, step and run against the team size, log-log, with each method's "
               "fitted slope: the whole-team filters grow much faster than the per-agent ones.",
               lambda r: plot_cost(r.summary, r.slopes)),
    FigureSpec("robustness", "", "Own-position RMSE at N = 8 under link drop-outs, other noise distributions and a "
               "wrong process-noise covariance in the filters, beside the baseline.",
               lambda r: plot_robustness(r.summary)),
)

TABLES = (
    TableSpec("headline", "", "Per team method at N = 8: RMSE ratio to the centralized filter, consistency, "
              "control spread, floats sent and CPU per agent and step, and the CPU slope in N.",
              lambda r: headline(r.summary).reset_index()),
    TableSpec("summary", "", "Means and 95 % intervals of every metric per condition of the sweep, with the "
              "ratio to the bound.", lambda r: r.summary),
)

#: The chapter "Comparing the methods": the sweep, its figures, tables and ledger.
STUDY = Study("compare", "comparing_methods", SETTINGS, run, FIGURES, TABLES, claims)

#: The comparison's registry: its ledger is ``results/compare/claims.json`` (``python -m mascore compare``).
REGISTRY = PaperRegistry("compare", "Comparing the methods", studies=(STUDY,), position=5)
